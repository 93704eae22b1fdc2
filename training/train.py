"""Train a shared bidding policy: optional behaviour cloning from CBGABI, then (Maskable)PPO.

    python -m training.train --config configs/training/train_small.yaml
    python -m training.train --config configs/training/train_small.yaml --seed 1 --total-steps 200000 \\
        --n-envs 16 --scripted-agents "{uav_0: cbga}"

Every field of :class:`TrainConfig` can be set in the YAML file and overridden on the command line
(``--field-name value``; values are read as YAML, so ``null``, ``true``, ``1e-4`` and ``{k: v}`` work).
The run writes to ``out_dir`` (default ``runs/<name>``): ``config.yaml`` (the resolved config), checkpoints
(``policies.checkpoint``: JSON + safetensors) ``bc`` after behaviour cloning and ``model`` at the end, ``eval.csv``
(periodic evaluation on validation seeds against CBGABI) and ``summary.yaml`` (timings, throughput, final
evaluation); TensorBoard logs, SB3 checkpoints and the best model by validation score (``best``) go to ``log_dir``
(default ``runs/<name>``).

The script reads top to bottom like a CleanRL script: config, environments, model, imitation warm start, PPO,
saving.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import typing
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
import yaml
from sb3_contrib import MaskablePPO
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
from stable_baselines3.common.utils import set_random_seed

from evaluation.episodes import evaluate, summarise
from evaluation.seeds import DEMO_SEED_START, TEST_SEEDS, VALIDATION_SEED_START
from policies.networks import count_parameters
from policies.teams import scripted_env_overrides, with_teammates
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.observation import ObservationLayout
from training.bc import behaviour_cloning, collect_demonstrations
from training.callbacks import EpisodeMetricsCallback, PeriodicEvalCallback
from training.sb3_policy import (
    TaskMaskablePolicy,
    TaskPolicy,
    as_learned,
    load_actor_weights,
    save_checkpoint,
)
from training.vec_env import TaskAllocVecEnv, make_env_fns

ALGOS = {"maskable_ppo": (MaskablePPO, TaskMaskablePolicy), "ppo": (PPO, TaskPolicy)}


@dataclasses.dataclass
class TrainConfig:
    """Everything a run needs; the resolved copy is saved as ``config.yaml`` next to the model."""

    name: str = "run"
    out_dir: str | None = None               # small artefacts (model, config, eval curve); default runs/<name>
    log_dir: str | None = None               # TensorBoard, checkpoints, best model; default runs/<name>
    seed: int = 0
    # environment
    scenario: str = "train_small"
    env_overrides: dict[str, Any] = dataclasses.field(default_factory=lambda: {"task_quitting": True, "delta": 1})
    reward_scale: float = 100.0              # rewards are Δscore / reward_scale
    max_cycles: int | None = 200
    scripted_agents: dict[str, str] = dataclasses.field(default_factory=dict)   # e.g. {uav_0: cbga}
    n_envs: int = 8                          # env copies; slots = n_envs × learned agents per copy
    n_procs: int = 0                         # 0: copies in this process; k: spread over k subprocesses
    # algorithm
    algo: str = "maskable_ppo"               # maskable_ppo | ppo
    total_steps: int = 300_000               # PPO steps (agent transitions); 0: behaviour cloning only
    body: str = "pooling"                    # pooling | mlp
    hidden: int = 64
    learning_rate: float = 3e-4
    linear_lr: bool = False                  # decay the learning rate linearly to 0
    n_steps: int = 128
    batch_size: int = 512
    n_epochs: int = 10
    gamma: float = 1.0
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float | None = None
    init_from: str | None = None             # start from this checkpoint's weights
    # imitation warm start
    bc_episodes: int = 0                     # expert episodes; 0: no behaviour cloning
    bc_expert: str = "cbgabi"
    bc_epochs: int = 10
    bc_batch_size: int = 256
    bc_learning_rate: float = 1e-3
    bc_ent_coef: float = 0.0                 # entropy bonus while cloning (keeps the clone exploring for PPO)
    # evaluation, logging
    eval_freq: int = 50_000
    eval_episodes: int = 50
    eval_baseline: str = "cbgabi"
    checkpoint_freq: int = 0
    tensorboard: bool = True
    progress_bar: bool = True
    torch_threads: int = 1
    verbose: int = 0

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of ``TaskAllocEnv`` (scripted teammates' needs merged in)."""
        overrides = {**scripted_env_overrides(self.scripted_agents), **self.env_overrides}
        return {"scenario": self.scenario, "max_cycles": self.max_cycles, "reward_scale": self.reward_scale,
                **overrides}

    def check(self) -> None:
        if self.algo not in ALGOS:
            raise SystemExit(f"algo {self.algo!r} is not one of {sorted(ALGOS)}")
        train_seeds = set(range(self.seed, self.seed + self.n_envs))
        for label, seeds in (("test", TEST_SEEDS),
                             ("validation", range(VALIDATION_SEED_START, VALIDATION_SEED_START + self.eval_episodes)),
                             ("demonstration", range(DEMO_SEED_START, DEMO_SEED_START + self.bc_episodes))):
            if train_seeds & set(seeds):
                raise SystemExit(f"training seeds {self.seed}..{self.seed + self.n_envs - 1} overlap the {label} "
                                 f"seeds {seeds.start}..{seeds.stop - 1}; pick another --seed")


