"""Train a shared bidding policy: optional behaviour cloning from CBGABI, then (Maskable)PPO.

    taskalloc train --config train_small
    taskalloc train --config train_small --seed 1 --total-steps 200000 --n-envs 16 \\
        --scripted-agents "{uav_0: cbga}"

Every field of :class:`TrainConfig` can be set in the YAML file and overridden on the command line
(``--field-name value``; values are read as YAML, so ``null``, ``true``, ``1e-4`` and ``{k: v}`` work).
The run writes to ``out_dir`` (default ``runs/<name>``): ``config.yaml`` (the resolved config), checkpoints
(``taskalloc.policies.checkpoint``: JSON + safetensors) ``bc`` after behaviour cloning and ``model`` at the end,
``eval.csv`` (periodic evaluation on validation seeds against CBGABI) and ``summary.yaml`` (timings, throughput, final
evaluation); TensorBoard logs, SB3 checkpoints and the best model by validation score (``best``) go to ``log_dir``
(default ``runs/<name>``).

The script reads top to bottom like a CleanRL script: config, environments, model, imitation warm start, PPO,
saving.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Any

import torch as th
import yaml

try:
    from sb3_contrib import MaskablePPO
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.utils import set_random_seed
except ModuleNotFoundError as missing:              # name the extra, not just the module
    raise ModuleNotFoundError(f"taskalloc train needs {missing.name}: pip install 'taskalloc[train]'") from missing

from taskalloc.evaluation.episodes import evaluate, summarise
from taskalloc.evaluation.seeds import DEMO_SEED_START, TEST_SEEDS, VALIDATION_SEED_START
from taskalloc.policies.networks import count_parameters
from taskalloc.policies.teams import scripted_env_overrides, with_teammates
from taskalloc.training.bc import behaviour_cloning, collect_demonstrations
from taskalloc.training.callbacks import EpisodeMetricsCallback, PeriodicEvalCallback, RolloutProgressBar
from taskalloc.training.config import check_at_least, check_types, opt, parse, plain, prepare_out_dir
from taskalloc.training.sb3_policy import (
    BODIES,
    TaskMaskablePolicy,
    TaskPolicy,
    as_learned,
    load_actor_weights,
    save_checkpoint,
)
from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli
from taskalloc_env.observation import ObservationLayout
from taskalloc_env.rewards import check_reward_scale

ALGOS = {"maskable_ppo": (MaskablePPO, TaskMaskablePolicy), "ppo": (PPO, TaskPolicy)}


@dataclasses.dataclass
class TrainConfig:
    """Everything a run needs; the resolved copy is saved as ``config.yaml`` next to the model."""

    name: str = opt("run", "run name: the default output folder is runs/<name>-<date-time>")
    out_dir: str | None = opt(None, "folder for the checkpoints, config, eval curve and summary (default: a fresh "
                                    "runs/<name>-<date-time>); an existing model there is kept unless --overwrite")
    log_dir: str | None = opt(None, "folder for TensorBoard logs and the best model (default: out_dir/logs)")
    overwrite: bool = opt(False, "replace a model already in out_dir (needed to regenerate a committed model)")
    seed: int = opt(0, "seed of the training instances (copy c starts from seed + c), of torch and of PPO")
    # environment
    scenario: str = opt("train_small", "scenario name (configs/scenarios) or YAML path the policy trains on")
    env_overrides: dict[str, Any] = dataclasses.field(
        default_factory=lambda: {"task_quitting": True, "delta": 1},
        metadata={"help": "config fields set on top of the scenario, e.g. {task_quitting: true}"})
    reward_scale: str | float = opt(100.0, "rewards are the change of the team score divided by this: a number, "
                                           "total_reward (the instance's total task reward) or raw (1)")
    max_cycles: int | None = opt(200, "steps before an episode is truncated")
    scripted_agents: dict[str, str] = dataclasses.field(
        default_factory=dict, metadata={"help": "agents played by scripted policies, e.g. {uav_0: cbga}"})
    n_envs: int = opt(8, "environment copies; PPO slots = n_envs × learned agents per copy")
    n_procs: int = opt(0, "0: copies in this process; k: spread the copies over k subprocesses")
    # algorithm
    algo: str = opt("maskable_ppo", "maskable_ppo (sb3-contrib) | ppo (SB3, masking inside the network)")
    total_steps: int = opt(300_000, "PPO agent transitions (rounded up to whole rollouts of n_steps × slots); "
                                    "0: behaviour cloning only")
    body: str = opt("pooling", "actor network: pooling (any number of tasks) | mlp (fixed number of tasks)")
    hidden: int = opt(64, "hidden width of the network")
    learning_rate: float = opt(3e-4, "Adam learning rate")
    linear_lr: bool = opt(False, "decay the learning rate linearly to 0")
    n_steps: int = opt(128, "steps per slot in one rollout")
    batch_size: int = opt(512, "minibatch size of a PPO update")
    n_epochs: int = opt(10, "passes over a rollout per update")
    gamma: float = opt(1.0, "discount (1: the return is the final team score)")
    gae_lambda: float = opt(0.95, "GAE λ")
    clip_range: float = opt(0.2, "PPO clipping range")
    ent_coef: float = opt(0.01, "entropy bonus")
    vf_coef: float = opt(0.5, "value-loss weight")
    max_grad_norm: float = opt(0.5, "gradient-norm clipping")
    target_kl: float | None = opt(None, "stop an update early beyond this KL divergence (null: never)")
    init_from: str | None = opt(None, "start from this checkpoint's actor weights (a model name or path)")
    # imitation warm start
    bc_episodes: int = opt(0, "expert episodes for behaviour cloning; 0: no behaviour cloning")
    bc_expert: str = opt("cbgabi", "the scripted policy to clone")
    bc_epochs: int = opt(10, "behaviour-cloning epochs")
    bc_batch_size: int = opt(256, "behaviour-cloning minibatch size")
    bc_learning_rate: float = opt(1e-3, "behaviour-cloning learning rate")
    bc_ent_coef: float = opt(0.0, "entropy bonus while cloning (keeps the clone exploring for PPO)")
    # evaluation, logging
    eval_freq: int = opt(50_000, "steps between evaluations on validation seeds (0: only at the end)")
    eval_episodes: int = opt(50, "validation instances per evaluation")
    eval_baseline: str = opt("cbgabi", "the scripted policy the evaluation compares with")
    checkpoint_freq: int = opt(0, "steps between SB3 checkpoints in log_dir (0: none)")
    tensorboard: bool = opt(True, "write TensorBoard logs to log_dir")
    progress_bar: bool = opt(True, "show a progress bar")
    torch_threads: int = opt(1, "torch threads")
    verbose: int = opt(0, "SB3 verbosity")

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``TaskAllocEnv`` (scripted teammates' needs merged in)."""
        overrides = {**scripted_env_overrides(self.scripted_agents), **self.env_overrides}
        return {"scenario": self.scenario, "max_cycles": self.max_cycles, "reward_scale": self.reward_scale,
                **overrides}

    def check(self) -> None:
        """Bad values raise ``ConfigError`` naming the field and what is allowed."""
        check_types(self)
        try:
            check_reward_scale(self.reward_scale)
        except ConfigError as exc:
            raise ConfigError(f"training field 'reward_scale': {exc}") from None
        if self.algo not in ALGOS:
            raise ConfigError(f"training field 'algo': got {self.algo!r}; allowed: {' | '.join(sorted(ALGOS))}")
        if self.body not in BODIES:
            raise ConfigError(f"training field 'body': got {self.body!r}; allowed: {' | '.join(BODIES)}")
        check_at_least(self, ("n_envs", "n_steps", "batch_size", "n_epochs", "hidden", "torch_threads"), 1)
        check_at_least(self, ("total_steps", "bc_episodes", "eval_freq", "checkpoint_freq", "n_procs"), 0)
        train_seeds = set(range(self.seed, self.seed + self.n_envs))
        for label, seeds in (("test", TEST_SEEDS),
                             ("validation", range(VALIDATION_SEED_START, VALIDATION_SEED_START + self.eval_episodes)),
                             ("demonstration", range(DEMO_SEED_START, DEMO_SEED_START + self.bc_episodes))):
            if train_seeds & set(seeds):
                raise ConfigError(f"training seeds {self.seed}..{self.seed + self.n_envs - 1} overlap the {label} "
                                  f"seeds {seeds.start}..{seeds.stop - 1}; pick another --seed")


