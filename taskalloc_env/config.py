"""Configuration of a task-allocation problem and of the consensus protocol that solves it.

One flat, frozen :class:`TaskAllocConfig` holds three groups of fields:

* scenario generation (thesis §3.3.2, §3.3.4, §5.3.1): counts, arena, speeds, windows, agent types, task
  equipment mixes, prerequisite chains, communication range;
* scoring (thesis §3.2.2, (3.8)–(3.11); §5.3.1): discount rates and the named options ``distance_cost``,
  ``prereq_timing``, ``reward_split``, ``conflict_policy``, ``marginal_gain``;
* protocol (thesis §3.2–§5.2; Johnson §3.4.1): ``cbba_table``, ``prereq_mode``, ``release_order``,
  ``task_quitting``, ``delta``, ``reset_on``, ``quit_block``, ``require_known_capacity``, ``consensus``,
  ``max_bundle``, ``max_rounds``; the network (``message_loss`` …); pop-up tasks (``popup_*``,
  ``mission_time_per_tick``; Johnson §4.1.3) and the asynchronous consensus ``consensus="acbba"`` (``message_ticks``,
  ``build_ticks``, ``separation_time``, ``termination``, ``acbba_*``; Johnson §4.1); the observations'
  ``team_features`` (ours, off by default).

The named options mark points the sources leave open or state in more than one way; docs/configuration.md gives
the source of each and docs/decisions.md the reasons for the defaults. Configs come from YAML files in
``configs/scenarios/`` (``load_config``) and keyword overrides (``TaskAllocConfig.replace``); unknown keys and bad
values raise :class:`ConfigError` naming the field and the allowed values.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from taskalloc_env import resources, stamps
from taskalloc_env.errors import ConfigError

# every real-valued field lies within ±MAX_MAGNITUDE: far beyond any sensible unit, and small enough that
# distances, times and their sums stay finite (1e308 would overflow to inf and NaN)
MAX_MAGNITUDE = 1e9
MAX_FILE_BYTES = 1 << 20       # config files are a few hundred bytes; anything beyond 1 MiB is refused unread


# Allowed values of every named option (docs/configuration.md gives the source of each).
CHOICES: dict[str, tuple[str, ...]] = {
    "units": ("km_min", "raw"),
    "edge_rule": ("dist", "circles_overlap"),
    "distance_cost": ("leg", "from_start"),
    "prereq_mode": ("all_have_bid", "all_complete", "any_has_bid"),
    "prereq_timing": ("conservative", "earliest", "none"),
    "conflict_policy": ("first_L_paid", "none_paid"),
    "reward_split": ("per_agent", "total"),
    "marginal_gain": ("rescore", "frozen"),
    "cbba_table": ("canonical", "thesis"),
    "release_order": ("bundle", "path"),
    "reset_on": ("additions", "any_change"),
    "quit_block": ("until_joined", "none"),
    "consensus": ("sync", "every_step", "acbba"),
    "outbid_ties": ("strict", "higher_id"),
    "reward_time": ("arrival", "start"),
    "loss_model": ("independent", "gilbert_elliott"),
    "popup_arrivals": ("periodic", "poisson"),
    "termination": ("auto", "global", "local"),
    "acbba_row11": ("update", "trust_later"),
    "acbba_equal_bids": ("leave", "trust_later"),
    "acbba_outbid_time": ("bump", "sender"),
    "acbba_row15": ("leave_bump", "leave", "empty"),
    "acbba_time_refresh": ("epsilon", "now"),
    "acbba_ties": ("lowest_id", "higher_id"),
}


@dataclasses.dataclass(frozen=True)
class TaskMix:
    """``count`` tasks needing ``agents`` agents and the equipment multiset ``equipment`` (thesis §3.1.3).

    With equipment, a task needs one agent per equipment item (|te_j| = L_j, thesis §3.1.3); ``agents`` alone gives
    tasks any agent may join.
    """

    count: int
    agents: int | None = None
    equipment: tuple[str, ...] = ()

    @property
    def required_agents(self) -> int:
        return self.agents if self.agents is not None else max(1, len(self.equipment))


@dataclasses.dataclass(frozen=True)
class PrerequisiteChains:
    """``chains`` prerequisite chains of ``length`` tasks each (E3.15: T → B → C, thesis §3.3.4, Figs 3.25–3.26).

    ``followup_window=False`` gives follow-up tasks no time requirement (E3.15 Exp3): their window stays open until
    the end of the horizon.
    """

    chains: int
    length: int = 3
    followup_window: bool = True


@dataclasses.dataclass(frozen=True)
class TaskAllocConfig:
    """All settings of one task-allocation environment. Defaults: thesis §3.3.2's test scenario, E5.10's L_j = 4."""

    # -- scenario generation (thesis §3.3.2) --
    n_agents: int = 10
    n_tasks: int = 20
    agents_per_task: int | tuple[int, ...] = 4
    arena: tuple[float, float, float] = (5.0, 5.0, 2.0)
    speed: float = 20.0
    units: str = "km_min"
    reward: float = 100.0
    time_discount: float = 0.8
    distance_discount: float = 0.8
    window: float = 5.0
    duration: float = 5.0
    start_time_range: tuple[float, float] = (0.0, 100.0)
    agent_types: tuple[str, ...] | None = None
    agent_type_counts: tuple[int, ...] | None = None
    task_mix: tuple[TaskMix, ...] | None = None
    prerequisites: PrerequisiteChains | None = None
    comm_range: float | None = None
    edge_rule: str = "dist"
    # -- scoring (thesis §3.2.2, §5.3.1; docs/decisions.md) --
    distance_cost: str = "leg"
    prereq_timing: str = "conservative"
    reward_split: str = "per_agent"
    conflict_policy: str = "first_L_paid"
    marginal_gain: str = "rescore"
    reward_time: str = "arrival"
    # -- protocol (thesis §3.2, §4.2, §5.2; Johnson §3.4.1) --
    cbba_table: str = "canonical"
    prereq_mode: str = "all_have_bid"
    release_order: str = "bundle"
    require_known_capacity: bool = False
    task_quitting: bool = False
    delta: int = 1
    reset_on: str = "additions"
    quit_block: str = "until_joined"
    consensus: str = "sync"
    outbid_ties: str = "strict"
    bid_warping: bool = True
    max_bundle: int | None = None
    max_rounds: int | None = None
    # -- the network (network.Network; faults are ours: the sources assume every message arrives) --
    message_loss: float = 0.0
    loss_model: str = "independent"
    burst_enter: float = 0.05
    burst_leave: float = 0.5
    burst_loss: float = 1.0
    max_delay: int = 0
    dropouts: int = 0
    dropout_rounds: tuple[int, int] = (1, 10)
    dropout_schedule: tuple[tuple[int, int], ...] | None = None
    silence_timeout: int | None = None
    # -- pop-up tasks (Johnson §4.1.3, Figs 4-3/4-4): the last popup_tasks task ids appear during the episode --
    popup_tasks: int = 0
    popup_period: int = 200
    popup_arrivals: str = "periodic"
    popup_times: tuple[int, ...] | None = None
    mission_time_per_tick: float = 0.0
    # -- the asynchronous consensus, consensus = "acbba" (Johnson §4.1; times in ticks) --
    message_ticks: tuple[float, float] = (0.0, 0.2)
    build_ticks: tuple[int, int] = (1, 3)
    separation_time: int = 25
    termination: str = "auto"
    confirmations: int | None = None
    acbba_row11: str = "update"
    acbba_equal_bids: str = "trust_later"
    acbba_outbid_time: str = "sender"
    acbba_row15: str = "leave_bump"
    acbba_row20_guard: bool = True
    acbba_row28_guard: bool = True
    acbba_time_refresh: str = "epsilon"
    acbba_ties: str = "lowest_id"
    # -- observations (the learning interface; not in the sources) --
    team_features: bool = False

    def __post_init__(self) -> None:
        _validate(self)

    def replace(self, **overrides: Any) -> TaskAllocConfig:
        """A copy with ``overrides`` applied; values are normalised and validated like YAML values."""
        return from_mapping({**to_mapping(self), **overrides})

    @property
    def faulty(self) -> bool:
        """Whether messages can be lost or delayed, or agents fail (the network is not perfect)."""
        return (self.message_loss > 0 or self.loss_model == "gilbert_elliott" or self.max_delay > 0
                or self.dropouts > 0 or bool(self.dropout_schedule))

    @property
    def asynchronous(self) -> bool:
        """The asynchronous consensus (ACBBA): one env step is one tick of a global clock."""
        return self.consensus == "acbba"

    @property
    def stochastic(self) -> bool:
        """Whether the protocol draws random numbers: network faults, Poisson pop-up arrivals, or processing times
        drawn from a range (the environment then hands it a generator spawned from its seeded one)."""
        poisson = self.popup_tasks > 0 and self.popup_times is None and self.popup_arrivals == "poisson"
        spread = self.asynchronous and (self.message_ticks[0] < self.message_ticks[1]
                                        or self.build_ticks[0] < self.build_ticks[1])
        return self.faulty or poisson or spread

    @property
    def local_termination(self) -> bool:
        """The asynchronous episode ends at local convergence (separation time) rather than at network quiet:
        ``termination="local"``, or ``auto`` with pop-up tasks (Johnson §4.1.3: with pop-ups "it does not make sense
        to define the idea of global convergence")."""
        return self.termination == "local" or (self.termination == "auto" and self.popup_tasks > 0)

    @property
    def confirmation_count(self) -> int:
        """Full-state announcements an asynchronous agent makes before it declares local convergence:
        ``confirmations``, or (None) 2 when messages can be lost and 0 otherwise (our rule, docs/decisions.md)."""
        if self.confirmations is not None:
            return self.confirmations
        return 2 if self.message_loss > 0 or self.loss_model == "gilbert_elliott" else 0

    @property
    def speed_internal(self) -> float:
        """Speed in arena units per time unit: 20 m/s = 1.2 km/min under ``units=km_min`` (our unit reading)."""
        return self.speed * 0.06 if self.units == "km_min" else self.speed

    @property
    def equipment_names(self) -> tuple[str, ...]:
        """Equipment universe E in first-seen order (agent types first, then task requirements)."""
        names: list[str] = list(self.agent_types or ())
        for mix in self.task_mix or ():
            names += [e for e in mix.equipment if e not in names]
        return tuple(names)


_FIELDS = {f.name: f for f in dataclasses.fields(TaskAllocConfig)}
# the three groups of fields (the class docstring): what generates an instance, how it is scored, how agents agree
GENERATION_FIELDS = ("n_agents", "n_tasks", "agents_per_task", "arena", "speed", "units", "reward", "time_discount",
                     "distance_discount", "window", "duration", "start_time_range", "agent_types", "agent_type_counts",
                     "task_mix", "prerequisites")
SCORING_FIELDS = ("distance_cost", "prereq_timing", "reward_split", "conflict_policy", "marginal_gain", "reward_time")
PROTOCOL_FIELDS = tuple(name for name in _FIELDS if name not in GENERATION_FIELDS + SCORING_FIELDS)


def _fail(field: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"config field {field!r}: got {value!r}; allowed: {allowed}")


def _check_positive_int(name: str, value: Any, minimum: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        _fail(name, value, f"an integer >= {minimum}")


def _check_number(name: str, value: Any, minimum: float = 0.0, strict: bool = False) -> None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if ok:
        ok = (value > minimum if strict else value >= minimum) and abs(value) <= MAX_MAGNITUDE
    if not ok:
        low = "" if minimum == -math.inf else f"{'>' if strict else '>='} {minimum} and "
        _fail(name, value, f"a number {low}within ±{MAX_MAGNITUDE:g}")


def _validate(cfg: TaskAllocConfig) -> None:
    _check_positive_int("n_agents", cfg.n_agents)
    _check_positive_int("n_tasks", cfg.n_tasks)
    apt = cfg.agents_per_task if isinstance(cfg.agents_per_task, tuple) else (cfg.agents_per_task,)
    if not apt:
        _fail("agents_per_task", cfg.agents_per_task, "an integer >= 1 or a non-empty list of them")
    for value in apt:
        _check_positive_int("agents_per_task", value)
    if cfg.task_mix is None and max(apt) > cfg.n_agents:
        which = "no task" if min(apt) > cfg.n_agents else f"no task needing more than {cfg.n_agents} agents"
        warnings.warn(f"agents_per_task {cfg.agents_per_task} with n_agents = {cfg.n_agents}: {which} can ever be "
                      "completed (such tasks are never biddable)", stacklevel=4)
    if len(cfg.arena) != 3:
        _fail("arena", cfg.arena, "three sizes [W, W, H]")
    for size in cfg.arena:
        _check_number("arena", size, strict=True)
    for name in ("speed", "reward", "window"):
        _check_number(name, getattr(cfg, name), strict=True)
    for name in ("time_discount", "distance_discount", "duration"):
        _check_number(name, getattr(cfg, name))
    if len(cfg.start_time_range) != 2:
        _fail("start_time_range", cfg.start_time_range, "two times [earliest, latest]")
    lo, hi = cfg.start_time_range
    _check_number("start_time_range", lo, minimum=-math.inf)
    _check_number("start_time_range", hi, minimum=lo)
    for name, allowed in CHOICES.items():
        if getattr(cfg, name) not in allowed:
            _fail(name, getattr(cfg, name), " | ".join(allowed))
    if cfg.comm_range is not None:
        _check_number("comm_range", cfg.comm_range)
    if cfg.max_bundle is not None:
        _check_positive_int("max_bundle", cfg.max_bundle)
    if cfg.max_rounds is not None:
        _check_positive_int("max_rounds", cfg.max_rounds)
    for name in ("require_known_capacity", "task_quitting", "bid_warping", "acbba_row20_guard", "acbba_row28_guard",
                 "team_features"):
        if not isinstance(getattr(cfg, name), bool):
            _fail(name, getattr(cfg, name), "true | false")
    _check_positive_int("delta", cfg.delta, minimum=0)
    for name in ("message_loss", "burst_enter", "burst_leave", "burst_loss"):
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
            _fail(name, value, "a probability in [0, 1]")
    _check_positive_int("max_delay", cfg.max_delay, minimum=0)
    _check_positive_int("dropouts", cfg.dropouts, minimum=0)
    if cfg.dropouts >= cfg.n_agents:
        _fail("dropouts", cfg.dropouts, f"fewer than n_agents = {cfg.n_agents} (one agent must stay)")
    if len(cfg.dropout_rounds) != 2:
        _fail("dropout_rounds", cfg.dropout_rounds, "two rounds [earliest, latest]")
    _check_positive_int("dropout_rounds", cfg.dropout_rounds[0])
    _check_positive_int("dropout_rounds", cfg.dropout_rounds[1], minimum=cfg.dropout_rounds[0])
    if cfg.dropout_schedule is not None:
        if cfg.dropouts:
            _fail("dropout_schedule", cfg.dropout_schedule, "null when dropouts > 0 (one or the other)")
        for entry in cfg.dropout_schedule:
            if not (isinstance(entry, tuple) and len(entry) == 2):
                _fail("dropout_schedule", cfg.dropout_schedule, "a list of [agent, round] pairs")
            _check_positive_int("dropout_schedule", entry[0], minimum=0)
            _check_positive_int("dropout_schedule", entry[1])
            if entry[0] >= cfg.n_agents:
                _fail("dropout_schedule", entry, f"an agent id below n_agents = {cfg.n_agents}")
        if len({a for a, _ in cfg.dropout_schedule}) != len(cfg.dropout_schedule):
            _fail("dropout_schedule", cfg.dropout_schedule, "each agent at most once")
    if cfg.silence_timeout is not None:
        _check_positive_int("silence_timeout", cfg.silence_timeout)
    _check_popups(cfg)
    _check_asynchronous(cfg)
    if cfg.agent_types is not None and (
            not cfg.agent_types or len(set(cfg.agent_types)) != len(cfg.agent_types)
            or not all(isinstance(t, str) and t for t in cfg.agent_types)):
        _fail("agent_types", cfg.agent_types, "null or a list of distinct type names")
    if cfg.agent_type_counts is not None:
        if cfg.agent_types is None or len(cfg.agent_type_counts) != len(cfg.agent_types):
            _fail("agent_type_counts", cfg.agent_type_counts, "one count per entry of agent_types")
        for count in cfg.agent_type_counts:
            _check_positive_int("agent_type_counts", count, minimum=0)
        if sum(cfg.agent_type_counts) != cfg.n_agents:
            _fail("agent_type_counts", cfg.agent_type_counts,
                  f"counts summing to n_agents = {cfg.n_agents} (got {sum(cfg.agent_type_counts)})")
    if cfg.task_mix is not None:
        for mix in cfg.task_mix:
            _check_positive_int("task_mix.count", mix.count, minimum=0)
            if mix.agents is not None:
                _check_positive_int("task_mix.agents", mix.agents)
            if mix.equipment and mix.agents is not None and mix.agents != len(mix.equipment):
                _fail("task_mix.agents", mix.agents,
                      f"the number of equipment items {len(mix.equipment)} (|te_j| = L_j, thesis §3.1.3), "
                      "or leave agents out")
            known = set(cfg.agent_types or ())
            for item in mix.equipment:
                if item not in known:
                    _fail("task_mix.equipment", item, f"a type listed in agent_types: {sorted(known) or 'none'}")
        total = sum(mix.count for mix in cfg.task_mix)
        if total != cfg.n_tasks:
            _fail("task_mix", [dataclasses.asdict(m) for m in cfg.task_mix],
                  f"counts summing to n_tasks = {cfg.n_tasks} (got {total})")
    if cfg.prerequisites is not None:
        chains = cfg.prerequisites
        _check_positive_int("prerequisites.chains", chains.chains)
        _check_positive_int("prerequisites.length", chains.length, minimum=2)
        if not isinstance(chains.followup_window, bool):
            _fail("prerequisites.followup_window", chains.followup_window, "true | false")
        if chains.chains * chains.length > cfg.n_tasks:
            _fail("prerequisites", dataclasses.asdict(chains),
                  f"chains * length <= n_tasks = {cfg.n_tasks}")


def _check_popups(cfg: TaskAllocConfig) -> None:
    _check_positive_int("popup_tasks", cfg.popup_tasks, minimum=0)
    if cfg.popup_tasks > cfg.n_tasks:
        _fail("popup_tasks", cfg.popup_tasks, f"at most n_tasks = {cfg.n_tasks}")
    _check_positive_int("popup_period", cfg.popup_period)
    if cfg.popup_times is not None:
        if len(cfg.popup_times) != cfg.popup_tasks:
            _fail("popup_times", cfg.popup_times, f"one release tick per pop-up task (popup_tasks = {cfg.popup_tasks})")
        for tick in cfg.popup_times:
            _check_positive_int("popup_times", tick, minimum=0)
    _check_number("mission_time_per_tick", cfg.mission_time_per_tick)


def _check_asynchronous(cfg: TaskAllocConfig) -> None:
    for name in ("message_ticks", "build_ticks"):
        pair = getattr(cfg, name)
        if len(pair) != 2:
            _fail(name, pair, "two tick counts [fewest, most]")
    for bound in cfg.message_ticks:
        _check_number("message_ticks", bound)
    for bound in cfg.build_ticks:
        _check_positive_int("build_ticks", bound, minimum=0)
    for name in ("message_ticks", "build_ticks"):             # a range of processing times (Johnson §4.1.1)
        low, high = getattr(cfg, name)
        if high < low:
            _fail(name, (low, high), "[fewest, most] with the upper bound >= the lower bound")
    _check_positive_int("separation_time", cfg.separation_time)
    if cfg.confirmations is not None:
        _check_positive_int("confirmations", cfg.confirmations, minimum=0)
    if cfg.asynchronous and cfg.n_agents > stamps.MAX_AGENTS:
        _fail("n_agents", cfg.n_agents, f"at most {stamps.MAX_AGENTS} with consensus acbba (timestamp stamper ids)")
    if cfg.asynchronous and cfg.max_rounds is not None and cfg.max_rounds > stamps.MAX_TICKS:
        _fail("max_rounds", cfg.max_rounds, f"at most {stamps.MAX_TICKS} ticks with consensus acbba")


def _as_tuple(name: str, value: Any) -> tuple:
    if isinstance(value, (list, tuple)):
        return tuple(value)
    _fail(name, value, "a list")
    raise AssertionError  # unreachable


def _check_record(name: str, entry: Any, keys: tuple[str, ...], required: str) -> None:
    """A nested record (a ``task_mix`` entry, ``prerequisites``) is a mapping of known keys with ``required`` set."""
    if not isinstance(entry, Mapping):
        _fail(name, entry, f"a mapping with keys {', '.join(keys)}")
    unknown = set(entry) - set(keys)
    if unknown:
        _fail(f"{name}.{sorted(unknown)[0]}", entry, f"keys {', '.join(keys)}")
    if required not in entry:
        _fail(f"{name}.{required}", entry, f"{required} is required")


def _normalise(name: str, value: Any) -> Any:
    """Turn YAML/keyword values into the dataclass field types (lists → tuples, mappings → records)."""
    if name == "agents_per_task" and isinstance(value, (list, tuple)):
        return tuple(value)
    if name in ("arena", "start_time_range"):
        return tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                     for v in _as_tuple(name, value))
    if name in ("agent_types", "agent_type_counts") and value is not None:
        return _as_tuple(name, value)
    if name in ("dropout_rounds", "build_ticks"):
        return _as_tuple(name, value)
    if name == "message_ticks":
        return tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in _as_tuple(name, value))
    if name == "popup_times" and value is not None:
        return _as_tuple(name, value)
    if name == "dropout_schedule" and value is not None:
        return tuple(tuple(entry) if isinstance(entry, (list, tuple)) else entry for entry in _as_tuple(name, value))
    if name == "task_mix" and value is not None:
        mixes = []
        for entry in _as_tuple(name, value):
            if isinstance(entry, TaskMix):
                mixes.append(entry)
                continue
            _check_record(name, entry, ("count", "agents", "equipment"), required="count")
            equipment = entry.get("equipment", ())
            if not isinstance(equipment, (str, list, tuple)) or not all(isinstance(e, str) for e in equipment):
                _fail("task_mix.equipment", equipment, "a list of type names, or a string of one-letter names")
            equipment = tuple(equipment)  # "AB" and ["A", "B"] both name two items
            mixes.append(TaskMix(count=entry["count"], agents=entry.get("agents"), equipment=equipment))
        return tuple(mixes)
    if name == "prerequisites" and value is not None:
        if isinstance(value, PrerequisiteChains):
            return value
        _check_record(name, value, ("chains", "length", "followup_window"), required="chains")
        return PrerequisiteChains(**value)
    if name in ("speed", "reward", "time_discount", "distance_discount", "window", "duration", "comm_range",
                "message_loss", "burst_enter", "burst_leave", "burst_loss", "mission_time_per_tick") \
            and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def from_mapping(values: Mapping[str, Any]) -> TaskAllocConfig:
    """Build a config from a flat mapping (YAML contents plus overrides); unknown keys are errors."""
    unknown = sorted(set(values) - set(_FIELDS))
    if unknown:
        raise ConfigError(f"unknown config field(s) {unknown}; known fields: {sorted(_FIELDS)}")
    kwargs = {name: _normalise(name, value) for name, value in values.items()}
    return TaskAllocConfig(**kwargs)


