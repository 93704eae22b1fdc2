"""Agents and tasks of one problem instance, as arrays (thesis §3.1.1–3.1.3).

A :class:`Scenario` is either generated from a :class:`~taskalloc_env.config.TaskAllocConfig` and a
``numpy.random.Generator`` (``generate``; every seed a new instance, thesis §3.3.2), or built from explicit
:class:`Agent` and :class:`Task` records (``Scenario.from_entities``). Agent and task ids are their indices.

Equipment: every agent carries a set of equipment items (``ae_i``, a bit mask over the scenario's equipment
names) and every task requires a multiset (``te_j``, a count per item; the multiset is our reading of te_j); the
empty multiset lets any agent bid (thesis §3.1.3).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc_env.config import MAX_MAGNITUDE, TaskAllocConfig, type_counts
from taskalloc_env.errors import ConfigError
from taskalloc_env.fields import bounded_repr, fail
from taskalloc_env.generators import GENERATORS, register_generator

NO_DEADLINE = np.inf
# our size limits of a scenario built from entities (docs/decisions.md "config limits"): its (M, M) prerequisite
# matrix stays below 100 MB, and the per-record checks below take seconds, not minutes
MAX_AGENTS_BUILT = 100_000
MAX_TASKS_BUILT = 10_000


@dataclasses.dataclass(frozen=True)
class Agent:
    """One UAV: start position (3-D), constant speed, equipment set ae_i (thesis §3.1.3, §3.3.2)."""

    position: tuple[float, float, float]
    speed: float
    equipment: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class Task:
    """One task: position, reward c̄_j, start window [start, end], duration, L_j, te_j, P_j (thesis §3.1.2–3.1.3)."""

    position: tuple[float, float, float]
    reward: float
    start: float
    end: float
    duration: float
    agents: int = 1
    equipment: tuple[str, ...] = ()
    prerequisites: tuple[int, ...] = ()


@dataclasses.dataclass(frozen=True, eq=False)
class Scenario:
    """Arrays of agent and task attributes. Shapes: N agents, M tasks, E equipment items.

    Checked on construction and read-only afterwards (the protocol plans on it): a changed instance is a new one,
    ``dataclasses.replace(scenario, agent_pos=moved)``, checked again.
    """

    agent_pos: np.ndarray          # (N, 3)
    agent_speed: np.ndarray        # (N,)
    agent_equipment: np.ndarray    # (N, E) bool: ae_i
    task_pos: np.ndarray           # (M, 3)
    task_reward: np.ndarray        # (M,) c̄_j
    task_start: np.ndarray         # (M,)
    task_end: np.ndarray           # (M,) latest start (arrival must be strictly earlier, (3.7))
    task_duration: np.ndarray      # (M,)
    task_agents: np.ndarray        # (M,) int L_j
    task_equipment: np.ndarray     # (M, E) int: te_j as counts per item
    task_prereqs: np.ndarray       # (M, M) bool: task_prereqs[j, m] ⇔ m ∈ P_j
    time_discount: float           # λ
    distance_discount: float       # γ
    equipment_names: tuple[str, ...] = ()
    arena: tuple[float, float, float] = (5.0, 5.0, 2.0)

    def __post_init__(self) -> None:
        n, m = len(self.agent_pos), len(self.task_pos)
        if not (len(self.arena) == 3 and all(_is_number(v) and 0 < v <= MAX_MAGNITUDE for v in self.arena)):
            raise ConfigError(f"scenario arena {bounded_repr(self.arena)} must be three sizes in "
                              f"(0, {MAX_MAGNITUDE:g}]")
        if not np.issubdtype(np.asarray(self.task_agents).dtype, np.integer):
            raise ConfigError(f"scenario task_agents {bounded_repr(self.task_agents)} must be integers (L_j)")
        e = len(self.equipment_names)
        checks = {
            "agent_pos": (self.agent_pos.shape, (n, 3)),
            "agent_speed": (self.agent_speed.shape, (n,)),
            "agent_equipment": (self.agent_equipment.shape, (n, e)),
            "task_reward": (self.task_reward.shape, (m,)),
            "task_start": (self.task_start.shape, (m,)),
            "task_end": (self.task_end.shape, (m,)),
            "task_duration": (self.task_duration.shape, (m,)),
            "task_agents": (self.task_agents.shape, (m,)),
            "task_equipment": (self.task_equipment.shape, (m, e)),
            "task_prereqs": (self.task_prereqs.shape, (m, m)),
        }
        for name, (got, want) in checks.items():
            if got != want:
                raise ValueError(f"scenario array {name} has shape {got}, expected {want}")
        if n == 0 or m == 0:
            raise ValueError(f"a scenario needs at least one agent and one task (got {n} agents, {m} tasks)")
        finite = {"agent_pos": self.agent_pos, "agent_speed": self.agent_speed, "task_pos": self.task_pos,
                  "task_reward": self.task_reward, "task_start": self.task_start, "task_duration": self.task_duration}
        for name, array in finite.items():
            bad = ~(np.abs(array) <= MAX_MAGNITUDE)         # NaN and ±inf compare False
            if bad.any():
                raise ValueError(f"scenario array {name} holds {array[bad].tolist()[:3]}: every value must be a finite "
                                 f"number within ±{MAX_MAGNITUDE:g}")
        if np.isnan(self.task_end).any() or (self.task_end == -np.inf).any():
            raise ValueError("task windows must end at a number or +inf (open), not NaN or -inf")
        for name in ("time_discount", "distance_discount"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= MAX_MAGNITUDE):
                raise ValueError(f"scenario {name} must be a finite number in [0, {MAX_MAGNITUDE:g}], got {value!r}")
        if (self.agent_speed <= 0).any():
            raise ValueError(f"agent speeds must be > 0, got {self.agent_speed.tolist()}")
        if (self.task_agents < 1).any():
            raise ValueError(f"every task needs L_j >= 1 agents, got {self.task_agents.tolist()}")
        if (self.task_end < self.task_start).any():
            bad = np.flatnonzero(self.task_end < self.task_start).tolist()
            raise ValueError(f"tasks {bad} have end < start")
        positions = np.vstack([self.agent_pos, self.task_pos])
        if (np.abs(positions) > np.asarray(self.arena) * (1 + 1e-9)).any():
            raise ValueError(f"positions must lie within ±arena {self.arena} on every axis")
        if (self.task_duration < 0).any() or (self.task_reward < 0).any():
            raise ValueError("task durations and rewards must be >= 0")
        items = self.task_equipment.sum(axis=1)
        if ((items > 0) & (items != self.task_agents)).any():
            bad = np.flatnonzero((items > 0) & (items != self.task_agents)).tolist()
            raise ValueError(f"tasks {bad} require a number of equipment items other than L_j: a task's equipment "
                             "names one item per agent, |te_j| = L_j, or none at all (thesis §3.1.3; "
                             "decoupling L_j from te_j is future work, thesis §6.1.2 and §6.2)")
        if (self.agent_equipment.sum(axis=1) > 1).any():
            bad = np.flatnonzero(self.agent_equipment.sum(axis=1) > 1).tolist()
            raise ValueError(f"agents {bad} carry several equipment items; every agent carries one type or none "
                             "(|ae_i| = 1 in every experiment of the thesis; with several items the group rules "
                             "of docs/algorithm.md depend on the order members join)")
        if np.diag(self.task_prereqs).any():
            raise ValueError("a task cannot be its own prerequisite (j ∉ P_j, thesis §3.1.3)")
        if self.task_prereqs.any() and _has_cycle(self.task_prereqs):
            raise ValueError("prerequisites contain a cycle; no task of the cycle could ever be done")
        for field in dataclasses.fields(self):       # not dataclasses.astuple: it would freeze deep copies
            array = getattr(self, field.name)
            if isinstance(array, np.ndarray):
                array.setflags(write=False)

    @property
    def n_agents(self) -> int:
        return len(self.agent_pos)

    @property
    def n_tasks(self) -> int:
        return len(self.task_pos)

    @property
    def multi_agent(self) -> np.ndarray:
        """Tasks with L_j > 1."""
        return self.task_agents > 1

    # read-only arrays (``__post_init__``): what is derived from them is computed once (kept in __dict__)
    @functools.cached_property
    def has_equipment(self) -> bool:
        return bool(self.task_equipment.any())

    @functools.cached_property
    def has_prerequisites(self) -> bool:
        return bool(self.task_prereqs.any())

    def eligible(self) -> np.ndarray:
        """(N, M) equipment eligibility: te_j = ∅ or ae_i ∩ te_j ≠ ∅ (thesis §3.1.3)."""
        required = self.task_equipment > 0
        shares = self.agent_equipment.astype(np.int64) @ required.T.astype(np.int64) > 0
        return shares | ~required.any(axis=1)[None, :]

    def infeasible_tasks(self) -> dict[int, str]:
        """Tasks no team of this scenario can ever complete, with the reason (reported, not an error)."""
        reasons: dict[int, str] = {}
        capable = self.eligible().sum(axis=0)
        short = self.task_equipment > self.agent_equipment.sum(axis=0)[None, :]     # items all agents carry < te_j
        for j in np.flatnonzero((capable < self.task_agents) | short.any(axis=1)).tolist():
            if capable[j] < self.task_agents[j]:
                reasons[j] = (f"needs L_j = {self.task_agents[j]} agents but only {capable[j]} carry "
                              "equipment it accepts")
            elif short[j].any():
                names = [self.equipment_names[e] for e in np.flatnonzero(short[j])]
                reasons[j] = f"needs more agents with {names} than the scenario has"
        return reasons

    @classmethod
    def from_entities(cls, agents: Sequence[Agent], tasks: Sequence[Task], *, time_discount: float = 0.8,
                      distance_discount: float = 0.8, arena: tuple[float, float, float] | None = None,
                      equipment_names: Sequence[str] | None = None) -> Scenario:
        """Build a fixed scenario from explicit agents and tasks (ids are list positions); at most
        ``MAX_AGENTS_BUILT`` agents and ``MAX_TASKS_BUILT`` tasks (the (M, M) prerequisite matrix, checked first)."""
        if len(agents) > MAX_AGENTS_BUILT or len(tasks) > MAX_TASKS_BUILT:
            raise ConfigError(f"a scenario built from entities holds at most {MAX_AGENTS_BUILT} agents and "
                              f"{MAX_TASKS_BUILT} tasks (got {len(agents)} and {len(tasks)}; our size limit, "
                              "docs/decisions.md \"config limits\")")
        if equipment_names is None:
            seen: list[str] = []
            for item in [e for a in agents for e in a.equipment] + [e for t in tasks for e in t.equipment]:
                if item not in seen:
                    seen.append(item)
            equipment_names = seen
        names = tuple(equipment_names)
        index = {name: e for e, name in enumerate(names)}
        for kind, records, record_type in (("agent", agents, Agent), ("task", tasks, Task)):
            for k, record in enumerate(records):
                _check_record(kind, k, record, record_type)
            _warn_duplicates(kind, records)
        for record in [*agents, *tasks]:
            unknown = [e for e in record.equipment if e not in index]
            if unknown:
                raise ValueError(f"equipment {unknown} of {record} is not in equipment_names {list(names)}")
        m = len(tasks)
        prereqs = np.zeros((m, m), dtype=bool)
        for j, task in enumerate(tasks):
            for p in task.prerequisites:
                if not 0 <= p < m:
                    raise ValueError(f"task {j} names prerequisite {p}, but task ids run 0..{m - 1}")
                prereqs[j, p] = True
        agent_eq = np.zeros((len(agents), len(names)), dtype=bool)
        for i, agent in enumerate(agents):
            agent_eq[i, [index[e] for e in agent.equipment]] = True
        task_eq = np.zeros((m, len(names)), dtype=np.int64)
        for j, task in enumerate(tasks):
            for e in task.equipment:
                task_eq[j, index[e]] += 1
        positions = np.array([a.position for a in agents] + [t.position for t in tasks], dtype=float).reshape(-1, 3)
        if arena is None:  # every |coordinate| / arena ≤ 1, which the observation bounds rely on
            arena = tuple(float(v) for v in np.maximum(np.abs(positions).max(axis=0), 1e-9))
        return cls(
            agent_pos=np.array([a.position for a in agents], dtype=float).reshape(-1, 3),
            agent_speed=np.array([a.speed for a in agents], dtype=float),
            agent_equipment=agent_eq,
            task_pos=np.array([t.position for t in tasks], dtype=float).reshape(-1, 3),
            task_reward=np.array([t.reward for t in tasks], dtype=float),
            task_start=np.array([t.start for t in tasks], dtype=float),
            task_end=np.array([t.end for t in tasks], dtype=float),
            task_duration=np.array([t.duration for t in tasks], dtype=float),
            task_agents=np.array([t.agents for t in tasks], dtype=np.int64),
            task_equipment=task_eq,
            task_prereqs=prereqs,
            time_discount=float(time_discount),
            distance_discount=float(distance_discount),
            equipment_names=names,
            arena=tuple(arena),
        )


def scenario_config(scenario: Scenario, base: str = "default", **overrides: Any) -> TaskAllocConfig:
    """The config of a fixed scenario: ``base``'s scoring and protocol options, its counts and L_j values.

    Fields that generate instances cannot apply to a fixed scenario; overriding one raises ``ConfigError``.
    """
    from taskalloc_env.config import GENERATION_FIELDS, resolve_config

    levels = tuple(sorted({int(v) for v in scenario.task_agents}))
    counts = {"n_agents": scenario.n_agents, "n_tasks": scenario.n_tasks,
              "agents_per_task": levels[0] if len(levels) == 1 else levels}

    def same(key: str, value: Any) -> bool:
        return key in counts and (value == counts[key] or (isinstance(value, (list, tuple))
                                                           and tuple(sorted(set(value))) == levels))

    moot = sorted(k for k in overrides if k in GENERATION_FIELDS and not same(k, overrides[k]))
    if moot:
        raise ConfigError(f"overrides {moot} generate instances and cannot apply to a fixed Scenario; set them on "
                          "its agents and tasks (scoring and protocol options may be overridden)")
    return resolve_config(base, **{**overrides, **counts})


def _check_record(kind: str, k: int, record: Agent | Task, cls: type) -> None:
    """An explicit agent or task has the declared types: numbers are numbers, counts are integers (no silent casts)."""
    if not isinstance(record, cls):
        raise ValueError(f"{kind} {k} is a {type(record).__name__}, not a {cls.__name__}")
    if not (isinstance(record.position, (tuple, list)) and len(record.position) == 3
            and all(_is_number(v) for v in record.position)):
        raise ValueError(f"{kind} {k}: position {record.position!r} must be three numbers (x, y, z)")
    numbers = ("speed",) if kind == "agent" else ("reward", "start", "end", "duration")
    for field in numbers:
        if not _is_number(getattr(record, field)):
            raise ValueError(f"{kind} {k}: {field} {getattr(record, field)!r} must be a number")
    if not (isinstance(record.equipment, (tuple, list)) and all(isinstance(e, str) for e in record.equipment)):
        raise ValueError(f"{kind} {k}: equipment {record.equipment!r} must be a tuple of item names")
    if kind == "task":
        if isinstance(record.agents, bool) or not isinstance(record.agents, (int, np.integer)) or record.agents < 1:
            raise ValueError(f"task {k}: agents {record.agents!r} must be an integer >= 1 (L_j)")
        if not all(isinstance(p, (int, np.integer)) and not isinstance(p, bool) for p in record.prerequisites):
            raise ValueError(f"task {k}: prerequisites {record.prerequisites!r} must be task ids (integers)")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _warn_duplicates(kind: str, records: Sequence[Agent | Task]) -> None:
    """Identical agents or tasks are allowed (two UAVs on one base, two equal jobs) but worth a word."""
    seen: dict[Agent | Task, int] = {}
    for k, record in enumerate(records):
        if record in seen:
            warnings.warn(f"{kind}s {seen[record]} and {k} are identical; allowed, and exact ties between them go to "
                          "the rule of the tie (see docs/decisions.md)", stacklevel=4)
        seen.setdefault(record, k)


def _has_cycle(prereqs: np.ndarray) -> bool:
    """Whether the prerequisite graph has a cycle (Kahn's algorithm)."""
    indegree = prereqs.sum(axis=1).astype(int)
    ready = list(np.flatnonzero(indegree == 0))
    seen = 0
    while ready:
        m = ready.pop()
        seen += 1
        for j in np.flatnonzero(prereqs[:, m]):
            indegree[j] -= 1
            if indegree[j] == 0:
                ready.append(j)
    return seen < len(prereqs)


def generate(cfg: TaskAllocConfig, rng: np.random.Generator) -> Scenario:
    """Draw a random instance of ``cfg`` with the generator it names (``cfg.generator``, ``uniform`` by default)."""
    return GENERATORS[cfg.generator](cfg, rng)     # the config refused an unregistered name (config_rules)


def uniform(cfg: TaskAllocConfig, rng: np.random.Generator) -> Scenario:
    """Draw a random instance of ``cfg`` (the test scenario of thesis §3.3.2).

    Agents start uniformly on the floor (z = 0), tasks uniformly in the W × W × H volume, start times
    U(start_time_range) (the distribution is our choice; the thesis does not state it), end = start + window,
    duration fixed. L_j is ``agents_per_task``
    (one value, or drawn uniformly from a list), or comes from ``task_mix``. Prerequisite chains follow E3.15.
    """
    n, m = cfg.n_agents, cfg.n_tasks
    width, depth, height = cfg.arena
    agent_pos = np.column_stack([rng.uniform(0, width, n), rng.uniform(0, depth, n), np.zeros(n)])
    task_pos = rng.uniform((0, 0, 0), (width, depth, height), size=(m, 3))
    start = rng.uniform(*cfg.start_time_range, size=m)
    end = start + cfg.window
    names = cfg.equipment_names
    agent_eq = np.zeros((n, len(names)), dtype=bool)
    if cfg.agent_types:
        types = np.repeat(np.arange(len(cfg.agent_types)), type_counts(cfg))
        agent_eq[np.arange(n), types] = True
    task_eq = np.zeros((m, len(names)), dtype=np.int64)
    if cfg.task_mix:
        agents = np.empty(m, dtype=np.int64)
        j = 0
        for mix in cfg.task_mix:
            for _ in range(mix.count):
                agents[j] = mix.required_agents
                for item in mix.equipment:
                    task_eq[j, names.index(item)] += 1
                j += 1
    else:
        agents = required_agents(cfg, rng, m)
    prereqs = np.zeros((m, m), dtype=bool)
    if cfg.prerequisites:
        chains = cfg.prerequisites
        order = rng.permutation(m)[: chains.chains * chains.length].reshape(chains.chains, chains.length)
        for chain in order:
            for earlier, later in itertools.pairwise(chain):
                prereqs[later, earlier] = True
                if not chains.followup_window:
                    end[later] = NO_DEADLINE
    speed = np.full(n, cfg.speed_internal)
    return Scenario(
        agent_pos=agent_pos, agent_speed=speed, agent_equipment=agent_eq, task_pos=task_pos,
        task_reward=np.full(m, cfg.reward), task_start=start, task_end=end, task_duration=np.full(m, cfg.duration),
        task_agents=agents, task_equipment=task_eq, task_prereqs=prereqs, time_discount=cfg.time_discount,
        distance_discount=cfg.distance_discount, equipment_names=names, arena=cfg.arena,
    )


def required_agents(cfg: TaskAllocConfig, rng: np.random.Generator, m: int) -> np.ndarray:
    """(m,) L_j from ``agents_per_task``: the one value, or drawn uniformly per task from its list."""
    if isinstance(cfg.agents_per_task, tuple):
        return rng.choice(np.array(cfg.agents_per_task, dtype=np.int64), size=m)
    return np.full(m, cfg.agents_per_task, dtype=np.int64)


def _check_uniform(cfg: TaskAllocConfig) -> None:
    if cfg.grid:
        fail("grid", cfg.grid, "false with generator uniform (grid cells are the visit generator's)")


def visit_starts(cfg: TaskAllocConfig) -> np.ndarray:
    """(N, 3) the visit agents' starts: evenly along the floor's edge x = 0, from y = 0 to y = depth (one agent: the
    edge's middle), each on the nearest integer cell under ``grid`` (the DCTA benchmark's ``edge_even`` layout:
    4 robots at y = 0, 6, 12, 18 of a 19 × 19 grid)."""
    n, depth = cfg.n_agents, cfg.arena[1]
    y = depth * np.arange(n) / (n - 1) if n > 1 else np.array([depth / 2])
    if cfg.grid:
        y = np.round(y)
    return np.column_stack([np.zeros(n), y, np.zeros(n)])


def _grid_cells(cfg: TaskAllocConfig) -> np.ndarray:
    """(C, 2) the floor's integer cells (x, y) that are no agent's start, in row-major order."""
    width, depth = (int(np.floor(v)) for v in cfg.arena[:2])
    x, y = np.meshgrid(np.arange(width + 1), np.arange(depth + 1), indexing="ij")
    cells = np.column_stack([x.ravel(), y.ravel()]).astype(float)
    taken = (cells[:, None, :] == visit_starts(cfg)[None, :, :2]).all(axis=2).any(axis=1)
    return cells[~taken]


def _check_visit(cfg: TaskAllocConfig) -> None:
    """What ``visit`` cannot honour: equipment, task mixes and prerequisites (it draws none), and more agents or
    targets than the grid has cells for."""
    for name in ("agent_types", "agent_type_counts", "task_mix", "prerequisites"):
        if getattr(cfg, name) is not None:
            fail(name, getattr(cfg, name), "null with generator visit (its targets need no equipment or order)")
    if not cfg.grid:
        return
    edge = int(np.floor(cfg.arena[1])) + 1
    if cfg.n_agents > edge:
        fail("n_agents", cfg.n_agents, f"at most {edge} with generator visit and grid: one cell each along the "
             f"edge of depth {cfg.arena[1]:g}")
    free = (int(np.floor(cfg.arena[0])) + 1) * edge - cfg.n_agents
    if cfg.n_tasks > free:
        fail("n_tasks", cfg.n_tasks, f"at most {free} with generator visit and grid: the cells of the "
             f"{cfg.arena[0]:g} × {cfg.arena[1]:g} floor that are no agent's start")


def visit(cfg: TaskAllocConfig, rng: np.random.Generator) -> Scenario:
    """Draw a collaborative-visit instance (ours, after Nayak et al., IEEE RA-L 2020, "Collaborative visit": agents
    visit known stationary targets; and the DCTA benchmark's 19 × 19 grid with 4 robots on its left edge and 10
    targets on distinct cells, none on a start).

    Agents start on the floor's edge x = 0 (``visit_starts``); the ``n_tasks`` targets lie on the floor (z = 0),
    uniformly, or on distinct integer cells under ``grid``; every target is known from the start, open from time 0
    and never closes (``start_time_range`` and ``window`` are not used), with reward c̄ and L_j from
    ``agents_per_task`` (1 in ``configs/scenarios/visit.yaml``).
    """
    n, m = cfg.n_agents, cfg.n_tasks
    agent_pos = visit_starts(cfg)
    if cfg.grid:
        cells = _grid_cells(cfg)
        floor = cells[rng.choice(len(cells), size=m, replace=False)]
    else:
        floor = rng.uniform((0.0, 0.0), cfg.arena[:2], size=(m, 2))
    task_pos = np.column_stack([floor, np.zeros(m)])
    return Scenario(
        agent_pos=agent_pos, agent_speed=np.full(n, cfg.speed_internal), agent_equipment=np.zeros((n, 0), dtype=bool),
        task_pos=task_pos, task_reward=np.full(m, cfg.reward), task_start=np.zeros(m),
        task_end=np.full(m, NO_DEADLINE), task_duration=np.full(m, cfg.duration),
        task_agents=required_agents(cfg, rng, m), task_equipment=np.zeros((m, 0), dtype=np.int64),
        task_prereqs=np.zeros((m, m), dtype=bool), time_discount=cfg.time_discount,
        distance_discount=cfg.distance_discount, arena=cfg.arena,
    )


register_generator("uniform", uniform, _check_uniform)
register_generator("visit", visit, _check_visit)
