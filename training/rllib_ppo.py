"""RLlib PPO (new API stack) on the same environment: one shared RLModule with the project's actor, masked logits.

    pip install "taskalloc[ray]"
    taskalloc rllib train --out-dir runs/rllib --iterations 20                # a local Ray instance
    RAY_ADDRESS=<head>:6379 taskalloc rllib train --env-runners 8 --out-dir runs/rllib   # a cluster
    taskalloc rllib export runs/rllib/rllib runs/rllib/model     # an RLlib checkpoint → model.json

Parameter sharing: every agent maps to the one module ``shared`` (RLlib's ``pettingzoo_parameter_sharing`` example).
The module (``TaskAllocRLModule``) holds one of the project's actor networks (``taskalloc.policies.networks``:
``attention`` or ``pooling``), which masks its own logits, as RLlib's ``ActionMaskingTorchRLModule`` does; its critic is
a pooling encoder of the agent's own observation (PPO with parameter sharing; the centralised critic on ``env.state()``
is in ``taskalloc.training.mappo``). Because the actor is a project network, a run ends by writing it in the project's
checkpoint format (``model.json`` + ``model.safetensors``, ``taskalloc.policies.checkpoint``): ``learned:<out_dir>`` in
``compare``, the experiment runner and ``taskalloc.evaluation.heldout``. The RLlib checkpoint (``<out_dir>/rllib``) is
saved too; ``export`` turns any RLlib checkpoint of this module (from a cluster run, say) into a project checkpoint.

Ray starts locally (``address="local"``) unless ``RAY_ADDRESS`` names a cluster; the package must be installed on
every node of the cluster (``pip install taskalloc[ray]``), and ``--env-runners`` then samples on the nodes. (Ray's
own default, ``address=None``, joins the last cluster started on this machine, and hung when that one was gone.)
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch as th
import yaml
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModule, RLModuleSpec
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

from taskalloc.evaluation.episodes import evaluate, summarise
from taskalloc.evaluation.seeds import VALIDATION_SEED_START
from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.training.config import plain, prepare_out_dir
from taskalloc.training.rllib_module import NETWORKS, TaskAllocRLModule
from taskalloc_env.config import PROTOCOL_FIELDS, resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, mapping_argument, run_cli, seed_argument
from taskalloc_env.taskalloc_v0 import parallel_env
from taskalloc_env.wrappers.rllib import RLlibObservations

ENV_NAME = "taskalloc"
MODULE_ID = "shared"

def make_env(env_config: Mapping[str, Any]) -> ParallelPettingZooEnv:
    """The env creator RLlib calls on every env runner (``register_env``)."""
    return ParallelPettingZooEnv(RLlibObservations(parallel_env(**env_config)))


def env_config(scenario: str, overrides: Mapping[str, Any], env_overrides: Mapping[str, Any],
               max_cycles: int) -> dict[str, Any]:
    """Keyword arguments of ``parallel_env``; rewards in units of c̄ · N, as in ``taskalloc.training.mappo``."""
    cfg = resolve_config(scenario, **overrides)
    return {"scenario": scenario, **overrides, **env_overrides, "max_cycles": max_cycles,
            "reward_scale": float(cfg.reward) * cfg.n_agents}


def build_config(args: argparse.Namespace) -> tuple[PPOConfig, dict[str, Any]]:
    """The PPO config (new API stack: RLModule, EnvRunners, Learner) and the env config it trains on."""
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    config = env_config(args.scenario, args.set, args.env_overrides, args.max_cycles)
    probe = TaskAllocEnv(**config)
    layout = probe.observation_layout
    model_config = {"network": args.network, "hidden": args.hidden, "own_features": list(layout.own_names),
                    "task_features": list(layout.task_names), "kinds": 3 if probe.config.release_actions else 2}
    ppo = (
        PPOConfig()
        .environment(ENV_NAME, env_config=config)
        .env_runners(num_env_runners=args.env_runners, num_envs_per_env_runner=args.envs_per_runner)
        .learners(num_learners=0)
        .multi_agent(policies={MODULE_ID}, policy_mapping_fn=lambda agent_id, *a, **k: MODULE_ID)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={
            MODULE_ID: RLModuleSpec(module_class=TaskAllocRLModule, model_config=model_config)}))
        .training(train_batch_size_per_learner=args.train_batch, minibatch_size=args.minibatch,
                  num_epochs=args.epochs, lr=args.lr, gamma=1.0, lambda_=0.95, entropy_coeff=0.01, clip_param=0.2,
                  vf_loss_coeff=0.5, grad_clip=0.5)
        .debugging(seed=args.seed)
    )
    return ppo, config


def export(module: RLModule, stem: Path, env_overrides: Mapping[str, Any], meta: Mapping[str, Any]) -> Path:
    """The module's actor as a project checkpoint (``<stem>.json`` + ``<stem>.safetensors``)."""
    cfg = module.model_config
    return checkpoint.save(stem, module.actor, cfg["own_features"], cfg["task_features"], env_overrides, meta)


