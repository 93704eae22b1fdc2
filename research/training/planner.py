"""Learning the round-0 plan: supervised, from solver labels (ours; the local plan of ``research.policies.local_plan``
learned).

    python -m research.training.planner --config planner_default --seed 0 --out-dir runs/planner_default/seed0

Before any message (round 0, thesis Alg 5) an agent knows its own start, speed and equipment and the tasks, not
where its teammates are. ``research.policies.local_plan`` plans its first bundle by solving teams drawn around its own
start; this run learns that plan instead. It draws training instances (seeds 100000 + 100000 · seed + k), solves each
(``solver``: the exact optimum, or the group search ``taskalloc.policies.local_search`` with ``LNS_ITERATIONS`` per
start at sizes ``exact`` cannot reach), plays round 0 with every agent bidding along its path of that allocation
(``research.policies.oracle.bid_along``) and keeps every round-0 state in which the agent may bid: its observation, the
tasks it may bid on and which of them are on its path. The actor's bid logits are fitted as per-task log-odds with
binary cross-entropy over the allowed tasks, so the network estimates, from what the agent sees, the probability that a
task is on its path, the share the local plan estimates by sampling. Play (``research.policies.round_zero``): bid the
most likely allowed task while that probability is ≥ ``threshold`` (re-estimated at every step, or planned once at the
agent's first round-0 state: ``replan``), then hand over to ``then`` (by default the committed MAPPO bidder) from round
1 on.

The run writes ``model.json`` + ``model.safetensors`` (``learned:<out_dir>`` plays the planner, then ``then``),
``planner.csv`` (one row per epoch: training and validation loss), ``config.yaml`` and ``summary.yaml`` (the
validation scores of the planner then ``then``, of ``then`` alone and of CBGABI).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import os
import resource
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
import yaml
from torch import nn

from research import CONFIGS
from research.policies.local_plan import SOLVERS
from research.policies.oracle import bid_along
from research.policies.round_zero import PLANNER, bid_log_odds, is_threshold
from research.policies.symmetry import is_square, square_symmetries
from taskalloc.evaluation.episodes import evaluate
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.seeds import DEMO_SEED_START, VALIDATION_SEED_START
from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.base import stack_observations
from taskalloc.training.config import (
    check_at_least,
    check_protocol_options,
    check_types,
    opt,
    parse,
    plain,
    prepare_out_dir,
)
from taskalloc.training.mappo import check_actor, make_actor
from taskalloc_env.actions import bid_columns
from taskalloc_env.allocation import on_paths
from taskalloc_env.config import resolve_config, to_mapping
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli
from taskalloc_env.observation import ObservationLayout

COLUMNS = ("epoch", "loss", "validation_loss", "wall_time")
MAX_GRAD_NORM = 1.0
CHUNK = 50          # instances per labelling task


@dataclasses.dataclass
class PlannerConfig:
    """Everything a run needs; the resolved copy is saved as ``config.yaml`` next to the model."""

    name: str = opt("planner", "run name: the default output folder is runs/<name>-<date-time>")
    out_dir: str | None = opt(None, "folder for the model, config, table and summary")
    overwrite: bool = opt(False, "replace a model already in out_dir")
    seed: int = opt(0, "seed of torch and of the training instances (100000 + 100000 · seed + k)")
    scenario: str = opt("default", "the scenario the plans are learned on")
    env_overrides: dict[str, Any] = dataclasses.field(
        default_factory=lambda: {"task_quitting": True, "delta": 1},
        metadata={"help": "protocol options the planner and its successor play with, saved in the checkpoint"})
    solver: str = opt("lns", "the labels' solver: exact (small scenarios) | lns (policies.local_plan.lns_draw)")
    then: str = opt("learned:mappo_small_pooling_1m", "the policy that takes over from round 1 on")
    threshold: float = opt(0.5, "bid while the most likely allowed task's probability is at least this")
    replan: bool = opt(True, "estimate afresh at every round-0 step (true) or plan once at the agent's first "
                             "round-0 state, the local plan's way (false); policies.round_zero")
    actor: str = opt("pooling", "actor network: attention | pooling (policies.networks)")
    hidden: int = opt(64, "width of the actor")
    heads: int = opt(4, "attention heads")
    layers: int = opt(2, "self-attention layers")
    episodes: int = opt(8000, "training instances")
    epochs: int = opt(30, "passes over the data set")
    batch_size: int = opt(256, "minibatch size")
    learning_rate: float = opt(1e-3, "Adam learning rate")
    anneal_lr: bool = opt(False, "decay the learning rate to 0 over the epochs along a cosine (CosineAnnealingLR)")
    augment: bool = opt(False, "fit each minibatch state under one of the square floor's 8 mirrors and quarter turns, "
                               "drawn afresh every epoch (policies.symmetry; needs a square floor)")
    eval_episodes: int = opt(40, "validation instances (their states give the validation loss; played at the end)")
    label_cache: str | None = opt(None, "folder that keeps the labelled states, one .npz per scenario, protocol "
                                        "options, solver and seeds, reused by a later run with the same four "
                                        "(e.g. another network on the same data); none: label afresh")
    jobs: int = opt(2, "processes that label instances")
    torch_threads: int = opt(2, "torch threads")

    def check(self) -> None:
        check_types(self)
        check_at_least(self, ("hidden", "heads", "layers", "episodes", "epochs", "batch_size", "eval_episodes",
                              "jobs", "torch_threads"), 1)
        check_at_least(self, ("seed",), 0)
        check_actor(self)
        check_protocol_options(self)
        if self.solver not in SOLVERS:
            raise ConfigError(f"training field 'solver': got {self.solver!r}; allowed: {' | '.join(SOLVERS)}")
        if not is_threshold(self.threshold):
            raise ConfigError(f"training field 'threshold': got {self.threshold!r}; allowed: a number in (0, 1)")
        if self.learning_rate <= 0:
            raise ConfigError(f"training field 'learning_rate': got {self.learning_rate!r}; allowed: a number > 0")
        if self.augment and not is_square(arena := resolve_config(self.scenario).arena):
            raise ConfigError(f"training field 'augment': the symmetries need a square floor, scenario "
                              f"{self.scenario!r} has arena {arena}")


@dataclasses.dataclass
class Plans:
    """Round-0 states in which an agent may bid: observation, the tasks it may bid on, those on its path."""

    obs: np.ndarray         # (S, D) float32
    allowed: np.ndarray     # (S, M) bool
    on_path: np.ndarray     # (S, M) bool, a subset of allowed

    @classmethod
    def concat(cls, parts: Sequence[Plans]) -> Plans:
        return cls(*(np.concatenate(arrays) for arrays in zip(*(dataclasses.astuple(p) for p in parts))))


def label(job: tuple[str, dict[str, Any], str, Sequence[int]]) -> Plans:
    """The round-0 states of ``seeds`` with every agent bidding along its path of ``solver``'s allocation."""
    scenario, overrides, solver, seeds = job
    env = TaskAllocEnv(resolve_config(scenario), **overrides)
    agents, m = env.possible_agents, env.observation_layout.n_tasks
    round_column = env.observation_layout.own_names.index("round")
    parts = []
    for seed in seeds:
        observations, _ = env.reset(seed=int(seed))
        paths = SOLVERS[solver](env.scenario, env.config).paths
        on_path = on_paths(paths, m)
        while env.agents:
            obs, masks = stack_observations(observations, agents)
            if obs[0, round_column] > 0:
                break
            allowed = masks[:, bid_columns(m)] > 0
            rows = allowed.any(axis=1)
            parts.append(Plans(obs[rows].astype(np.float32), allowed[rows], (on_path & allowed)[rows]))
            observations, *_ = env.step({a: bid_along(paths[env.agent_index[a]], observations[a]["action_mask"])
                                         for a in agents})
    return Plans.concat(parts)


