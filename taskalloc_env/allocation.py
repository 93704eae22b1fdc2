"""The allocation type every solver returns: paths with start times, groups, validity, score and traffic.

``Allocation.from_paths`` scores each agent's own path with the shared scoring code (``scoring.team_score``), so the
environment's ``evaluate()``, the centralised greedy SGAMA and the exact optimum are compared on equal terms.

Besides the thesis's figures (score, valid tasks, rounds, messages) an allocation carries the per-episode measures of
the decentralised task-allocation benchmarks (Nayak et al., IEEE RA-L 2020: "the maximum distance traveled by any
agent" and "the maximum number of messages sent by any agent"; its 2026 successor, the DCTA benchmark: a workload
Gini coefficient, and mission completion kept apart from the efficiency of what was completed):
``max_travel``, ``counters.max_agent_messages``, ``workload_gini``, ``completion`` and ``score_per_task``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc_env.scoring import Schedule, ScoringModel, TeamScore, team_score


def on_paths(paths: Sequence[Sequence[int]], n_tasks: int) -> np.ndarray:
    """(N, M) bool: task j is on agent i's path, for one path per agent."""
    out = np.zeros((len(paths), n_tasks), dtype=bool)
    for i, path in enumerate(paths):
        out[i, list(path)] = True
    return out


@dataclasses.dataclass
class Counters:
    """Cumulative figures of one run (communication steps and bids as the thesis counts them, §3.3.2–3.3.3)."""

    rounds: int = 0
    messages: int = 0
    informative_messages: int = 0
    data_items: int = 0
    bids: int = 0
    quits: int = 0
    # quits other agents saw: the quit's release reached another agent's table, i.e. a merge dropped the
    # quitter from that task's group in the table of an agent that listed it, before the quitter bid on it again
    quits_seen: int = 0
    invalid_actions: int = 0    # actions outside the mask turned into passes (invalid_action="noop")
    # release actions taken (release_actions): kept out of the repr, so that a run without the option prints, and
    # digests (benchmarks.episode_digests), exactly as before the option existed; summary() and asdict() carry it
    releases: int = dataclasses.field(default=0, repr=False)
    # the round after which no table or bundle changed again, and the messages sent until then: the thesis's stop
    # "when all agents converge to the same conflict-free solution" (§3.2.3), before our D + 1 quiet rounds confirm it
    rounds_to_agreement: int = 0
    messages_to_agreement: int = 0
    # the network (network.Network): messages sent, lost and delayed; data items sent (received: data_items);
    # bids later replaced by a better one (thesis Fig 4.10's conflicting bids); agents that failed; tables cleared of
    # an agent that went silent for silence_timeout rounds
    messages_sent: int = 0
    messages_lost: int = 0
    messages_delayed: int = 0
    data_items_sent: int = 0
    # the most messages any one agent sent (its share of messages_sent; Nayak et al. 2020's second measure)
    max_agent_messages: int = 0
    conflicting_bids: int = 0
    dropped_agents: int = 0
    silent_releases: int = 0
    # the asynchronous consensus (consensus="acbba", Johnson §4.1.3): broadcasts (one per flush of an outgoing buffer,
    # however many agents hear it: Johnson's "1 message"), the tick the network went quiet (global convergence, 0: not
    # reached), the tick every agent had heard nothing relevant for longer than separation_time (local convergence,
    # 0: not reached), and the longest gap between two relevant messages at one agent (the separation time observed)
    broadcasts: int = 0
    quiet_tick: int = 0
    local_tick: int = 0
    separation_ticks: int = 0


