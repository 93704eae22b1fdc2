"""The rules between config fields, and the nested records: what a field's own facts (``fields.Field``) cannot check.

Each field's kind and bounds are checked from its facts first (``check_fields``); the rules here relate fields to
each other (counts summing to ``n_agents``, a range's upper bound above its lower one, pop-up releases within the
horizon) and check the records ``task_mix``, ``prerequisites``, ``dropout_schedule`` and ``join_at``. Every failure
is one ``ConfigError`` naming the field, its value (bounded) and what is allowed.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

from taskalloc_env import stamps
from taskalloc_env.fields import MAX_COUNT, MAX_HORIZON, Field, fail
from taskalloc_env.generators import CHECKS, GENERATORS
from taskalloc_env.options.generation import PrerequisiteChains, TaskMix


def check_fields(cfg: Any, facts: Sequence[Field]) -> None:
    """Every field's kind and bounds (its facts), then the rules between fields."""
    for field in facts:
        field.check(getattr(cfg, field.name))
    _check_generation(cfg)
    _check_network(cfg)
    _check_joins(cfg)
    _check_popups(cfg)
    _check_asynchronous(cfg)
    _check_release(cfg)
    _check_generator(cfg)


def _int(name: str, value: Any, low: int = 1, high: int = MAX_COUNT) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        fail(name, value, f"an integer >= {low} and <= {high:g}")


def _check_generation(cfg: Any) -> None:
    apt = cfg.agents_per_task if isinstance(cfg.agents_per_task, (tuple, list)) else (cfg.agents_per_task,)
    if cfg.task_mix is None and max(apt) > cfg.n_agents:
        which = "no task" if min(apt) > cfg.n_agents else f"no task needing more than {cfg.n_agents} agents"
        warnings.warn(f"agents_per_task {cfg.agents_per_task} with n_agents = {cfg.n_agents}: {which} can ever be "
                      "completed (such tasks are never biddable)", stacklevel=5)
    lo, hi = cfg.start_time_range
    if hi < lo:
        fail("start_time_range", cfg.start_time_range, f"a number >= {lo} and within the range's ±1e+09")
    if cfg.agent_types is not None and len(set(cfg.agent_types)) != len(cfg.agent_types):
        fail("agent_types", cfg.agent_types, "null or a list of distinct type names")
    if cfg.agent_type_counts is not None:
        if cfg.agent_types is None or len(cfg.agent_type_counts) != len(cfg.agent_types):
            fail("agent_type_counts", cfg.agent_type_counts, "one count per entry of agent_types")
        if sum(cfg.agent_type_counts) != cfg.n_agents:
            fail("agent_type_counts", cfg.agent_type_counts,
                 f"counts summing to n_agents = {cfg.n_agents} (got {sum(cfg.agent_type_counts)})")
    if cfg.task_mix is not None:
        _check_task_mix(cfg)
    if cfg.prerequisites is not None:
        chains = cfg.prerequisites
        _int("prerequisites.chains", chains.chains)
        _int("prerequisites.length", chains.length, low=2)
        if not isinstance(chains.followup_window, bool):
            fail("prerequisites.followup_window", chains.followup_window, "true | false")
        if chains.chains * chains.length > cfg.n_tasks:
            fail("prerequisites", dataclasses.asdict(chains), f"chains * length <= n_tasks = {cfg.n_tasks}")


def _check_task_mix(cfg: Any) -> None:
    known = set(cfg.agent_types or ())
    for mix in cfg.task_mix:
        _int("task_mix.count", mix.count, low=0)
        if mix.agents is not None:
            _int("task_mix.agents", mix.agents)
        if mix.equipment and mix.agents is not None and mix.agents != len(mix.equipment):
            fail("task_mix.agents", mix.agents, f"the number of equipment items {len(mix.equipment)} (|te_j| = L_j, "
                 "thesis §3.1.3), or leave agents out")
        if len(mix.equipment) > MAX_COUNT:
            fail("task_mix.equipment", mix.equipment, f"at most {MAX_COUNT:g} items (the count limit)")
        for item in mix.equipment:
            if item not in known:
                fail("task_mix.equipment", item, f"a type listed in agent_types: {sorted(known) or 'none'}")
    total = sum(mix.count for mix in cfg.task_mix)
    if total != cfg.n_tasks:
        fail("task_mix", [dataclasses.asdict(m) for m in cfg.task_mix],
             f"counts summing to n_tasks = {cfg.n_tasks} (got {total})")