def labelled(cfg: PlannerConfig, seeds: Sequence[int]) -> Plans:
    """``label`` over chunks of ``seeds`` in ``cfg.jobs`` processes, in seed order; read from and kept in
    ``cfg.label_cache`` when it is set."""
    if cfg.label_cache is None:
        return label_all(cfg, seeds)
    key = {"scenario": to_mapping(resolve_config(cfg.scenario)), "env_overrides": cfg.env_overrides,
           "solver": cfg.solver, "seeds": [int(k) for k in seeds]}
    text = json.dumps(key, sort_keys=True, default=str)
    path = Path(cfg.label_cache) / f"{hashlib.sha256(text.encode()).hexdigest()[:16]}.npz"
    if path.exists():
        with np.load(path) as kept:
            if str(kept["key"]) != text:
                raise ConfigError(f"label cache {str(path)!r} holds other states (its key differs); remove it")
            return Plans(kept["obs"], kept["allowed"], kept["on_path"])
    plans = label_all(cfg, seeds)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f"{path.stem}.{os.getpid()}.partial.npz")    # runs side by side write their own
    np.savez(partial, key=np.array(text), **dataclasses.asdict(plans))
    partial.replace(path)       # a run stopped while writing leaves no half file under the key's name
    return plans


def label_all(cfg: PlannerConfig, seeds: Sequence[int]) -> Plans:
    """``label`` over chunks of ``seeds`` in ``cfg.jobs`` processes, in seed order."""
    chunks = [(cfg.scenario, dict(cfg.env_overrides), cfg.solver, list(seeds[k: k + CHUNK]))
              for k in range(0, len(seeds), CHUNK)]
    return Plans.concat(list(parallel_map(label, chunks, cfg.jobs)))


