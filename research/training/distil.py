"""Distilling the optimum: how much of it a local observation can learn (DAgger from the privileged oracle).

    python -m research.training.distil --config distil_small --seed 0 --out-dir runs/distil_small/seed0

A measurement more than a training method. The oracle (``research.policies.oracle``) bids along the exact optimum and
reaches it through the protocol; a decentralised actor sees only its own observation. This run fits the actor to
the oracle's choices with DAgger (Ross, Gordon and Bagnell 2011, "A Reduction of Imitation Learning and Structured
Prediction to No-Regret Online Learning"): iteration 0 plays the oracle, iteration k plays, at every step, the
oracle with probability β = 0.5^k and the actor's greedy action otherwise; every real decision of every visited
state (more than one valid action) is labelled by the oracle and added to the data set, and the actor is refitted
on all of it. The label is a set (``OraclePolicy.targets``: every allowed bid on a task of the agent's optimal
path, or pass), since the optimum fixes which tasks an agent does but not the order it bids for them; the loss is
the negative log of the probability the actor puts on that set.

After each iteration the run reports the agreement (the actor's greedy action is in the oracle's set) on the
training states and on the oracle's states of the validation instances (all, those of the first round, before any
message was exchanged, and those of later rounds), where it also reports CBGABI's rule for comparison, and the
greedy actor's score on the validation instances against CBGABI and the optimum. The run writes ``model.json`` +
``model.safetensors`` (the actor: ``learned:<out_dir>``, and a start for ``taskalloc mappo --init-from
<out_dir>/model.json``), ``distil.csv`` (one row per iteration), ``config.yaml`` and ``summary.yaml``.
"""

from __future__ import annotations

import csv
import dataclasses
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch as th
import yaml
from torch import nn

from research import CONFIGS
from research.policies.oracle import OraclePolicy
from taskalloc.evaluation.episodes import evaluate
from taskalloc.evaluation.seeds import DEMO_SEED_START, VALIDATION_SEED_START
from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.base import stack_observations
from taskalloc.policies.learned import LearnedPolicy
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
from taskalloc_env.config import resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import run_cli

COLUMNS = ("iteration", "beta", "episodes", "samples", "loss", "train_agreement", "validation_agreement",
           "first_round_agreement", "later_rounds_agreement", "cbgabi_agreement", "score", "ratio_cbgabi",
           "ratio_optimum", "wall_time")
MAX_GRAD_NORM = 1.0


@dataclasses.dataclass
class DistilConfig:
    """Everything a run needs; the resolved copy is saved as ``config.yaml`` next to the model."""

    name: str = opt("distil", "run name: the default output folder is runs/<name>-<date-time>")
    out_dir: str | None = opt(None, "folder for the model, config, table and summary")
    overwrite: bool = opt(False, "replace a model already in out_dir")
    seed: int = opt(0, "seed of torch and of the training instances (100000 + 100000 · seed + k)")
    scenario: str = opt("train_small", "the scenario (small enough for the exact optimum: at most 6 × 9)")
    env_overrides: dict[str, Any] = dataclasses.field(
        default_factory=lambda: {"task_quitting": True, "delta": 1},
        metadata={"help": "protocol options the actor plays with, saved in the checkpoint"})
    actor: str = opt("attention", "actor network: attention | pooling (policies.networks)")
    hidden: int = opt(64, "width of the actor")
    heads: int = opt(4, "attention heads")
    layers: int = opt(2, "self-attention layers")
    iterations: int = opt(6, "DAgger iterations (iteration 0 plays the oracle alone)")
    episodes: int = opt(500, "training instances per iteration")
    epochs: int = opt(4, "passes over the whole data set per iteration")
    batch_size: int = opt(256, "minibatch size")
    learning_rate: float = opt(1e-3, "Adam learning rate")
    eval_episodes: int = opt(50, "validation instances")
    torch_threads: int = opt(1, "torch threads")

    def check(self) -> None:
        check_types(self)
        check_at_least(self, ("hidden", "heads", "layers", "iterations", "episodes", "epochs", "batch_size",
                              "eval_episodes", "torch_threads"), 1)
        check_at_least(self, ("seed",), 0)
        check_actor(self)
        check_protocol_options(self)


