"""Paired evaluation: several solvers on the same seeds, one row of figures per episode, parallel over processes.

A *solver* is a policy name (``random``, ``cbba``, ``cbga``, ``cbga+tq``, ``cbga+tb``, ``cbgabi``,
``learned:<checkpoint>``, see ``taskalloc.policies.make_policy``), a centralised solver (``sgama``, ``exact``, ``lns``:
the group search of ``taskalloc.policies.local_search``), or ``cbba-duo`` (preferred-duo CBBA,
``taskalloc.policies.duo``: every task of the single-agent instance split into a lead and a helper part, messages and
rounds counted as for any policy). Seed s generates the same scenario instance for every solver (the paired design of
thesis §5.3.1): the environment draws the instance from ``reset(seed=s)`` before any policy acts, and each row carries a
fingerprint of the instance so that the pairing can be checked. Policies that need protocol options (``env_overrides``,
e.g. task quitting) get an environment built with them; those options do not touch the instance generator.

Communication steps (thesis §3.3.2: one message from i received by k is one step): ``messages`` counts every
message received (one per sender → receiver pair per round); ``comm_steps`` = messages / N_n, the per-agent count
until the episode ends (D + 1 quiet rounds after the last change; the per-agent count, our reading, whose magnitudes
match the thesis's Fig 3.11), ``comm_steps_to_agreement`` the same count until the last change, after which every
agent holds the final solution (the thesis's stop, "when all agents converge to the same conflict-free solution",
§3.2.3).
The benchmarks' per-episode measures (``Allocation``): ``completion`` (share of tasks serviced) apart from
``score_per_task`` (efficiency of what was completed, empty when nothing was), ``workload_gini`` (over serviced tasks
per agent), ``max_travel`` (the longest flight) and ``max_agent_messages`` (the most messages one agent sent).
Centralised solvers have no rounds or messages (left empty). Episodes that hit the round bound are kept and
flagged ``converged = False``.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from tqdm import tqdm

from taskalloc.evaluation.distributed import BACKENDS, ray_map
from taskalloc.evaluation.pool import as_finished, worker_threads
from taskalloc.policies import exact, local_search, make_policy, rollout, sgama
from taskalloc.policies.base import Policy
from taskalloc.policies.centralised import MAX_AGENTS, MAX_TASKS
from taskalloc.policies.duo import preferred_duo_cbba
from taskalloc.policies.fast import solvable as fast_solvable
from taskalloc.policies.fast import solve as fast_solve
from taskalloc.policies.scripted import CBGAPolicy
from taskalloc_env import Scenario, TaskAllocConfig, TaskAllocEnv, kernels
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import max_required_agents

CENTRALISED = {"sgama": ("SGAMA", sgama), "exact": ("exact", exact), "lns": ("LNS", local_search)}
# solvers that run a protocol on a transformed instance: (display name, solver(scenario, config) -> Allocation)
SOLVERS = {"cbba-duo": ("CBBA preferred duo", preferred_duo_cbba)}
METRICS = ("score", "valid_tasks", "conflicts", "rounds", "messages", "comm_steps", "rounds_to_agreement",
           "comm_steps_to_agreement", "invalid_actions", "informative_messages", "data_items", "bids", "quits",
           "quits_seen", "messages_lost", "messages_delayed", "data_received_per_agent", "data_sent_per_agent",
           "data_per_assignment", "data_per_agent_per_assignment", "conflicting_bids_per_agent", "dropped_agents",
           "connected", "fully_connected", "completion", "score_per_task", "workload_gini", "max_travel",
           "max_agent_messages")
# policies of single-agent tasks only (every L_j = 1): CBBA, ACBBA (and its replan), CBAA, PI
SINGLE_AGENT_TASKS = ("cbba", "acbba", "acbba+replan", "cbaa", "pi")
SUMMARY_FIELDS = ("score", "valid_tasks", "rounds", "messages")
PROTOCOL_METRICS = ("rounds", "messages", "comm_steps", "rounds_to_agreement", "comm_steps_to_agreement",
                    "invalid_actions", "informative_messages", "data_items", "quits", "quits_seen", "messages_lost",
                    "messages_delayed", "data_received_per_agent", "data_sent_per_agent", "data_per_assignment",
                    "data_per_agent_per_assignment", "conflicting_bids_per_agent", "dropped_agents",
                    "max_agent_messages")


@dataclasses.dataclass(frozen=True)
class Episode:
    """One run: ``solver`` on the instance ``seed`` of ``config``; ``labels`` are copied into the result row."""

    solver: str
    config: TaskAllocConfig
    seed: int
    labels: tuple[tuple[str, Any], ...] = ()


def skip_reason(solver: str, cfg: TaskAllocConfig) -> str | None:
    """Why ``solver`` does not apply to ``cfg`` (None if it does): CBBA needs every L_j = 1, exact small sizes."""
    key = solver.lower()
    if key in SINGLE_AGENT_TASKS and max_required_agents(cfg) > 1:
        return f"{key.upper()} assigns single-agent tasks only (every L_j = 1)"
    if key == "cbba-duo" and (max_required_agents(cfg) > 1 or cfg.prerequisites or cfg.comm_range is not None):
        return "preferred-duo CBBA splits single-agent tasks without prerequisites, with full communication"
    if key in ("exact", "oracle") and (cfg.n_agents > MAX_AGENTS or cfg.n_tasks > MAX_TASKS):
        return f"{key} needs the exact optimum, which enumerates; at most {MAX_AGENTS} agents x {MAX_TASKS} tasks"
    return None


def solver_name(solver: str) -> str:
    """The display name: the policy's own name (``CBGA+TQ``), ``SGAMA``, ``exact`` or ``LNS``."""
    key = solver.lower()
    if key in CENTRALISED:
        return CENTRALISED[key][0]
    if key in SOLVERS:
        return SOLVERS[key][0]
    return policy_for(solver).name