def plan_loss(actor: nn.Module, obs: th.Tensor, allowed: th.Tensor, on_path: th.Tensor) -> th.Tensor:
    """Binary cross-entropy of the bid log-odds against membership of the path, over the allowed tasks."""
    losses = nn.functional.binary_cross_entropy_with_logits(bid_log_odds(actor, obs), on_path.float(),
                                                            reduction="none")
    return (losses * allowed).sum() / allowed.sum()


def tensors(data: Plans) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    return th.as_tensor(data.obs), th.as_tensor(data.allowed), th.as_tensor(data.on_path)


def fit_epoch(actor: nn.Module, optimizer: th.optim.Optimizer, data: tuple[th.Tensor, ...], batch_size: int,
              rng: np.random.Generator, symmetries: tuple[th.Tensor, ...] | None = None) -> float:
    """One pass over ``data`` in random minibatches, each state turned by a random one of ``symmetries``
    (permutations, signs, shifts: ``research.policies.symmetry.square_symmetries``) when given; the mean loss per
    allowed
    task. The labels stay: a turn moves the tasks, not their indices."""
    obs, allowed, on_path = data
    total, weight = 0.0, 0.0
    order = rng.permutation(len(obs))
    for start in range(0, len(obs), batch_size):
        idx = th.as_tensor(order[start: start + batch_size])
        batch = obs[idx]
        if symmetries is not None:
            permutations, signs, shifts = symmetries
            k = th.as_tensor(rng.integers(len(permutations), size=len(idx)))
            batch = th.gather(batch, 1, permutations[k]) * signs[k] + shifts[k]
        loss = plan_loss(actor, batch, allowed[idx], on_path[idx])
        optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(actor.parameters(), MAX_GRAD_NORM)
        optimizer.step()
        n = float(allowed[idx].sum())
        total, weight = total + loss.item() * n, weight + n
    return total / weight


def symmetry_tensors(layout: ObservationLayout) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
    """``research.policies.symmetry.square_symmetries`` of ``layout`` as tensors ``fit_epoch`` turns states with."""
    permutations, signs, shifts = square_symmetries(layout.own_names, layout.task_names, layout.n_tasks)
    return th.as_tensor(permutations), th.as_tensor(signs, dtype=th.float32), th.as_tensor(shifts, dtype=th.float32)