def to_mapping(cfg: TaskAllocConfig) -> dict[str, Any]:
    """The flat mapping that ``from_mapping`` reads back (nested records as plain mappings)."""
    out: dict[str, Any] = {}
    for name in _FIELDS:
        value = getattr(cfg, name)
        if name == "task_mix" and value is not None:
            value = [{k: v for k, v in dataclasses.asdict(m).items() if v is not None} for m in value]
            for entry in value:
                entry["equipment"] = list(entry.get("equipment", ()))
        elif name == "prerequisites" and value is not None:
            value = dataclasses.asdict(value)
        elif isinstance(value, tuple):
            value = [list(v) if isinstance(v, tuple) else v for v in value]
        out[name] = value
    return out


def type_counts(cfg: TaskAllocConfig) -> tuple[int, ...]:
    """Agents per type: ``agent_type_counts``, or an even split with extras to the first types (E3.14)."""
    if cfg.agent_type_counts is not None:
        return cfg.agent_type_counts
    types: Sequence[str] = cfg.agent_types or ()
    base, extra = divmod(cfg.n_agents, len(types))
    return tuple(base + (1 if i < extra else 0) for i in range(len(types)))


def read_yaml(source: Path | resources.Traversable, what: str = "config file") -> Any:
    """Parse a YAML file; every way it can fail becomes one ``ConfigError`` naming the file (and the line)."""
    data = resources.read_bounded(source, MAX_FILE_BYTES, what)    # size from stat, refused unread
    try:
        return yaml.safe_load(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} {str(source)!r} is not UTF-8 text (byte {exc.start})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}:" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"{what} {str(source)!r} is not valid YAML:{where} {problem}") from None
    except RecursionError:
        raise ConfigError(f"{what} {str(source)!r} nests too deeply to be a config file") from None