@functools.cache
def policy_for(solver: str) -> Policy:
    """One policy object per solver name and process (a learned policy loads its checkpoint once)."""
    return make_policy(solver)


def policy_overrides(solver: str, cfg: TaskAllocConfig) -> dict[str, Any]:
    """The protocol options ``solver`` needs on top of ``cfg`` (its ``env_overrides``).

    A policy that pins an option (a learned policy trained with ``delta=1``) may not silently overrule a value the
    config sets away from the default (a δ sweep): that is an error naming both. The scripted CBGA+TQ and CBGABI
    pin nothing but ``task_quitting`` and take δ from the config, so a sweep over ``delta`` reaches them.
    """
    if solver.lower() in CENTRALISED or solver.lower() in SOLVERS:
        return {}
    overrides = policy_for(solver).env_overrides
    clash = {k: (getattr(cfg, k), v) for k, v in overrides.items()
             if getattr(cfg, k) != v and getattr(cfg, k) != getattr(TaskAllocConfig, k)}
    if clash:
        detail = ", ".join(f"{k}={have!r} (the policy needs {want!r})" for k, (have, want) in clash.items())
        raise ValueError(f"{solver}: the config sets {detail}; the policy would overrule it")
    return overrides


@functools.cache
def _env(solver: str, cfg: TaskAllocConfig) -> TaskAllocEnv:
    """One environment per (solver, config) and process, reused across seeds (reset draws a fresh instance)."""
    return TaskAllocEnv(cfg, **policy_overrides(solver, cfg))


def fingerprint(scenario: Scenario) -> str:
    """A short hash of every array of the instance: equal fingerprints ⇔ the same problem (pairing check)."""
    digest = hashlib.sha1()
    for field in dataclasses.fields(scenario):
        value = getattr(scenario, field.name)
        digest.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray) else repr(value).encode())
    return digest.hexdigest()[:12]


def solve(solver: str | Policy, env: TaskAllocEnv, seed: int) -> Allocation:
    """Solve instance ``seed`` of ``env``: roll a policy out, or hand the instance to a centralised solver.

    ``solver`` is a name (a policy, ``sgama``, ``exact``, ``lns`` or ``cbba-duo``) or a policy object; ``env`` must
    carry the policy's ``env_overrides``.
    """
    table = {**CENTRALISED, **SOLVERS}
    if isinstance(solver, str) and solver.lower() in table:
        env.reset(seed=seed)
        return table[solver.lower()][1](env.unwrapped.scenario, env.config)
    policy = policy_for(solver) if isinstance(solver, str) else solver
    unwrapped = env.unwrapped
    if isinstance(policy, CBGAPolicy) and fast_solvable(unwrapped.config):
        # the scripted consensus policies through the protocol directly: the same allocation and counters as the
        # rollout (tests/test_fast.py), without the env's observations, rewards and infos
        env.reset(seed=seed)
        policy.start(env, seed=seed)                # the same binding and environment checks as the rollout
        return fast_solve(unwrapped.scenario, unwrapped.config, policy, dtype=unwrapped.dtype,
                          max_cycles=unwrapped.max_cycles)
    return rollout(env, policy, seed=seed)


def evaluate(policy: Policy, env_kwargs: Mapping[str, Any], seeds: Sequence[int]) -> list[Allocation]:
    """One episode per seed of an in-memory policy; the env gets ``env_kwargs`` plus the policy's overrides."""
    env = TaskAllocEnv(**{**env_kwargs, **policy.env_overrides})
    return [solve(policy, env, int(seed)) for seed in seeds]


def summarise(allocations: Sequence[Allocation]) -> dict[str, float]:
    """Means of score, valid tasks, rounds and messages, plus the score's standard deviation."""
    rows = [a.summary() for a in allocations]
    out = {k: float(np.mean([r[k] for r in rows])) for k in SUMMARY_FIELDS}
    out["score_std"] = float(np.std([r["score"] for r in rows]))
    return out


