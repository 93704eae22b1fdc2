"""How much of the local plan a learned round-0 planner has learned: both scored against the real paths (ours).

    python -m research.evaluation.plan_fit --planner learned:runs/planner_small/seed0 --episodes 40

At each agent's first round-0 state (no bid made, no message heard; thesis Alg 5) two estimates of the same thing
are compared: for every task the agent may bid on, the probability that the task is on the agent's path in the
solver's allocation of the instance. The local plan (``research.policies.local_plan``) estimates it by drawing
``--samples`` teams around the agent's own start and solving each; a round-0 planner (``research.policies.round_zero``,
trained by ``research.training.planner`` on exactly this target) from the agent's observation. Both are scored against
the paths of the real instance, as is the base rate (the share of allowed tasks on a path, one number for every task):
binary cross-entropy (the loss ``research.training.planner`` minimises; estimates clipped to [0.001, 0.999]) and, for
the tasks estimated at ½ or more (those both bid on), how many, precision and recall. The local plan's cross-entropy
shows what the agent's own information allows; the planner's distance from it is what its training has not learned. The
seeds default to the validation instances, on which ``research.training.planner`` reports its validation loss over
every round-0 state (this table keeps the first one of each agent, the state the plan is made in). Costs as
``research.evaluation.local_plan``: N × ``--samples`` solves per instance. docs/learning.md ("The local plan learned")
names this command.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence

import numpy as np

from research.evaluation.handover import REFERENCES
from research.plugins import planner_pair
from research.policies.local_plan import SOLVERS, LocalPlanPolicy
from research.policies.round_zero import RoundZeroPlanner
from taskalloc.evaluation.episodes import skip_reason
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.seeds import VALIDATION_SEED_START
from taskalloc.policies.base import stack_observations
from taskalloc_env.actions import bid_columns
from taskalloc_env.allocation import on_paths
from taskalloc_env.config import resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli

CLIP = 1e-3         # estimates are clipped to [CLIP, 1 - CLIP] in the cross-entropy (a share of 0 or 1 is common)


@dataclasses.dataclass
class FirstStates:
    """Per agent of each instance, at its first round-0 state: the tasks it may bid on, those on its path in the
    real instance's allocation, and each estimate of the probability that a task is on it."""

    allowed: np.ndarray                 # (A, M) bool
    on_path: np.ndarray                 # (A, M) bool
    estimates: dict[str, np.ndarray]    # label → (A, M)

    @classmethod
    def concat(cls, parts: Sequence[FirstStates]) -> FirstStates:
        """The states of ``parts`` one after the other (every part has the same estimates)."""
        return cls(np.concatenate([p.allowed for p in parts]), np.concatenate([p.on_path for p in parts]),
                   {label: np.concatenate([p.estimates[label] for p in parts]) for label in parts[0].estimates})


def planner_of(name: str) -> RoundZeroPlanner:
    """The round-0 planner of a planner checkpoint's policy name (``ConfigError`` naming it otherwise)."""
    return planner_pair(name, "--planner").first


def first_states(job: tuple[str, str, int, Sequence[str], Sequence[int]]) -> FirstStates:
    """``FirstStates`` of ``seeds``; the local plan's shares are those it plays by (``LocalPlanPolicy.start``)."""
    scenario, solver, samples, planner_names, seeds = job
    planners = [planner_of(name) for name in planner_names]
    env = TaskAllocEnv(scenario, **planners[0].env_overrides)
    agents, m = env.possible_agents, env.observation_layout.n_tasks
    local = LocalPlanPolicy(samples, solver)
    labels = [*planner_names, local.name]
    allowed, on_path, estimates = [], [], {label: [] for label in labels}
    for seed in seeds:
        observations, _ = env.reset(seed=int(seed))
        local.start(env, int(seed))
        obs, masks = stack_observations(observations, agents)
        allowed.append(masks[:, bid_columns(m)] > 0)
        on_path.append(on_paths(SOLVERS[solver](env.scenario, env.config).paths, m))
        for name, planner in zip(planner_names, planners):
            planner.start(env, int(seed))
            estimates[name].append(planner.probabilities(planner.actor_input(obs)))
        estimates[local.name].append(local.team_shares)
    return FirstStates(np.concatenate(allowed), np.concatenate(on_path),
                       {label: np.concatenate(rows) for label, rows in estimates.items()})


def cross_entropy(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Mean binary cross-entropy of ``estimate`` (clipped by ``CLIP``) against the 0/1 ``truth``."""
    p = np.clip(estimate, CLIP, 1 - CLIP)
    return float(-np.mean(truth * np.log(p) + (1 - truth) * np.log(1 - p)))


def table(states: FirstStates) -> str:
    """One row per estimate (the base rate first) over the allowed tasks: cross-entropy, tasks at ≥ ½, precision,
    recall."""
    truth = states.on_path[states.allowed].astype(float)
    rows = [("base rate", np.full_like(truth, truth.mean()))]
    rows += [(label, estimate[states.allowed]) for label, estimate in states.estimates.items()]
    lines = ["| estimate | cross-entropy | tasks at ≥ ½ | precision | recall |", "|---|--:|--:|--:|--:|"]
    for label, estimate in rows:
        chosen = estimate >= 0.5
        hits = int((chosen & (truth > 0)).sum())
        precision = f"{hits / chosen.sum():.3f}" if chosen.any() else "–"
        lines.append(f"| {label} | {cross_entropy(estimate, truth):.4f} | {int(chosen.sum())} | {precision} | "
                     f"{hits / truth.sum():.3f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.plan_fit", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--planner", action="append", required=True, metavar="NAME",
                        help="a round-0 planner's policy name, learned:<checkpoint> (repeatable)")
    parser.add_argument("--scenario", default="train_small", help="scenario name or YAML path (default train_small)")
    parser.add_argument("--reference", choices=sorted(REFERENCES), default="exact",
                        help="the solver of the real and the drawn instances: exact (default; small instances) or lns")
    parser.add_argument("--samples", type=int, default=24, help="teams drawn per agent (default 24)")
    parser.add_argument("--seed-start", type=int, default=VALIDATION_SEED_START,
                        help=f"first seed (default {VALIDATION_SEED_START}, the validation instances)")
    parser.add_argument("--episodes", type=int, default=40, help="number of instances (default 40)")
    parser.add_argument("--jobs", type=int, default=2, help="processes (default 2)")
    args = parser.parse_args(argv)
    for option in ("samples", "episodes", "jobs"):
        if getattr(args, option) < 1:
            raise ConfigError(f"--{option}: got {getattr(args, option)}; allowed: an integer >= 1")
    reason = skip_reason(args.reference, resolve_config(args.scenario))
    if reason:
        raise ConfigError(f"--scenario {args.scenario}: {reason} (--reference lns solves at any size)")
    overrides = {name: planner_of(name).env_overrides for name in args.planner}
    if len({tuple(sorted(o.items())) for o in overrides.values()}) > 1:
        raise ConfigError(f"--planner: the planners play with different protocol options {overrides}")
    seeds = list(range(args.seed_start, args.seed_start + args.episodes))
    chunks = [(args.scenario, args.reference, args.samples, args.planner, seeds[k::args.jobs])
              for k in range(min(args.jobs, len(seeds)))]
    states = FirstStates.concat(list(parallel_map(first_states, chunks, args.jobs)))
    share = states.on_path[states.allowed].mean()
    out = table(states)
    print(f"{args.scenario}, seeds {seeds[0]}–{seeds[-1]}: {int(states.allowed.sum())} allowed tasks at the agents' "
          f"first round-0 states, {share:.3f} of them on a path\n\n{out}")
    return out


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