def _check_network(cfg: Any) -> None:
    if cfg.dropouts >= cfg.n_agents:
        fail("dropouts", cfg.dropouts, f"fewer than n_agents = {cfg.n_agents} (one agent must stay)")
    if cfg.dropout_rounds[1] < cfg.dropout_rounds[0]:
        fail("dropout_rounds", cfg.dropout_rounds, "[earliest, latest] with latest >= earliest")
    schedule = cfg.dropout_schedule
    if schedule is None:
        return
    if cfg.dropouts:
        fail("dropout_schedule", schedule, "null when dropouts > 0 (one or the other)")
    if not isinstance(schedule, (tuple, list)):
        fail("dropout_schedule", schedule, "a list of [agent, round] pairs")
    for entry in schedule:
        if not (isinstance(entry, tuple) and len(entry) == 2):
            fail("dropout_schedule", schedule, "a list of [agent, round] pairs")
        _int("dropout_schedule", entry[0], low=0)
        _int("dropout_schedule", entry[1], high=MAX_HORIZON)
        if entry[0] >= cfg.n_agents:
            fail("dropout_schedule", entry, f"an agent id below n_agents = {cfg.n_agents}")
    if len({a for a, _ in schedule}) != len(schedule):
        fail("dropout_schedule", schedule, "each agent at most once")
    if len(schedule) >= cfg.n_agents:
        fail("dropout_schedule", schedule, f"fewer failures than n_agents = {cfg.n_agents} (one agent must stay)")


def _check_joins(cfg: Any) -> None:
    """``join_at``: [agent, round] pairs of known agents, each once, rounds 1..the horizon limit, one agent present
    from the start; a scheduled failure of a joiner comes after its join."""
    joins = cfg.join_at
    if joins is None:
        return
    allowed = f"{{agent: round}} with agent ids 0..{cfg.n_agents - 1} and rounds 1..{MAX_HORIZON}"
    if not isinstance(joins, tuple) or not joins:
        fail("join_at", joins, allowed)
    for entry in joins:
        if not (isinstance(entry, tuple) and len(entry) == 2):
            fail("join_at", joins, allowed)
        agent, round_ = entry
        if isinstance(agent, bool) or not isinstance(agent, int) or not 0 <= agent < cfg.n_agents:
            fail("join_at", agent, f"an agent id 0..{cfg.n_agents - 1} (n_agents = {cfg.n_agents})")
        _int("join_at", round_, high=MAX_HORIZON)
    if len({a for a, _ in joins}) != len(joins):
        fail("join_at", joins, "each agent at most once")
    if len(joins) >= cfg.n_agents:
        fail("join_at", joins, f"fewer joiners than n_agents = {cfg.n_agents} (one agent present from the start)")
    joined = dict(joins)
    for agent, round_ in cfg.dropout_schedule or ():
        if agent in joined and round_ <= joined[agent]:
            fail("dropout_schedule", (agent, round_), f"a failure after agent {agent} joins (join_at round "
                 f"{joined[agent]})")


def _check_popups(cfg: Any) -> None:
    if cfg.popup_tasks > cfg.n_tasks:
        fail("popup_tasks", cfg.popup_tasks, f"at most n_tasks = {cfg.n_tasks}")
    if cfg.popup_times is not None and len(cfg.popup_times) != cfg.popup_tasks:
        fail("popup_times", cfg.popup_times, f"one release tick per pop-up task (popup_tasks = {cfg.popup_tasks})")
    if cfg.popup_times is None and cfg.popup_tasks * cfg.popup_period > MAX_HORIZON:
        fail("popup_period", cfg.popup_period, f"popup_tasks × popup_period <= {MAX_HORIZON} (the horizon limit: the "
             f"last release, got {cfg.popup_tasks} × {cfg.popup_period})")


