"""Observations built from each agent's *local* knowledge only, and the global state for centralised critics.

An agent's observation vector is ``[own features | task 0 features | … | task M−1 features]``. Bid-like values
are divided by the largest task reward c̄, so the gain, the group total and the displaced bid add up to the team
value of thesis (5.5) in the same unit. ``ObservationLayout`` names every column so policies (scripted or
learned) can slice the vector without magic numbers.

Features that exist only in some modes are appended to every task's block only there, so observations of the
default environment (and the models trained on it) keep their size: ``member_silence`` on a faulty network,
``released`` with pop-up tasks, and with ``team_features`` (an option of ours, off by default) what every agent
knows of the team at launch, seen from each task. A task not yet released is invisible: its whole block is zero. Under
``consensus="acbba"`` the own feature ``passed`` marks an agent whose builder is not ready (it may only pass).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from gymnasium import spaces

from taskalloc_env import kernels
from taskalloc_env.kernels.observe import BUNDLE_SIZE, PASSED, ROUND, step_features
from taskalloc_env.kernels.observe import COLUMNS as KERNEL_COLUMNS
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.protocol import Protocol
from taskalloc_env.scenario import Scenario

OWN_FEATURES = ("x", "y", "z", "speed", "bundle_size", "round", "passed")
TASK_FEATURES = (
    "gain",               # c_ij / c̄ (3.11)
    "can_bid",            # the bid action is valid
    "outbid",             # h_ij (3.12)–(3.14)
    "required_agents",    # L_j / N
    "members",            # known members / L_j
    "lowest_bid",         # lowest member bid / c̄
    "group_total",        # Σ_k X_i[k][j] / c̄ (4.2)
    "displaced_bid",      # bid of the member a bid would displace / c̄
    "in_bundle",
    "own_bid",            # X_i[i][j] / c̄
    "quit_before",        # Q_i[j]
    "can_quit",
    "rounds_since_change",  # T − H_i[j] for held tasks: rounds since assigned or since the group last grew
    "equipment_match",
    "prereqs_met",
    "window_start",       # start_j / horizon
    "window_end",         # min(end_j, horizon) / horizon
    "dx", "dy", "dz",     # task position relative to the agent's start / arena
    "distance",           # distance from the agent's start / arena diagonal
    "group_complete",     # L_j members in i's table
)
# only on a faulty network (lost or delayed messages, failing agents), where silence carries information
FAULT_FEATURES = (
    "member_silence",     # rounds since i last heard from or about its quietest fellow member / silence_timeout, ≤ 1
)


# only with team_features (ours, not in the sources): what every agent knows of the team at launch, each agent's
# start and speed, seen from task j; the observation of a source agent holds its own state and the tables only
TEAM_FEATURES = (
    "sooner_agents",      # other agents whose straight flight from their start reaches j sooner / N
    "nearest_other",      # the shortest start distance of another agent to j / arena diagonal (2 alone)
)


# only with pop-up tasks (popup_tasks > 0), whose release carries information
POPUP_FEATURES = (
    "released",           # the task is known (pop-up tasks are invisible before their release, Johnson §4.1.3)
)


# bounds of the relative task position (÷ arena) and of the start distance (÷ arena diagonal): a task and an agent
# both lie within ±arena on every axis, so a difference stays within ±2 arena sizes
RELATIVE_BOUND = 2.0


@dataclasses.dataclass(frozen=True)
class Scales:
    """The units observations and the state are measured in: one home for their normalisation."""

    arena: np.ndarray       # (3,) positions ÷ arena
    diagonal: float         # distances ÷ the arena diagonal
    reward_unit: float      # bids and rewards ÷ the largest task reward c̄
    horizon: float          # times ÷ the latest finite window end
    max_speed: float        # speeds ÷ the fastest agent

    @classmethod
    def of(cls, scenario: Scenario) -> Scales:
        arena = np.asarray(scenario.arena, dtype=float)
        finite_end = scenario.task_end[np.isfinite(scenario.task_end)]
        horizon = float(finite_end.max()) if finite_end.size and finite_end.max() > 0 else 1.0
        return cls(arena, float(np.linalg.norm(arena)), float(scenario.task_reward.max()) or 1.0, horizon,
                   float(scenario.agent_speed.max()))

    def window(self, scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
        """(M,) window start and end ÷ horizon, clipped to [0, 1] (an open window ends at the horizon)."""
        start = np.clip(scenario.task_start / self.horizon, 0, 1)
        end = np.clip(np.minimum(scenario.task_end, self.horizon) / self.horizon, 0, 1)
        return start, end


@dataclasses.dataclass(frozen=True)
class ObservationLayout:
    """Column positions of the observation vector."""

    n_tasks: int
    n_equipment: int
    task_names: tuple[str, ...] = TASK_FEATURES

    # derived once per layout (read at every step by the policies; a frozen dataclass keeps them in its __dict__)
    @functools.cached_property
    def own_names(self) -> tuple[str, ...]:
        return OWN_FEATURES + tuple(f"equipment_{e}" for e in range(self.n_equipment))

    @functools.cached_property
    def own_size(self) -> int:
        return len(self.own_names)

    @functools.cached_property
    def task_size(self) -> int:
        return len(self.task_names)

    @functools.cached_property
    def size(self) -> int:
        return self.own_size + self.n_tasks * self.task_size

    def task_column(self, name: str) -> int:
        return self.task_names.index(name)

    def split(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(…, D) → own (…, own_size) and tasks (…, M, task_size)."""
        own = obs[..., : self.own_size]
        tasks = obs[..., self.own_size:].reshape(*obs.shape[:-1], self.n_tasks, self.task_size)
        return own, tasks

    def task_feature(self, obs: np.ndarray, name: str) -> np.ndarray:
        """(…, M) one feature of every task."""
        return self.split(obs)[1][..., self.task_column(name)]

    def bounds(self, max_agents_per_task: int, max_rounds: int, n_agents: int) -> tuple[np.ndarray, np.ndarray]:
        own_low = np.zeros(self.own_size)
        own_low[:3] = -1.0                       # positions / arena; explicit scenarios may sit below 0
        own_high = np.ones(self.own_size)
        task_low = np.zeros(self.task_size)
        task_high = np.ones(self.task_size)
        task_high[self.task_column("group_total")] = max_agents_per_task
        task_high[self.task_column("required_agents")] = max(1.0, max_agents_per_task / n_agents)
        task_high[self.task_column("rounds_since_change")] = max_rounds
        for name in ("dx", "dy", "dz"):
            task_low[self.task_column(name)] = -RELATIVE_BOUND
            task_high[self.task_column(name)] = RELATIVE_BOUND
        task_high[self.task_column("distance")] = RELATIVE_BOUND
        if "nearest_other" in self.task_names:
            task_high[self.task_column("nearest_other")] = RELATIVE_BOUND
        low = np.concatenate([own_low, np.tile(task_low, self.n_tasks)])
        high = np.concatenate([own_high, np.tile(task_high, self.n_tasks)])
        return low, high