def load_config(argv: list[str] | None = None) -> TrainConfig:
    """``--config NAME_OR_FILE`` then ``--field value`` overrides (values parsed as YAML)."""
    cfg = parse(TrainConfig, argv, "taskalloc train", __doc__)
    cfg.out_dir = cfg.out_dir or f"runs/{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    cfg.log_dir = cfg.log_dir or str(Path(cfg.out_dir) / "logs")
    cfg.check()
    return cfg


def build_model(cfg: TrainConfig, venv: TaskAllocVecEnv) -> MaskablePPO | PPO:
    algo_class, policy_class = ALGOS[cfg.algo]
    lr = cfg.learning_rate
    probe = TaskAllocEnv(**cfg.env_kwargs())        # its layout, and release logits with release_actions
    model = algo_class(
        policy_class, venv, learning_rate=(lambda progress: progress * lr) if cfg.linear_lr else lr,
        n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs, gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range, ent_coef=cfg.ent_coef, vf_coef=cfg.vf_coef,
        max_grad_norm=cfg.max_grad_norm, target_kl=cfg.target_kl, seed=cfg.seed, verbose=cfg.verbose,
        device="cpu", policy_kwargs={"body": cfg.body, "hidden": cfg.hidden,
                                     "task_size": probe.observation_layout.task_size,
                                     "kinds": 3 if probe.config.release_actions else 2},
        tensorboard_log=str(Path(cfg.log_dir) / "tb") if cfg.tensorboard else None,
    )
    return model