@dataclasses.dataclass(frozen=True)
class Allocation:
    """One assignment of agents to tasks and how it came about."""

    paths: tuple[tuple[int, ...], ...]          # per agent: task ids in execution order
    start_times: tuple[tuple[float, ...], ...]  # per agent: start time of each path task
    members: tuple[tuple[int, ...], ...]        # per task: agents with it on their own path
    valid_tasks: tuple[int, ...]                # tasks that pay (exactly L_j members, equipment, prerequisites)
    conflicts: tuple[int, ...]                  # tasks with more than L_j members
    score: float
    agent_scores: tuple[float, ...]
    counters: Counters = dataclasses.field(default_factory=Counters)   # how the run got there (a copy)
    converged: bool = True
    agreement: bool = True                      # every agent of a component holds the same table
    globally_converged: bool = True             # no message in flight and nothing left to change (async: quiet)
    locally_converged: bool = True              # async: every agent past its separation time; sync: = converged
    travel: tuple[float, ...] = ()              # per agent: the length of its flight (start → its path's tasks)

    @classmethod
    def from_paths(cls, model: ScoringModel, paths: Sequence[Sequence[int]], conflict_policy: str = "first_L_paid",
                   schedules: Sequence[Schedule] | None = None, **figures: Any) -> Allocation:
        """Score ``paths`` (one per agent) and wrap them with the run's ``figures`` (counters, convergence)."""
        if schedules is None:
            schedules = [model.schedule(i, p) for i, p in enumerate(paths)]
        infeasible = [i for i, s in enumerate(schedules) if not s.feasible]
        if infeasible:
            raise ValueError(f"the paths of agents {infeasible} miss a time window; an allocation must be feasible")
        return cls.scored(model, [s.path for s in schedules], [s.start for s in schedules],
                          team_score(model, schedules, conflict_policy), **figures)

    @classmethod
    def scored(cls, model: ScoringModel, paths: Sequence[Sequence[int]], start_times: Sequence[np.ndarray],
               team: TeamScore, **figures: Any) -> Allocation:
        """Wrap paths, their start times and their ``team_score`` (computed by the caller) with the run's figures;
        the flight lengths come from ``model``'s distances."""
        members: list[list[int]] = [[] for _ in range(team.members.shape[1])]
        for j, i in zip(*(a.tolist() for a in np.nonzero(team.members.T))):       # task-major, agents ascending
            members[j].append(i)
        return cls(
            paths=tuple(tuple(int(j) for j in path) for path in paths),
            start_times=tuple(tuple(np.asarray(start, dtype=float).tolist()) for start in start_times),
            members=tuple(map(tuple, members)),
            valid_tasks=tuple(np.flatnonzero(team.valid).tolist()),
            conflicts=tuple(np.flatnonzero(team.conflicts).tolist()),
            score=team.score,
            agent_scores=tuple(team.agent_scores.tolist()),
            travel=tuple(flight_lengths(model, paths).tolist()),
            **figures,
        )

    @property
    def n_valid(self) -> int:
        return len(self.valid_tasks)

    @property
    def completion(self) -> float:
        """The share of the tasks serviced (valid: paid, thesis (3.3)); the DCTA benchmark's completion, kept apart
        from the efficiency of what was completed (``score_per_task``)."""
        return self.n_valid / len(self.members) if self.members else 0.0

    @property
    def score_per_task(self) -> float | None:
        """The score per serviced task: the efficiency of what was completed (None when nothing was: the benchmark's
        efficiency is conditional on completion, so an episode without any has none)."""
        return self.score / self.n_valid if self.n_valid else None

    @property
    def max_travel(self) -> float:
        """The longest flight of any agent (Nayak et al. 2020, "the maximum distance traveled by any agent")."""
        return max(self.travel, default=0.0)

    @property
    def tasks_serviced(self) -> tuple[int, ...]:
        """Per agent: the serviced (valid) tasks on its path, its workload."""
        valid = set(self.valid_tasks)
        return tuple(sum(j in valid for j in path) for path in self.paths)

    @property
    def workload_gini(self) -> float:
        """The Gini coefficient of the agents' workloads (``tasks_serviced``): 0 when all serviced as many tasks, up
        to 1 − 1/N when one agent serviced all; 0 when nobody serviced any (the DCTA benchmark's target-completion
        Gini, over tasks per agent)."""
        return gini(self.tasks_serviced)

    def summary(self) -> dict[str, Any]:
        """The scalar figures (what infos and result tables carry)."""
        return {"score": self.score, "valid_tasks": self.n_valid, "conflicts": len(self.conflicts),
                "completion": self.completion, "score_per_task": self.score_per_task,
                "workload_gini": self.workload_gini, "max_travel": self.max_travel,
                **dataclasses.asdict(self.counters), "converged": self.converged, "agreement": self.agreement,
                "globally_converged": self.globally_converged, "locally_converged": self.locally_converged}


def flight_lengths(model: ScoringModel, paths: Sequence[Sequence[int]]) -> np.ndarray:
    """(N,) the distance each agent flies: from its start position to its path's first task, then task to task (the
    legs of thesis (3.8), without a return)."""
    out = np.zeros(len(paths))
    for i, path in enumerate(paths):
        if len(path):
            tasks = np.asarray(path, dtype=np.int64)
            out[i] = model.dist_agent_task[i, tasks[0]] + model.dist_task_task[tasks[:-1], tasks[1:]].sum()
    return out


def gini(values: Sequence[float]) -> float:
    """G = Σ_i Σ_k |x_i − x_k| / (2 n² x̄) (the mean absolute difference over twice the mean), 0 for an empty or
    all-zero sample; computed from the sorted values, G = 2 Σ_r r x_(r) / (n Σ x) − (n + 1) / n, r = 1..n."""
    x = np.sort(np.asarray(values, dtype=float))
    total, n = x.sum(), len(x)
    if not n or total == 0:
        return 0.0
    return float(2 * (np.arange(1, n + 1) * x).sum() / (n * total) - (n + 1) / n)