def init_ray() -> None:
    """A local Ray instance, or the cluster ``RAY_ADDRESS`` names."""
    import ray

    if not ray.is_initialized():
        ray.init(address=os.environ.get("RAY_ADDRESS", "local"), include_dashboard=False, log_to_driver=False)


def train(args: argparse.Namespace) -> dict[str, Any]:
    import ray

    out_dir = prepare_out_dir(args.out_dir, args.overwrite)
    th.set_num_threads(1)
    init_ray()
    ppo, config = build_config(args)
    algo = ppo.build_algo()
    t0, history = time.perf_counter(), []
    for _ in range(args.iterations):
        result = algo.train()
        runners = result["env_runners"]
        row = {"iteration": int(result["training_iteration"]),
               "env_steps": int(runners["num_env_steps_sampled_lifetime"]),
               "agent_steps": int(sum(runners["num_agent_steps_sampled_lifetime"].values())),
               "episode_return": float(runners.get("episode_return_mean", float("nan"))),
               "seconds": round(time.perf_counter() - t0, 1)}
        history.append(row)
        print(f"iteration {row['iteration']}: {row['env_steps']} env steps, {row['agent_steps']} agent steps, "
              f"mean return {row['episode_return']:.3f}, {row['seconds']} s", flush=True)
    seconds = time.perf_counter() - t0
    meta = {"name": args.name, "algo": "rllib_ppo", "seed": args.seed, "scenario": args.scenario,
            "agent_steps": history[-1]["agent_steps"] if history else 0}
    written = export(algo.get_module(MODULE_ID), out_dir / "model", args.env_overrides, meta)
    algo.save_to_path(str((out_dir / "rllib").resolve()))
    algo.stop()
    ray.shutdown()
    policy = LearnedPolicy.load(written)
    seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + args.eval_episodes)
    eval_env = {k: v for k, v in config.items() if k not in ("max_cycles", "reward_scale")}
    validation = summarise(evaluate(policy, eval_env, seeds))
    baseline = summarise(evaluate(make_policy("cbgabi"), eval_env, seeds))
    steps = history[-1]["agent_steps"] if history else 0
    summary = {"command": "taskalloc rllib " + " ".join(args.argv), "ray_address":
               os.environ.get("RAY_ADDRESS", "local"), "iterations": history, "train_seconds": round(seconds, 1),
               "agent_steps_per_second": round(steps / seconds, 1) if seconds else None,
               "validation": validation, "cbgabi_validation": baseline}
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    print(f"written: {written}, {out_dir / 'rllib'}; validation score {validation['score']:.1f} "
          f"(CBGABI {baseline['score']:.1f} on the same {len(seeds)} seeds)")
    return summary


