"""The allocation type every solver returns: paths with start times, groups, validity, score and traffic.

``Allocation.from_paths`` scores each agent's own path with the shared scoring code (``scoring.team_score``), so the
environment's ``evaluate()``, the centralised greedy SGAMA and the exact optimum are compared on equal terms.
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

    @classmethod
    def from_paths(cls, model: ScoringModel, paths: Sequence[Sequence[int]], conflict_policy: str = "first_L_paid",
                   schedules: Sequence[Schedule] | None = None, **figures: Any) -> Allocation:
        """Score ``paths`` (one per agent) and wrap them with the run's ``figures`` (counters, convergence)."""
        if schedules is None:
            schedules = [model.schedule(i, p) for i, p in enumerate(paths)]
        infeasible = [i for i, s in enumerate(schedules) if not s.feasible]
        if infeasible:
            raise ValueError(f"the paths of agents {infeasible} miss a time window; an allocation must be feasible")
        return cls.scored([s.path for s in schedules], [s.start for s in schedules],
                          team_score(model, schedules, conflict_policy), **figures)

    @classmethod
    def scored(cls, paths: Sequence[Sequence[int]], start_times: Sequence[np.ndarray], team: TeamScore,
               **figures: Any) -> Allocation:
        """Wrap paths, their start times and their ``team_score`` (computed by the caller) with the run's figures."""
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
            **figures,
        )

    @property
    def n_valid(self) -> int:
        return len(self.valid_tasks)

    def summary(self) -> dict[str, Any]:
        """The scalar figures (what infos and result tables carry)."""
        return {"score": self.score, "valid_tasks": self.n_valid, "conflicts": len(self.conflicts),
                **dataclasses.asdict(self.counters), "converged": self.converged, "agreement": self.agreement,
                "globally_converged": self.globally_converged, "locally_converged": self.locally_converged}