@dataclasses.dataclass
class Decisions:
    """Visited states with more than one valid action and the oracle's set of good actions."""

    obs: np.ndarray         # (S, D) float32
    masks: np.ndarray       # (S, A) bool
    targets: np.ndarray     # (S, A) bool
    first_round: np.ndarray  # (S,) bool: taken before any message was exchanged

    @classmethod
    def concat(cls, parts: Sequence[Decisions]) -> Decisions:
        return cls(*(np.concatenate(arrays) for arrays in zip(*(dataclasses.astuple(p) for p in parts))))


def greedy(actor: nn.Module, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """The actor's most likely action per row (the imitation target is one action, not a kind then an action)."""
    with th.no_grad():
        return actor(th.as_tensor(obs, dtype=th.float32), th.as_tensor(masks)).argmax(dim=-1).numpy()


def play(env: TaskAllocEnv, oracle: OraclePolicy, actor: nn.Module, seeds: Sequence[int], beta: float,
         rng: np.random.Generator) -> Decisions:
    """Episodes on ``seeds``: each step the oracle acts with probability ``beta``, else the actor; every real
    decision is labelled with the oracle's targets."""
    agents, rows = env.possible_agents, []
    round_column = env.observation_layout.own_names.index("round")
    for seed in seeds:
        observations, _ = env.reset(seed=int(seed))
        oracle.start(env, int(seed))
        while env.agents:
            obs, masks = stack_observations(observations, agents)
            masks = masks.astype(bool)
            decide = masks.sum(axis=1) > 1
            rows.append(Decisions(obs[decide], masks[decide], oracle.targets(agents, masks)[decide],
                                  obs[decide, round_column] == 0))
            if rng.random() < beta:
                actions = oracle.act({a: observations[a] for a in agents})
            else:
                actions = dict(zip(agents, greedy(actor, obs, masks).tolist()))
            observations, *_ = env.step(actions)
    return Decisions.concat(rows)


def set_loss(logits: th.Tensor, targets: th.Tensor) -> th.Tensor:
    """−log Σ_{a in the target set} π(a), averaged over rows."""
    log_probs = th.log_softmax(logits, dim=-1)
    return -th.logsumexp(log_probs.masked_fill(~targets, -th.inf), dim=-1).mean()


def fit(actor: nn.Module, optimizer: th.optim.Optimizer, data: Decisions, cfg: DistilConfig,
        rng: np.random.Generator) -> float:
    """``epochs`` passes over ``data``; returns the last pass's mean loss."""
    obs, masks, targets = th.as_tensor(data.obs).float(), th.as_tensor(data.masks), th.as_tensor(data.targets)
    total = 0.0
    for _ in range(cfg.epochs):
        total = 0.0
        order = rng.permutation(len(obs))
        for start in range(0, len(obs), cfg.batch_size):
            idx = th.as_tensor(order[start: start + cfg.batch_size])
            loss = set_loss(actor(obs[idx], masks[idx]), targets[idx])
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(actor.parameters(), MAX_GRAD_NORM)
            optimizer.step()
            total += loss.item() * len(idx)
    return total / len(obs)


def agreement(choices: np.ndarray, targets: np.ndarray, rows: np.ndarray | None = None) -> float:
    """Share of rows (all, or those selected by ``rows``) whose chosen action is in the oracle's set."""
    hits = targets[np.arange(len(choices)), choices]
    return float(hits.mean() if rows is None else hits[rows].mean())


def cbgabi_choices(env: TaskAllocEnv, data: Decisions) -> np.ndarray:
    """CBGABI's rule (``CBGAPolicy.decide``) on the same states, for comparison."""
    return make_policy("cbgabi").decide(data.obs, data.masks, env.observation_layout)


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    cfg = parse(DistilConfig, argv, "python -m research.training.distil", __doc__, configs=CONFIGS)
    cfg.out_dir = cfg.out_dir or f"runs/{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    cfg.check()
    out_dir = prepare_out_dir(cfg.out_dir, cfg.overwrite)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    th.set_num_threads(cfg.torch_threads)
    th.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    t0 = time.perf_counter()

    env_kwargs: Mapping[str, Any] = {"scenario": resolve_config(cfg.scenario), **cfg.env_overrides}
    env = TaskAllocEnv(**env_kwargs)
    layout = env.observation_layout
    oracle = OraclePolicy()
    actor = make_actor(cfg, layout.own_size, layout.task_size)
    optimizer = th.optim.Adam(actor.parameters(), lr=cfg.learning_rate)

    val_seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + cfg.eval_episodes)
    val_states = play(env, oracle, actor, val_seeds, 1.0, rng)
    baseline = np.array([a.score for a in evaluate(make_policy("cbgabi"), env_kwargs, val_seeds)])
    optimum = np.array([a.score for a in evaluate(oracle, env_kwargs, val_seeds)])
    cbgabi_agreement = agreement(cbgabi_choices(env, val_states), val_states.targets)
    policy = LearnedPolicy(actor, layout.own_names, layout.task_names, cfg.env_overrides, name=cfg.name)

    first = DEMO_SEED_START + 100_000 * cfg.seed
    data, rows = None, []
    with open(out_dir / "distil.csv", "w", newline="") as fh:
        csv.writer(fh).writerow(COLUMNS)
    for it in range(cfg.iterations):
        beta = 0.5 ** it
        seeds = range(first + it * cfg.episodes, first + (it + 1) * cfg.episodes)
        actor.eval()
        new = play(env, oracle, actor, seeds, beta, rng)
        data = new if data is None else Decisions.concat([data, new])
        actor.train()
        loss = fit(actor, optimizer, data, cfg, rng)
        actor.eval()
        scores = np.array([a.score for a in evaluate(policy, env_kwargs, val_seeds)])
        val_choices = greedy(actor, val_states.obs, val_states.masks)
        row = {"iteration": it, "beta": beta, "episodes": (it + 1) * cfg.episodes, "samples": len(data.obs),
               "loss": loss, "train_agreement": agreement(greedy(actor, data.obs, data.masks), data.targets),
               "validation_agreement": agreement(val_choices, val_states.targets),
               "first_round_agreement": agreement(val_choices, val_states.targets, val_states.first_round),
               "later_rounds_agreement": agreement(val_choices, val_states.targets, ~val_states.first_round),
               "cbgabi_agreement": cbgabi_agreement, "score": float(scores.mean()),
               "ratio_cbgabi": float(scores.mean() / baseline.mean()),
               "ratio_optimum": float(scores.mean() / optimum.mean()), "wall_time": round(time.perf_counter() - t0, 1)}
        rows.append(row)
        with open(out_dir / "distil.csv", "a", newline="") as fh:
            csv.writer(fh).writerow([f"{row[c]:.6g}" if isinstance(row[c], float) else row[c] for c in COLUMNS])
        print(", ".join(f"{c} {row[c]:.4g}" if isinstance(row[c], float) else f"{c} {row[c]}" for c in COLUMNS),
              flush=True)

    checkpoint.save(out_dir / "model", actor, layout.own_names, layout.task_names, cfg.env_overrides,
                    {"name": cfg.name, "algo": "distil", "seed": cfg.seed, "scenario": cfg.scenario})
    summary = {"command": " ".join(["python -m research.training.distil", *(argv or sys.argv[1:])]),
               "seconds": round(time.perf_counter() - t0, 1), "validation_cbgabi": float(baseline.mean()),
               "validation_optimum": float(optimum.mean()),
               "validation_decisions": len(val_states.obs),
               "validation_first_round_decisions": int(val_states.first_round.sum()), "last": rows[-1]}
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    return summary


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
