"""BenchMARL MAPPO on a task of the suite, exported as a project checkpoint (the MLP actor, ``learned:<out_dir>``).

    taskalloc benchmarl train --out-dir runs/benchmarl_small --agent-steps 1000000 --seed 0

BenchMARL (tested with 1.5.2) pins ``torchrl<0.12``: it lives in its own environment (``scripts/heavy_integrations.sh``
creates one); the exported checkpoint loads without it. The run is BenchMARL's MAPPO as its user gets it
(``MappoConfig.get_from_yaml()``, ``ExperimentConfig.get_from_yaml()``: 6000 frames per iteration, 45 epochs of
400-frame minibatches, lr 5e-5, a centralised critic on the global state, shared parameters), with these changes
(``changed_from_benchmarl_defaults`` in ``config.yaml``): the budget, gamma = 1 (the episode's return is its score,
as in the project's MAPPO and SB3 runs), evaluation and rendering off, the csv logger only, one torch thread, and the
actor ``MlpConfig(num_cells=[256, 256], ReLU, Linear)``, which is layer for layer the project's ``MlpActor``
(``mlp``, hidden 256). The env is the suite task's config plus the protocol options the policy plays with
(``--env-overrides``, default ``{task_quitting: true, delta: 1}`` as the other training stacks), through
``taskalloc_env.wrappers.benchmarl.TaskAllocTask``.

A frame is one env step of every agent: the budget ``--agent-steps`` is frames × agents. BenchMARL collects whole
iterations, so the run ends after ``ceil(frames / 6000)`` of them; ``summary.yaml`` states what was collected.

Export: the actor's weights (``…mlp.params.{0,2,4}.{weight,bias}``, BenchMARL's shared ``MultiAgentMLP``) are copied
into an ``MlpActor`` (``actor_from_state_dict``) and saved with ``taskalloc.policies.checkpoint.save``; before
saving, the ``MlpActor``'s masked logits are checked against BenchMARL's actor on observations of real episodes
(``MAX_LOGIT_DIFF``), and the run fails if they differ. ``<out_dir>`` then holds ``model.json``,
``model.safetensors``, ``config.yaml``, ``summary.yaml`` and BenchMARL's own folder (``benchmarl/``: csv logs).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch as th
import yaml

from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.learned import LearnedPolicy
from taskalloc.policies.networks import MASKED_LOGIT, MlpActor
from taskalloc.training.config import plain, prepare_out_dir
from taskalloc_env import suite
from taskalloc_env.config import to_mapping
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, mapping_argument, run_cli, seed_argument

HIDDEN = 256                    # the actor's width: MlpConfig(num_cells=[256, 256]) = MlpActor(hidden=256)
MAX_LOGIT_DIFF = 1e-5           # exported vs BenchMARL masked logits, largest absolute difference allowed (ours)
CHECK_EPISODES = 4              # real episodes whose observations the export check runs on
GAMMA = 1.0                     # as configs/training/mappo_small_pooling.yaml and train_small.yaml
DEFAULT_ENV_OVERRIDES = {"task_quitting": True, "delta": 1}
MACHINE = "2 shared CPU cores (other runs on the same machine), 1 torch thread"
# the MultiAgentMLP's shared parameters: params.<layer index in the Sequential>.<weight|bias>
PARAM_KEY = re.compile(r"(?:^|\.)mlp\.params\.(\d+)\.(weight|bias)$")
LINEAR_INDICES = (0, 2, 4)      # Linear, ReLU, Linear, ReLU, Linear: the Linears of MlpActor.actor


def env_config(task: suite.SuiteTask, env_overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``parallel_env``'s keywords: the suite task's config (``TaskAllocTask``'s default) plus ``env_overrides``."""
    return {"scenario": to_mapping(task.config()), **env_overrides}


def actor_from_state_dict(state: Mapping[str, Any], obs_size: int, n_actions: int) -> MlpActor:
    """An ``MlpActor`` holding the weights of BenchMARL's shared MLP actor (its policy's ``state_dict``)."""
    weights = {}
    for key, value in state.items():
        found = PARAM_KEY.search(key)
        if found:
            weights[f"actor.{found[1]}.{found[2]}"] = value
    indices = sorted({int(k.split(".")[1]) for k in weights})
    if tuple(indices) != LINEAR_INDICES:
        raise ConfigError(f"BenchMARL actor has linear layers at {indices}, expected {list(LINEAR_INDICES)} "
                          "(an MlpConfig with two hidden layers and shared parameters)")
    hidden = weights["actor.0.weight"].shape[0]
    actor = MlpActor(obs_size, n_actions, hidden=hidden)
    try:
        actor.load_state_dict({k: th.as_tensor(v).detach().clone().float() for k, v in weights.items()}, strict=True)
    except RuntimeError as exc:
        raise ConfigError(f"BenchMARL actor does not fit MlpActor({obs_size}, {n_actions}, {hidden}): "
                          f"{str(exc).splitlines()[-1].strip()}") from None
    return actor.eval()