def export_checkpoint(args: argparse.Namespace) -> Path:
    """An RLlib checkpoint (the algorithm's folder, or the module's own) → a project checkpoint."""
    source = Path(args.rllib_checkpoint).resolve()
    module_dir = source / "learner_group" / "learner" / "rl_module" / MODULE_ID
    if not module_dir.is_dir():
        module_dir = source
    try:
        module = RLModule.from_checkpoint(str(module_dir))
    except (FileNotFoundError, ValueError, KeyError) as exc:
        raise ConfigError(f"{args.rllib_checkpoint}: not an RLlib checkpoint of a {MODULE_ID!r} TaskAllocRLModule "
                          f"({exc})") from None
    if not isinstance(module, TaskAllocRLModule):
        raise ConfigError(f"{args.rllib_checkpoint}: holds a {type(module).__name__}, not a TaskAllocRLModule")
    if Path(args.out).with_suffix(".json").exists() and not args.overwrite:
        raise ConfigError(f"{args.out}.json exists; pass --overwrite to replace it")
    written = export(module, Path(args.out), args.env_overrides, {"algo": "rllib_ppo",
                                                                   "exported_from": source.name})
    print(f"written: {written} and {written.with_suffix('.safetensors')}")
    return written


def main(argv: Sequence[str] | None = None) -> Any:
    parser = argparse.ArgumentParser(prog="taskalloc rllib", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("train", help="train with RLlib PPO, then write the RLlib and the project checkpoint")
    run.add_argument("--out-dir", required=True, help="folder for model.json/.safetensors, rllib/ and summary.yaml")
    run.add_argument("--overwrite", action=argparse.BooleanOptionalAction, default=False,
                     help="replace a model already in --out-dir (default: no)")
    run.add_argument("--name", default="rllib_ppo", help="run name stored in the checkpoint (default rllib_ppo)")
    run.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    run.add_argument("--set", type=mapping_argument, default={}, metavar="YAML",
                     help="scenario overrides, e.g. '{n_agents: 6, n_tasks: 12}' (default none)")
    run.add_argument("--network", choices=sorted(NETWORKS), default="attention", help="actor network")
    run.add_argument("--hidden", type=int, default=64, help="width of actor and critic (default 64)")
    run.add_argument("--iterations", type=int, default=20, help="PPO iterations (default 20)")
    run.add_argument("--train-batch", type=int, default=1024,
                     help="env steps per iteration, each one step of every agent (default 1024)")
    run.add_argument("--minibatch", type=int, default=512, help="minibatch size (default 512)")
    run.add_argument("--epochs", type=int, default=4, help="passes over a batch (default 4)")
    run.add_argument("--lr", type=float, default=3e-4, help="Adam learning rate (default 3e-4)")
    run.add_argument("--env-runners", type=int, default=0,
                     help="remote EnvRunner actors (default 0: sample in this process; raise on a cluster)")
    run.add_argument("--envs-per-runner", type=int, default=4, help="env copies per EnvRunner (default 4)")
    run.add_argument("--max-cycles", type=int, default=200, help="steps before an episode is truncated")
    run.add_argument("--seed", type=seed_argument, default=0, help="RLlib's seed (default 0)")
    run.add_argument("--eval-episodes", type=int, default=50,
                     help="validation instances the exported model is scored on (default 50)")
    for p in (run, sub.add_parser("export", help="an RLlib checkpoint of this module → a project checkpoint")):
        p.add_argument("--env-overrides", type=mapping_argument, default={"task_quitting": True, "delta": 1},
                       metavar="YAML",
                       help="protocol options the policy plays with (default '{task_quitting: true, delta: 1}')")
    exp = sub.choices["export"]
    exp.add_argument("rllib_checkpoint", help="the algorithm checkpoint folder (<out-dir>/rllib) or a module's")
    exp.add_argument("out", help="the checkpoint stem to write (OUT.json, OUT.safetensors)")
    exp.add_argument("--overwrite", action=argparse.BooleanOptionalAction, default=False,
                     help="replace OUT.json if it exists (default: no)")
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    unknown = sorted(set(args.env_overrides) - set(PROTOCOL_FIELDS))
    if unknown:
        raise ConfigError(f"--env-overrides: {unknown} are not protocol options ({', '.join(PROTOCOL_FIELDS)})")
    if args.command == "export":
        return export_checkpoint(args)
    for name in ("iterations", "train_batch", "minibatch", "epochs", "hidden", "envs_per_runner", "max_cycles",
                 "eval_episodes"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')}: got {getattr(args, name)}; allowed: an integer >= 1")
    if args.env_runners < 0:
        raise ConfigError(f"--env-runners: got {args.env_runners}; allowed: an integer >= 0")
    return train(args)


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