class ObservationBuilder:
    """Builds every agent's observation from the protocol's local tables, vectorised over agents."""

    def __init__(self, protocol: Protocol, max_agents_per_task: int, max_rounds: int) -> None:
        """``max_agents_per_task`` and ``max_rounds`` bound every instance the env can draw (for the space)."""
        s = protocol.scenario
        names = (TASK_FEATURES + (FAULT_FEATURES if protocol.cfg.faulty else ())
                 + (POPUP_FEATURES if protocol.cfg.popup_tasks else ())
                 + (TEAM_FEATURES if protocol.cfg.team_features else ()))
        self.layout = ObservationLayout(s.n_tasks, len(s.equipment_names), names)
        self._bounds = (max_agents_per_task, max_rounds, s.n_agents)
        self.scales = Scales.of(s)
        self._buffer = self._static_features(protocol)
        self._columns = {name: c for c, name in enumerate(self.layout.task_names)}
        self._kernel_columns = np.array([self._columns[name] for name in KERNEL_COLUMNS], dtype=np.int64)
        self._silence, self._popups = "member_silence" in self._columns, "released" in self._columns
        self._tasks = self._task_block()
        # with pop-up tasks a hidden task's block is zeroed, its fixed columns too: kept to restore on release
        self._static_tasks = self._tasks.copy() if protocol.cfg.popup_tasks else None

    def _task_block(self) -> np.ndarray:
        """(N, M, F) the task features: a view into ``_buffer``, which every write goes through."""
        n_agents = len(self._buffer)
        return self._buffer[:, self.layout.own_size:].reshape(n_agents, self.layout.n_tasks, self.layout.task_size)

    def __getstate__(self) -> dict:
        """A copy or pickle keeps the buffer only: an array view is copied on its own, apart from its base."""
        state = dict(self.__dict__)
        del state["_tasks"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._tasks = self._task_block()

    def space(self, dtype: np.dtype) -> spaces.Box:
        """The observation space (built once per env; its bounds are not recomputed at every reset)."""
        low, high = self.layout.bounds(*self._bounds)
        return spaces.Box(low.astype(dtype), high.astype(dtype), dtype=dtype)

    def _static_features(self, protocol: Protocol) -> np.ndarray:
        """(N, D) observations with the columns that never change filled in (the rest is written by ``build``)."""
        s = protocol.scenario
        obs = np.zeros((s.n_agents, self.layout.size))
        obs[:, :3] = s.agent_pos / self.scales.arena
        obs[:, 3] = s.agent_speed / self.scales.max_speed
        obs[:, len(OWN_FEATURES):self.layout.own_size] = s.agent_equipment
        f = obs[:, self.layout.own_size:].reshape(s.n_agents, s.n_tasks, self.layout.task_size)
        col = self.layout.task_column
        f[:, :, col("required_agents")] = s.task_agents[None, :] / s.n_agents
        f[:, :, col("window_start")], f[:, :, col("window_end")] = self.scales.window(s)
        rel = (s.task_pos[None, :, :] - s.agent_pos[:, None, :]) / self.scales.arena
        f[:, :, col("dx")], f[:, :, col("dy")], f[:, :, col("dz")] = rel[..., 0], rel[..., 1], rel[..., 2]
        # ≤ 2 under euclidean travel (the bound never binds); under manhattan it can exceed 2 only for positions
        # beyond the arena's [0, size] box, and is then held at the space's bound
        f[:, :, col("distance")] = np.minimum(protocol.model.dist_agent_task / self.scales.diagonal, RELATIVE_BOUND)
        f[:, :, col("equipment_match")] = protocol.equipment_match
        if "sooner_agents" in self.layout.task_names:
            f[:, :, col("sooner_agents")], f[:, :, col("nearest_other")] = self._team_features(protocol)
        return obs

    def _team_features(self, protocol: Protocol) -> tuple[np.ndarray, np.ndarray]:
        """(N, M) ``TEAM_FEATURES``: the other agents that reach each task sooner from their starts, ÷ N, and the
        nearest other agent's start distance, ÷ the arena diagonal (``RELATIVE_BOUND`` when there is none)."""
        s = protocol.scenario
        distance = protocol.model.dist_agent_task                                  # (N, M)
        flight = distance / s.agent_speed[:, None]
        sooner, nearest = np.zeros(distance.shape), np.full(distance.shape, np.inf)
        for i in range(s.n_agents):                  # one agent at a time: (N, M) temporaries, not (N, N, M)
            others = np.arange(s.n_agents) != i
            sooner[i] = (flight[others] < flight[i]).sum(axis=0)
            if others.any():
                nearest[i] = distance[others].min(axis=0)
        return sooner / s.n_agents, np.minimum(nearest / self.scales.diagonal, RELATIVE_BOUND)

    def observe(self, protocol: Protocol, passed: np.ndarray, dtype: np.dtype | type = np.float64) -> np.ndarray:
        """(N, D) observations in ``dtype`` (a new array); row i uses only agent i's table, path and flags (the action
        masks are ``engine.action_masks``). The per-step columns are written by the compiled
        ``kernels.observe.step_features`` when numba is there, else by ``observe_reference``'s numpy lines (the
        same values, bit for bit)."""
        if not kernels.COMPILED:
            return self.observe_reference(protocol, passed, dtype)
        s = protocol.scenario
        kn = protocol.knowledge
        view = protocol.view()
        if self._static_tasks is not None:
            np.copyto(self._tasks, self._static_tasks)
        step_features(self._tasks, self._kernel_columns, self.scales.reward_unit, view.gain, view.can_bid,
                      view.outbid, view.members, s.task_agents, view.lowest_bid, view.group_total, view.displaced_bid,
                      view.in_bundle, kn.groups.own, kn.quit, protocol.quit_options(), protocol.round,
                      kn.assigned_at, view.prereqs_met, self._buffer, self._bundle_sizes(kn),
                      self._round_fraction(protocol), passed)
        return self._finish(protocol, dtype)

    def observe_reference(self, protocol: Protocol, passed: np.ndarray, dtype: np.dtype | type = np.float64
                          ) -> np.ndarray:
        """``observe`` in numpy (the reference of ``kernels.observe.step_features``)."""
        s = protocol.scenario
        kn = protocol.knowledge
        view = protocol.view()
        unit = self.scales.reward_unit
        col = self._columns.__getitem__
        f = self._tasks
        if self._static_tasks is not None:
            np.copyto(f, self._static_tasks)
        f[:, :, col("gain")] = view.gain / unit
        f[:, :, col("can_bid")] = view.can_bid
        f[:, :, col("outbid")] = view.outbid
        f[:, :, col("members")] = view.members / s.task_agents[None, :]
        f[:, :, col("lowest_bid")] = view.lowest_bid / unit
        f[:, :, col("group_total")] = view.group_total / unit
        f[:, :, col("displaced_bid")] = view.displaced_bid / unit
        f[:, :, col("in_bundle")] = view.in_bundle
        f[:, :, col("own_bid")] = kn.own_bids() / unit
        f[:, :, col("quit_before")] = kn.quit
        f[:, :, col("can_quit")] = protocol.quit_options()
        f[:, :, col("rounds_since_change")] = np.where(view.in_bundle, protocol.round - kn.assigned_at, 0)
        f[:, :, col("prereqs_met")] = view.prereqs_met
        f[:, :, col("group_complete")] = view.members == s.task_agents[None, :]
        own = self._buffer
        own[:, BUNDLE_SIZE] = self._bundle_sizes(kn) / s.n_tasks
        own[:, ROUND] = self._round_fraction(protocol)
        own[:, PASSED] = passed
        return self._finish(protocol, dtype)

    @staticmethod
    def _bundle_sizes(knowledge: LocalKnowledge) -> np.ndarray:
        """(N,) the bundle sizes |b_i| as floats."""
        return np.fromiter(map(len, knowledge.bundles), dtype=float, count=len(knowledge.bundles))

    @staticmethod
    def _round_fraction(protocol: Protocol) -> float:
        """The round as a fraction of the round bound (the own feature ``round``)."""
        return min(protocol.round / protocol.max_rounds, 1.0)

    def _finish(self, protocol: Protocol, dtype: np.dtype | type) -> np.ndarray:
        """The mode-dependent task columns; the observations in ``dtype``."""
        kn = protocol.knowledge
        col = self._columns.__getitem__
        f = self._tasks
        if self._silence:
            silence = (protocol.round - kn.timestamps) / protocol.silence_timeout               # (N, N)
            np.fill_diagonal(silence, 0.0)
            ids = kn.groups.members                                                             # (N, M, W)
            quiet = np.where(ids >= 0, silence[np.arange(len(ids))[:, None, None], np.maximum(ids, 0)], 0.0)
            f[:, :, col("member_silence")] = np.minimum(quiet.max(axis=2), 1.0)
        if self._popups:                                        # a task not yet released: its whole block is zero
            f[:, :, col("released")] = protocol.released
            f[:, ~protocol.released, :] = 0.0
        return self._buffer.astype(dtype)


def state_vector(protocol: Protocol) -> np.ndarray:
    """Global view: agent and task attributes, every agent's own row of bids (ground truth) and the round."""
    s = protocol.scenario
    scales = Scales.of(s)
    window_start, window_end = scales.window(s)
    known = protocol.released                   # a pop-up task is invisible before its release
    parts = [
        (s.agent_pos / scales.arena).ravel(),
        s.agent_equipment.astype(float).ravel(),
        (s.task_pos / scales.arena * known[:, None]).ravel(),
        window_start * known,
        window_end * known,
        s.task_agents / s.n_agents * known,
        (protocol.knowledge.own_bids() / scales.reward_unit).ravel(),
        [min(protocol.round / protocol.max_rounds, 1.0)],
    ]
    return np.concatenate([np.asarray(p, dtype=float).ravel() for p in parts])