def cpu_seconds() -> float:
    """CPU time of this process and of the labelling processes it waited for."""
    return sum(u.ru_utime + u.ru_stime for u in (resource.getrusage(resource.RUSAGE_SELF),
                                                    resource.getrusage(resource.RUSAGE_CHILDREN)))


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    cfg = parse(PlannerConfig, argv, "python -m research.training.planner", __doc__, configs=CONFIGS)
    cfg.out_dir = cfg.out_dir or f"runs/{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    cfg.check()
    try:
        then = make_policy(cfg.then)
    except ValueError as exc:      # a CheckpointError is a ConfigError already
        raise ConfigError(f"training field 'then': {exc}") from None
    out_dir = prepare_out_dir(cfg.out_dir, cfg.overwrite)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    th.set_num_threads(cfg.torch_threads)
    th.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    t0, load = time.perf_counter(), round(os.getloadavg()[0], 2)

    first = DEMO_SEED_START + 100_000 * cfg.seed
    train = labelled(cfg, range(first, first + cfg.episodes))
    val_seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + cfg.eval_episodes)
    val = tensors(labelled(cfg, val_seeds))
    label_seconds = time.perf_counter() - t0
    print(f"{len(train.obs)} round-0 states from {cfg.episodes} instances ({label_seconds:.0f} s), "
          f"{train.on_path.sum() / train.allowed.sum():.3f} of the allowed tasks on the path", flush=True)

    layout = TaskAllocEnv(resolve_config(cfg.scenario), **cfg.env_overrides).observation_layout
    actor = make_actor(cfg, layout.own_size, layout.task_size)
    optimizer = th.optim.Adam(actor.parameters(), lr=cfg.learning_rate)
    schedule = th.optim.lr_scheduler.CosineAnnealingLR(optimizer, cfg.epochs) if cfg.anneal_lr else None
    data = tensors(train)
    symmetries = symmetry_tensors(layout) if cfg.augment else None
    with open(out_dir / "planner.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(COLUMNS)
        for epoch in range(cfg.epochs):
            actor.train()
            loss = fit_epoch(actor, optimizer, data, cfg.batch_size, rng, symmetries)
            if schedule is not None:
                schedule.step()
            actor.eval()
            with th.no_grad():
                val_loss = plan_loss(actor, *val).item()
            writer.writerow([epoch, f"{loss:.6g}", f"{val_loss:.6g}", round(time.perf_counter() - t0, 1)])
            fh.flush()
            print(f"epoch {epoch}: loss {loss:.4f}, validation loss {val_loss:.4f}", flush=True)

    meta = {"name": cfg.name, "algo": PLANNER, "seed": cfg.seed, "scenario": cfg.scenario, "solver": cfg.solver,
            "then": cfg.then, "threshold": cfg.threshold, "replan": cfg.replan}
    checkpoint.save(out_dir / "model", actor, layout.own_names, layout.task_names, cfg.env_overrides, meta)
    env_kwargs = {"scenario": resolve_config(cfg.scenario)}
    scores = {label: float(np.mean([a.score for a in evaluate(policy, env_kwargs, val_seeds)]))
              for label, policy in (("planner_then", make_policy(f"learned:{out_dir}")), ("then", then),
                                    ("cbgabi", make_policy("cbgabi")))}
    command = ["python -m research.training.planner", *(argv if argv is not None else sys.argv[1:])]
    summary = {"command": " ".join(command),
               "wall_seconds": round(time.perf_counter() - t0, 1), "cpu_seconds": round(cpu_seconds(), 1),
               "label_seconds": round(label_seconds, 1), "load_average_at_start": load, "cpu_count": os.cpu_count(),
               "states": len(train.obs), "validation_loss": val_loss,
               "validation_scores": scores, "validation_ratio_cbgabi": scores["planner_then"] / scores["cbgabi"]}
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    print(f"validation ({cfg.eval_episodes} instances): planner then {cfg.then} {scores['planner_then']:.1f}, "
          f"{cfg.then} alone {scores['then']:.1f}, CBGABI {scores['cbgabi']:.1f}", flush=True)
    return summary


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