def scenario_source(scenario: str | Path) -> Path | resources.Traversable:
    """A scenario name (``default``: a file of ``configs/scenarios``) or a path to a YAML file.

    A ``Path``, or a string with a folder or a ``.yaml``/``.yml`` suffix, is a path; any other string must be a
    bare name, so a name can never reach a file outside the scenario folder.
    """
    if isinstance(scenario, Path) or (isinstance(scenario, str) and not resources.is_name(scenario)
                                      and Path(scenario).suffix in (".yaml", ".yml")):
        path = Path(scenario)
        if not path.exists():
            raise ConfigError(f"scenario file {str(path)!r} does not exist")
        return path
    if not isinstance(scenario, str):
        raise ConfigError(f"scenario: got {scenario!r} ({type(scenario).__name__}); allowed: a scenario name, a path "
                          "to a .yaml file, a TaskAllocConfig, a mapping of config fields, or a Scenario")
    return resources.named("scenarios", scenario)


def load_config(name: str | Path = "default", **overrides: Any) -> TaskAllocConfig:
    """Read a scenario YAML (by name from ``configs/scenarios`` or by path) and apply keyword overrides."""
    source = scenario_source(name)
    data = read_yaml(source, "scenario file")
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"scenario file {str(source)!r} must hold a mapping of config fields, "
                          f"got {type(data).__name__}")
    unknown = sorted(map(str, set(data) - set(_FIELDS)))
    if unknown:
        raise ConfigError(f"scenario file {str(source)!r}: unknown config field(s) {unknown}; known fields: "
                          f"{sorted(_FIELDS)}")
    return from_mapping({**data, **overrides})