def load_config(argv: list[str] | None = None) -> TrainConfig:
    """``--config file.yaml`` then ``--field value`` overrides (values parsed as YAML)."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", type=Path, help="YAML file with TrainConfig fields")
    for field in dataclasses.fields(TrainConfig):
        parser.add_argument(f"--{field.name.replace('_', '-')}", dest=field.name, type=yaml.safe_load,
                            default=argparse.SUPPRESS, metavar="VALUE", help=f"(default: {_default(field)})")
    args = vars(parser.parse_args(argv))
    values: dict[str, Any] = {}
    path = args.pop("config", None)
    if path is not None:
        values = yaml.safe_load(path.read_text()) or {}
        unknown = sorted(set(values) - {f.name for f in dataclasses.fields(TrainConfig)})
        if unknown:
            raise SystemExit(f"{path}: unknown fields {unknown}")
    values.update(args)
    cfg = TrainConfig(**{k: _coerce(k, v) for k, v in values.items()})
    cfg.out_dir = cfg.out_dir or f"runs/{cfg.name}"
    cfg.log_dir = cfg.log_dir or f"runs/{cfg.name}"
    cfg.check()
    return cfg


def _coerce(name: str, value: Any) -> Any:
    """YAML reads ``1e-3`` as a string and ``1`` as an int; float fields get floats."""
    hint = typing.get_type_hints(TrainConfig)[name]
    wants_float = hint is float or float in typing.get_args(hint)
    if wants_float and isinstance(value, (str, int)) and not isinstance(value, bool):
        try:
            return float(value)
        except ValueError:
            raise SystemExit(f"--{name.replace('_', '-')}: {value!r} is not a number") from None
    return value


def _default(field: dataclasses.Field) -> Any:
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def build_model(cfg: TrainConfig, venv: TaskAllocVecEnv) -> MaskablePPO | PPO:
    algo_class, policy_class = ALGOS[cfg.algo]
    lr = cfg.learning_rate
    model = algo_class(
        policy_class, venv, learning_rate=(lambda progress: progress * lr) if cfg.linear_lr else lr,
        n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs, gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range, ent_coef=cfg.ent_coef, vf_coef=cfg.vf_coef,
        max_grad_norm=cfg.max_grad_norm, target_kl=cfg.target_kl, seed=cfg.seed, verbose=cfg.verbose,
        device="cpu", policy_kwargs={"body": cfg.body, "hidden": cfg.hidden},
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
    out_dir, log_dir = Path(cfg.out_dir), Path(cfg.log_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    log_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    th.set_num_threads(cfg.torch_threads)
    set_random_seed(cfg.seed)
    summary: dict[str, Any] = {"command": " ".join(["python -m training.train", *(argv or sys.argv[1:])])}
    t_start = time.perf_counter()

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
        t0 = time.perf_counter()
        model.learn(cfg.total_steps, callback=CallbackList(callbacks), progress_bar=cfg.progress_bar,
                    tb_log_name=cfg.name)
        seconds = time.perf_counter() - t0
        summary["ppo"] = {"steps": int(model.num_timesteps), "seconds": round(seconds, 1),
                          "agent_steps_per_second": round(model.num_timesteps / seconds, 1),
                          "env_steps_per_second": round(model.num_timesteps / venv.agents_per_copy / seconds, 1),
                          "baseline_score": eval_callback.baseline_score, "best_validation": eval_callback.best}
    save_checkpoint(out_dir / "model", model.policy, layout(cfg), cfg.env_kwargs(), meta(cfg))
    venv.close()
    summary["validation"] = validation_score(model, cfg)
    summary["wall_seconds"] = round(time.perf_counter() - t_start, 1)
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(_plain(summary), sort_keys=False))
    print(yaml.safe_dump(_plain(summary), sort_keys=False), flush=True)
    return summary


def _plain(value: Any) -> Any:
    """numpy scalars → Python numbers, for YAML."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


if __name__ == "__main__":
    main()