def _check_asynchronous(cfg: Any) -> None:
    for name in ("message_ticks", "build_ticks"):             # a range of processing times (Johnson §4.1.1)
        low, high = getattr(cfg, name)
        if high < low:
            fail(name, (low, high), "[fewest, most] with the upper bound >= the lower bound")
    if cfg.asynchronous and cfg.n_agents > stamps.MAX_AGENTS:
        fail("n_agents", cfg.n_agents, f"at most {stamps.MAX_AGENTS} with consensus acbba (timestamp stamper ids)")


def _check_release(cfg: Any) -> None:
    if cfg.release_guard != "none" and not cfg.release_actions:
        fail("release_guard", cfg.release_guard, "release_actions = true (the guard restricts release actions)")


def _check_generator(cfg: Any) -> None:
    if cfg.generator not in GENERATORS:
        fail("generator", cfg.generator, f"a registered generator: {' | '.join(GENERATORS)} "
             "(register_generator adds one)")
    if cfg.generator in CHECKS:                     # the fields this family cannot honour (generators.CHECKS)
        CHECKS[cfg.generator](cfg)


# -- the nested records, from YAML mappings -----------------------------------------------------------------------
def _check_record(name: str, entry: Any, keys: tuple[str, ...], required: str) -> None:
    """A nested record (a ``task_mix`` entry, ``prerequisites``) is a mapping of known keys with ``required`` set."""
    if not isinstance(entry, Mapping):
        fail(name, entry, f"a mapping with keys {', '.join(keys)}")
    unknown = set(entry) - set(keys)
    if unknown:
        fail(f"{name}.{sorted(map(str, unknown))[0]}", entry, f"keys {', '.join(keys)}")
    if required not in entry:
        fail(f"{name}.{required}", entry, f"{required} is required")


def join_pairs(value: Any) -> tuple:
    """``join_at`` as (agent, round) pairs sorted by agent: from a mapping ``{agent: round}`` or a list of pairs."""
    if isinstance(value, Mapping):
        pairs = list(value.items())
    elif isinstance(value, (list, tuple)):
        pairs = [tuple(e) if isinstance(e, (list, tuple)) else e for e in value]
    else:
        fail("join_at", value, "a mapping {agent: round} or a list of [agent, round] pairs")
    if all(isinstance(p, tuple) and len(p) == 2 and isinstance(p[0], int) for p in pairs):
        pairs.sort()
    return tuple(pairs)


def as_tuple(name: str, value: Any) -> tuple:
    """A YAML list (or a tuple) as a tuple; anything else is refused."""
    if isinstance(value, (list, tuple)):
        return tuple(value)
    fail(name, value, "a list")
    raise AssertionError  # unreachable


def task_mix(value: Any) -> tuple[TaskMix, ...]:
    """``task_mix`` entries (mappings or ``TaskMix``) as records."""
    mixes = []
    for entry in as_tuple("task_mix", value):
        if isinstance(entry, TaskMix):
            mixes.append(entry)
            continue
        _check_record("task_mix", entry, ("count", "agents", "equipment"), required="count")
        equipment = entry.get("equipment", ())
        if not isinstance(equipment, (str, list, tuple)) or not all(isinstance(e, str) for e in equipment):
            fail("task_mix.equipment", equipment, "a list of type names, or a string of one-letter names")
        mixes.append(TaskMix(count=entry["count"], agents=entry.get("agents"), equipment=tuple(equipment)))
    return tuple(mixes)


def prerequisites(value: Any) -> PrerequisiteChains:
    """``prerequisites`` (a mapping or the record) as the record."""
    if isinstance(value, PrerequisiteChains):
        return value
    _check_record("prerequisites", value, ("chains", "length", "followup_window"), required="chains")
    return PrerequisiteChains(**value)


def as_float(value: Any) -> Any:
    """An integer as a float when it fits (a larger one stays, and its field's bounds refuse it)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) <= 2**53:
        return float(value)
    return value


def finite_positive(name: str, value: Any) -> None:
    """A limit such as ``memory_limit_gb``: a finite number > 0 (NaN would disable the check it sets)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < math.inf:
        fail(name, value, "a finite number > 0")