def resolve_config(scenario: str | Path | TaskAllocConfig | Mapping[str, Any] = "default",
                   **overrides: Any) -> TaskAllocConfig:
    """Accept a scenario name, a YAML path, a config object or a mapping, then apply ``overrides``."""
    if isinstance(scenario, TaskAllocConfig):
        return scenario.replace(**overrides) if overrides else scenario
    if isinstance(scenario, Mapping):
        return from_mapping({**scenario, **overrides})
    return load_config(scenario, **overrides)


def max_required_agents(cfg: TaskAllocConfig) -> int:
    """The largest L_j any instance of ``cfg`` can have."""
    if cfg.task_mix:
        return max(mix.required_agents for mix in cfg.task_mix)
    apt = cfg.agents_per_task
    return max(apt) if isinstance(apt, tuple) else apt


def round_bound(n_tasks: int, n_agents: int, max_agents_per_task: int, diameter: int) -> int:
    """T_max = 10 · max(N_m, N_n · max L_j) · D rounds (our choice; the thesis gives no bound for CBGA)."""
    return 10 * max(n_tasks, n_agents * max_agents_per_task) * max(1, diameter)


def release_horizon(cfg: TaskAllocConfig) -> int:
    """The latest tick (round) at which a pop-up task can be released: the last of ``popup_times``, or
    ``popup_tasks`` · ``popup_period`` (the last periodic release; Poisson arrivals are drawn within it)."""
    if cfg.popup_times:
        return max(cfg.popup_times)
    return cfg.popup_tasks * cfg.popup_period


def episode_bound(cfg: TaskAllocConfig, n_tasks: int, n_agents: int, max_agents_per_task: int, diameter: int) -> int:
    """T_max of an episode: ``max_rounds``, or the round bound after the last release. With ``consensus="acbba"``
    the bound is in ticks: a round of the bound is stretched to 2 + ``max_delay`` + the slowest build + N_n times
    the slowest message time (our choice: a bid crosses a hop in at most that many ticks, plus the session tick)."""
    if cfg.max_rounds:
        return cfg.max_rounds
    bound = round_bound(n_tasks, n_agents, max_agents_per_task, diameter)
    if cfg.asynchronous:
        bound *= 2 + cfg.max_delay + cfg.build_ticks[1] + math.ceil(n_agents * cfg.message_ticks[1])
    bound += release_horizon(cfg)
    return min(bound, stamps.MAX_TICKS) if cfg.asynchronous else bound