def real_observations(config: Mapping[str, Any], seeds: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Observations (B, N, D) and masks (B, N, A) of every step of episodes with uniformly random valid actions."""
    env = TaskAllocEnv(**config)
    obs_rows, mask_rows = [], []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        obs, _ = env.reset(seed=int(seed))
        while env.agents:
            agents = sorted(obs)
            obs_rows.append(np.stack([obs[a]["observation"] for a in agents]))
            mask_rows.append(np.stack([obs[a]["action_mask"] for a in agents]))
            actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
            obs, *_ = env.step(actions)
    return np.asarray(obs_rows, dtype=np.float32), np.asarray(mask_rows) > 0


def check_export(model: Any, group: str, actor: MlpActor, observation: np.ndarray, mask: np.ndarray) -> float:
    """Largest |masked logit difference| between BenchMARL's actor model and the exported ``MlpActor``; raises
    when it exceeds ``MAX_LOGIT_DIFF``."""
    from tensordict import TensorDict

    obs, valid = th.as_tensor(observation), th.as_tensor(mask)
    td = TensorDict({(group, "observation", "observation"): obs, (group, "action_mask"): valid},
                    batch_size=[obs.shape[0]])
    with th.no_grad():
        theirs = model(td).get((group, "logits")).masked_fill(~valid, MASKED_LOGIT)
        ours = actor(obs.reshape(-1, obs.shape[-1]), valid.reshape(-1, valid.shape[-1])).reshape(theirs.shape)
    diff = float((theirs - ours).abs().max())
    if not diff < MAX_LOGIT_DIFF:
        raise RuntimeError(f"exported MlpActor differs from BenchMARL's actor: max |masked logit diff| {diff:.3g} "
                           f">= {MAX_LOGIT_DIFF} on {obs.shape[0]} steps")
    return diff


def _names(value: Any) -> Any:
    """A config as plain YAML: classes by their dotted name."""
    if isinstance(value, Mapping):
        return {str(k): _names(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_names(v) for v in value]
    if isinstance(value, type):
        return f"{value.__module__}.{value.__qualname__}"
    return plain(value) if value is None or isinstance(value, (bool, int, float, str)) else repr(value)


def train(args: argparse.Namespace) -> dict[str, Any]:
    try:
        from benchmarl.algorithms import MappoConfig
        from benchmarl.experiment import Experiment, ExperimentConfig
        from benchmarl.models.mlp import Mlp, MlpConfig

        from taskalloc_env.wrappers.benchmarl import TaskAllocTask
    except ModuleNotFoundError as exc:
        raise ConfigError(f"taskalloc benchmarl needs BenchMARL ({exc.name!r} is not installed): run it with the "
                          "venv of scripts/heavy_integrations.sh benchmarl") from None

    task = suite.task(args.task)
    config = env_config(task, args.env_overrides)
    probe = TaskAllocEnv(**config)
    n_agents, layout = len(probe.possible_agents), probe.observation_layout
    obs_size = int(probe.observation_space(probe.possible_agents[0])["observation"].shape[0])
    n_actions = int(probe.action_space(probe.possible_agents[0]).n)
    if args.agent_steps % n_agents:
        raise ConfigError(f"--agent-steps: {args.agent_steps} is not a multiple of the task's {n_agents} agents")
    frames = args.agent_steps // n_agents
    out_dir = prepare_out_dir(args.out_dir, args.overwrite)
    os.environ["OMP_NUM_THREADS"] = "1"
    th.set_num_threads(1)

    experiment_cfg = ExperimentConfig.get_from_yaml()
    changed = {"max_n_frames": frames, "gamma": GAMMA, "evaluation": False, "render": False, "loggers": ["csv"],
               "create_json": False, "save_folder": str((out_dir / "benchmarl").resolve())}
    for key, value in changed.items():
        setattr(experiment_cfg, key, value)
    (out_dir / "benchmarl").mkdir(exist_ok=True)
    algorithm_cfg = MappoConfig.get_from_yaml()
    actor_cfg = MlpConfig(num_cells=[HIDDEN, HIDDEN], activation_class=th.nn.ReLU, layer_class=th.nn.Linear)
    critic_cfg = MlpConfig.get_from_yaml()
    member = task.name.upper()
    saved = {"task": task.id, "benchmarl_task": f"TaskAllocTask.{member}", "env_config": config,
             "changed_from_benchmarl_defaults": {**changed, "actor_model": "MlpConfig(num_cells=[256, 256], "
                                                 "activation_class=ReLU, layer_class=Linear)",
                                                 "torch_threads": 1, "OMP_NUM_THREADS": 1},
             "experiment": dataclasses.asdict(experiment_cfg), "algorithm": dataclasses.asdict(algorithm_cfg),
             "actor_model": dataclasses.asdict(actor_cfg), "critic_model": dataclasses.asdict(critic_cfg),
             "seed": args.seed}
    (out_dir / "config.yaml").write_text(yaml.safe_dump(_names(saved), sort_keys=False))

    experiment = Experiment(task=getattr(TaskAllocTask, member).get_task(config=config),
                            algorithm_config=algorithm_cfg, model_config=actor_cfg, critic_model_config=critic_cfg,
                            seed=args.seed, config=experiment_cfg)
    groups = list(experiment.group_map)
    if len(groups) != 1:
        raise ConfigError(f"{task.id}: BenchMARL made agent groups {groups}; the export needs one shared group")
    t0, cpu0 = time.perf_counter(), time.process_time()
    experiment.run()
    seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - cpu0

    actor = actor_from_state_dict(experiment.policy.state_dict(), obs_size, n_actions)
    model = next(m for m in experiment.policy.modules() if isinstance(m, Mlp))
    observation, mask = real_observations(config, task.validation_seeds[:CHECK_EPISODES])
    diff = check_export(model, groups[0], actor, observation, mask)
    collected = int(experiment.total_frames)
    meta = {"name": args.name, "algo": "benchmarl_mappo", "seed": args.seed, "task": task.id,
            "agent_steps": collected * n_agents, "frames": collected}
    written = checkpoint.save(out_dir / "model", actor, layout.own_names, layout.task_names, args.env_overrides,
                              meta)

    seeds = task.validation_seeds[:args.eval_episodes]
    scenario = {"scenario": config["scenario"]}
    policy = LearnedPolicy(actor, layout.own_names, layout.task_names, args.env_overrides, meta,  # safetensors
                           name=f"learned:{out_dir}")      # may be missing here: the saved actor, in memory
    validation = summarise_scores(policy, scenario, seeds)
    baseline = summarise_scores(make_policy(task.normaliser), scenario, seeds)
    summary = {"command": "taskalloc benchmarl " + " ".join(args.argv), "task": task.id, "seed": args.seed,
               "agent_steps_requested": args.agent_steps, "agent_steps": collected * n_agents, "frames": collected,
               "iterations": int(experiment.n_iters_performed), "wall_seconds": round(seconds, 1),
               "cpu_seconds": round(cpu_seconds, 1), "frames_per_second": round(collected / seconds, 1),
               "machine": MACHINE, "export_check": {"steps": int(observation.shape[0]), "max_abs_logit_diff": diff},
               "validation": {"seeds": f"{seeds[0]}..{seeds[-1]} ({len(seeds)}, the suite's validation seeds)",
                              "score": validation, task.normaliser: baseline}}
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    print(f"written: {written}; {collected} frames ({collected * n_agents} agent steps) in {seconds:.0f} s; export "
          f"check max |logit diff| {diff:.2g}; validation score {validation:.2f} ({task.normaliser} {baseline:.2f} "
          f"on the same {len(seeds)} seeds)")
    return summary


def summarise_scores(policy: Any, scenario: Mapping[str, Any], seeds: Sequence[int]) -> float:
    """Mean score of ``policy`` on ``seeds`` (its own env_overrides applied)."""
    from taskalloc.evaluation.episodes import evaluate, summarise

    return float(summarise(evaluate(policy, scenario, seeds))["score"])


def _task_id(text: str) -> str:
    """``Small`` or ``taskalloc/Small-v0`` → the suite id."""
    return text if "/" in text else f"taskalloc/{text}-{suite.SUITE}"


def main(argv: Sequence[str] | None = None) -> Any:
    parser = argparse.ArgumentParser(prog="taskalloc benchmarl", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("train", help="train BenchMARL MAPPO, then export the actor as a project checkpoint")
    run.add_argument("--out-dir", required=True, help="folder for model.json/.safetensors, config, summary.yaml")
    run.add_argument("--overwrite", action=argparse.BooleanOptionalAction, default=False,
                     help="replace a model already in --out-dir (default: no)")
    run.add_argument("--name", default="benchmarl_mappo", help="run name stored in the checkpoint")
    run.add_argument("--task", type=_task_id, default="Small", help="suite task, Small or taskalloc/Small-v0 "
                     "(default Small)")
    run.add_argument("--agent-steps", type=int, default=1_000_000,
                     help="budget in agent steps = frames x agents (default 1000000)")
    run.add_argument("--seed", type=seed_argument, default=0, help="BenchMARL's seed (default 0)")
    run.add_argument("--env-overrides", type=mapping_argument, default=dict(DEFAULT_ENV_OVERRIDES), metavar="YAML",
                     help="protocol options the policy plays with (default '{task_quitting: true, delta: 1}')")
    run.add_argument("--eval-episodes", type=int, default=50,
                     help="validation seeds of the task the exported model is scored on (default 50)")
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)
    unknown = sorted(set(args.env_overrides) - set(checkpoint.POLICY_OPTIONS))
    if unknown:
        raise ConfigError(f"--env-overrides: {unknown} are not options a policy plays by "
                          f"({', '.join(checkpoint.POLICY_OPTIONS)})")
    suite.task(args.task)
    for name in ("agent_steps", "eval_episodes"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')}: got {getattr(args, name)}; allowed: an integer >= 1")
    if args.eval_episodes > suite.task(args.task).episodes:
        raise ConfigError(f"--eval-episodes: got {args.eval_episodes}; the task has "
                          f"{suite.task(args.task).episodes} validation seeds")
    return train(args)


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