def meta(cfg: TrainConfig) -> dict[str, Any]:
    """What a checkpoint of this run records about it (plain JSON)."""
    return {"name": cfg.name, "scenario": cfg.scenario, "algo": cfg.algo, "seed": cfg.seed,
            "env_kwargs": {k: v for k, v in cfg.env_kwargs().items() if k != "scenario"}}


def layout(cfg: TrainConfig) -> ObservationLayout:
    """The observation layout of the run's environment (what its checkpoints are trained on)."""
    return TaskAllocEnv(**cfg.env_kwargs()).observation_layout


def validation_score(model: MaskablePPO | PPO, cfg: TrainConfig) -> dict[str, float]:
    learned = as_learned(model.policy, layout(cfg), cfg.env_kwargs(), name=cfg.name)
    seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + cfg.eval_episodes)
    return summarise(evaluate(with_teammates(learned, cfg.scripted_agents), cfg.env_kwargs(), seeds))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    cfg = load_config(argv)
    out_dir, log_dir = prepare_out_dir(cfg.out_dir, cfg.overwrite), Path(cfg.log_dir)
    log_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    th.set_num_threads(cfg.torch_threads)
    set_random_seed(cfg.seed)
    summary: dict[str, Any] = {"command": " ".join(["taskalloc train", *(argv or sys.argv[1:])]),
                               "cpu_count": os.cpu_count(), "load_average_at_start": round(os.getloadavg()[0], 2)}
    t_start, cpu_start = time.perf_counter(), time.process_time()

    # -- environments: every learned agent of every copy is one slot ------------------------------------------------
    venv = TaskAllocVecEnv(make_env_fns(cfg.n_envs, **cfg.env_kwargs()), scripted_agents=cfg.scripted_agents,
                           n_procs=cfg.n_procs)
    model = build_model(cfg, venv)
    summary["parameters"] = count_parameters(model.policy)
    if cfg.init_from:
        load_actor_weights(model.policy, cfg.init_from)

    # -- imitation warm start ------------------------------------------------------------------------------------------
    if cfg.bc_episodes > 0:
        t0 = time.perf_counter()
        demos = collect_demonstrations(cfg.env_kwargs(), cfg.bc_episodes, DEMO_SEED_START, expert=cfg.bc_expert,
                                       scripted_agents=cfg.scripted_agents, gamma=cfg.gamma)
        t1 = time.perf_counter()
        history = behaviour_cloning(model.policy, demos, epochs=cfg.bc_epochs, batch_size=cfg.bc_batch_size,
                                    learning_rate=cfg.bc_learning_rate, vf_coef=cfg.vf_coef,
                                    ent_coef=cfg.bc_ent_coef, seed=cfg.seed,
                                    log=lambda row: print(f"bc epoch {row['epoch']}: nll {row['nll']:.4f} "
                                                          f"entropy {row['entropy']:.4f} "
                                                          f"accuracy {row['accuracy']:.4f} "
                                                          f"value mse {row['value_mse']:.4f}", flush=True))
        save_checkpoint(out_dir / "bc", model.policy, layout(cfg), cfg.env_kwargs(), {**meta(cfg), "stage": "bc"})
        summary["bc"] = {"samples": len(demos), "expert_score": float(demos.episode_scores.mean()),
                         "collect_seconds": round(t1 - t0, 1), "train_seconds": round(time.perf_counter() - t1, 1),
                         "final_epoch": history[-1], "validation": validation_score(model, cfg)}
        print(f"behaviour cloning: {summary['bc']}", flush=True)

    # -- PPO ---------------------------------------------------------------------------------------------------------
    if cfg.total_steps > 0:
        eval_callback = PeriodicEvalCallback(
            cfg.env_kwargs(), range(VALIDATION_SEED_START, VALIDATION_SEED_START + cfg.eval_episodes),
            cfg.eval_freq, out_dir / "eval.csv", best_path=log_dir / "best", baseline=cfg.eval_baseline,
            scripted_agents=cfg.scripted_agents, meta=meta(cfg), layout=layout(cfg))
        callbacks = [EpisodeMetricsCallback(), eval_callback]
        if cfg.checkpoint_freq > 0:
            callbacks.append(CheckpointCallback(max(1, cfg.checkpoint_freq // venv.num_envs),
                                                str(log_dir / "checkpoints"), name_prefix=cfg.name))
        rollout = cfg.n_steps * venv.num_envs
        if cfg.progress_bar:
            callbacks.append(RolloutProgressBar(rollout))
        if cfg.total_steps % rollout:
            print(f"note: total_steps {cfg.total_steps} rounds up to {-(-cfg.total_steps // rollout) * rollout}: PPO "
                  f"collects whole rollouts of n_steps × slots = {cfg.n_steps} × {venv.num_envs} = {rollout} steps",
                  file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        model.learn(cfg.total_steps, callback=CallbackList(callbacks), tb_log_name=cfg.name)
        seconds = time.perf_counter() - t0
        summary["ppo"] = {"steps": int(model.num_timesteps), "seconds": round(seconds, 1),
                          "agent_steps_per_second": round(model.num_timesteps / seconds, 1),
                          "env_steps_per_second": round(model.num_timesteps / venv.agents_per_copy / seconds, 1),
                          "baseline_score": eval_callback.baseline_score, "best_validation": eval_callback.best}
    save_checkpoint(out_dir / "model", model.policy, layout(cfg), cfg.env_kwargs(), meta(cfg))
    venv.close()
    summary["validation"] = validation_score(model, cfg)
    summary["wall_seconds"] = round(time.perf_counter() - t_start, 1)
    summary["cpu_seconds"] = round(time.process_time() - cpu_start, 1)
    summary["load_average_at_end"] = round(os.getloadavg()[0], 2)
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    print(yaml.safe_dump(plain(summary), sort_keys=False), flush=True)
    return summary


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