def run_episode(episode: Episode) -> dict[str, Any]:
    """Solve one instance; the row holds the labels, the solver, the seed, the fingerprint and the figures."""
    key = episode.solver.lower()
    env = _env(episode.solver, episode.config)
    allocation = solve(episode.solver, env, episode.seed)
    figures = allocation.summary()
    n_agents = episode.config.n_agents
    figures["comm_steps"] = figures["messages"] / n_agents
    figures["comm_steps_to_agreement"] = figures["messages_to_agreement"] / n_agents
    # data volume (thesis §4.3, Figs 4.8–4.10): items received and sent per agent, received per assignment made (an
    # agent on a valid task), received per agent per assignment required (Σ_j L_j: thesis Fig 4.9, "the number of
    # assignments to reach a consensus is equal to Σ L_j"), and bids later replaced by a better one per agent
    figures["data_received_per_agent"] = figures["data_items"] / n_agents
    figures["data_sent_per_agent"] = figures["data_items_sent"] / n_agents
    assignments = sum(len(allocation.members[j]) for j in allocation.valid_tasks)
    figures["data_per_assignment"] = figures["data_items"] / assignments if assignments else None
    required = int(env.unwrapped.scenario.task_agents.sum())
    figures["data_per_agent_per_assignment"] = figures["data_received_per_agent"] / required
    figures["conflicting_bids_per_agent"] = figures["conflicting_bids"] / n_agents
    graph = env.unwrapped.protocol.graph
    figures["connected"] = bool((graph.component == 0).all())
    figures["fully_connected"] = bool(graph.adjacency.sum() == n_agents * (n_agents - 1))
    if key in CENTRALISED:
        figures.update(dict.fromkeys(PROTOCOL_METRICS))
    return {**dict(episode.labels), "solver": solver_name(episode.solver), "seed": episode.seed,
            "instance": fingerprint(env.unwrapped.scenario), "n_agents": n_agents,
            "n_tasks": episode.config.n_tasks, **{m: figures[m] for m in METRICS},
            "converged": bool(figures["converged"]), "agreement": bool(figures["agreement"])}


def default_jobs() -> int:
    """Worker processes: every core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_episodes(episodes: Sequence[Episode], jobs: int = 1, progress: bool = True,
                 desc: str = "episodes", backend: str = "local") -> list[dict[str, Any]]:
    """Run every episode (in ``jobs`` processes when > 1, or as Ray tasks with ``backend="ray"``, see
    ``taskalloc.evaluation.distributed``); rows come back in the order of ``episodes``, the progress bar advances
    as episodes finish. Locally, the compiled kernels are ready before the bar starts (``warm_up``)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend {backend!r} is not one of {BACKENDS}")
    rows: dict[int, dict[str, Any]] = warm_up(episodes) if backend == "local" else {}
    todo = [i for i in range(len(episodes)) if i not in rows]
    finished = (enumerate(ray_map(run_episode, episodes)) if backend == "ray"
                else as_finished(run_episode, [episodes[i] for i in todo], jobs))
    with tqdm(total=len(episodes), initial=len(rows), desc=desc, disable=not progress, unit="ep",
              dynamic_ncols=True) as bar:
        for index, row in finished:
            rows[index if backend == "ray" else todo[index]] = row
            bar.update()
    return [rows[i] for i in range(len(episodes))]


def warm_up(episodes: Sequence[Episode]) -> dict[int, dict[str, Any]]:
    """Rows of episodes run here, first, so that no worker compiles the kernels: the first episode; if it compiled
    (a cold cache, ``taskalloc_env.kernels.cache``), also the first episode of every other (solver, config) pair,
    which fills the cache for the workers (one compile, announced on stderr, instead of one per worker while the
    progress bar waits). With a warm cache only the first episode runs here. Keys are indices into ``episodes``."""
    if not episodes:
        return {}
    with worker_threads():
        compiles = kernels.NOTICE.compiles
        rows = {0: run_episode(episodes[0])}
        if kernels.NOTICE.compiles > compiles:
            firsts: dict[tuple[str, TaskAllocConfig], int] = {}
            for index, episode in enumerate(episodes):
                firsts.setdefault((episode.solver, episode.config), index)
            rows.update({i: run_episode(episodes[i]) for i in firsts.values() if i not in rows})
    return rows


def check_pairing(rows: Sequence[dict[str, Any]], keys: Sequence[str]) -> list[str]:
    """Groups of rows (same ``keys`` and seed) whose instances differ: empty for a paired design."""
    seen: dict[tuple, str] = {}
    broken = []
    for row in rows:
        group = (*(row.get(k) for k in keys), row["seed"])
        if seen.setdefault(group, row["instance"]) != row["instance"]:
            broken.append(f"{dict(zip([*keys, 'seed'], group))}: {row['solver']} saw another instance")
    return broken
