"""Configuration of a task-allocation problem and of the consensus protocol that solves it.

One flat, frozen :class:`TaskAllocConfig` (``parallel_env(n_agents=5, message_loss=0.2)``) whose fields come from the
facts of ``taskalloc_env/options/`` (``fields.Field``: kind, bounds, choices, default, meaning, source), grouped by
concern: scenario generation, scoring, protocol, network, pop-up tasks, the asynchronous consensus and observations.
The validation is generated from the facts plus the rules between fields (``config_rules``); the fuzzer's option
values and the tables of docs/configuration.md come from the same facts. The named options mark points the sources
leave open or state in more than one way; docs/decisions.md gives the reasons for the defaults. Configs come from YAML
files in ``configs/scenarios/`` (``load_config``) and keyword overrides (``TaskAllocConfig.replace``); unknown keys
(with the closest known name) and bad values raise :class:`ConfigError` naming the field and the allowed values.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from taskalloc_env import config_rules as rules
from taskalloc_env import resources, stamps
from taskalloc_env.config_rules import check_fields
from taskalloc_env.errors import ConfigError
from taskalloc_env.faults import LOSS_MODELS
from taskalloc_env.fields import MAX_MAGNITUDE, Field, bounded_repr, did_you_mean
from taskalloc_env.options.asynchronous import ASYNC_GROUP
from taskalloc_env.options.generation import GENERATION_GROUP, PrerequisiteChains, TaskMix
from taskalloc_env.options.network import NETWORK_GROUP
from taskalloc_env.options.observation import OBSERVATION_GROUP
from taskalloc_env.options.popups import POPUP_GROUP
from taskalloc_env.options.protocol import PROTOCOL_GROUP
from taskalloc_env.options.scoring import SCORING_GROUP

MAX_FILE_BYTES = 1 << 20       # config files are a few hundred bytes; anything beyond 1 MiB is refused unread
__all__ = ["MAX_MAGNITUDE", "PrerequisiteChains", "TaskAllocConfig", "TaskMix", "bounded_repr"]


FIELD_GROUPS: dict[str, tuple[Field, ...]] = {
    "generation": GENERATION_GROUP, "scoring": SCORING_GROUP, "protocol": PROTOCOL_GROUP, "network": NETWORK_GROUP,
    "popups": POPUP_GROUP, "asynchronous": ASYNC_GROUP, "observation": OBSERVATION_GROUP}
FACTS: dict[str, Field] = {f.name: f for group in FIELD_GROUPS.values() for f in group}
# the allowed values of every named option (the facts' choices)
CHOICES: dict[str, tuple[str, ...]] = {f.name: f.choices for f in FACTS.values() if f.kind == "choice"}


class _ConfigBehaviour:
    """What ``TaskAllocConfig`` derives from its fields (the fields themselves come from ``FACTS``)."""

    def __post_init__(self) -> None:
        check_fields(self, tuple(FACTS.values()))

    def replace(self, **overrides: Any) -> TaskAllocConfig:
        """A copy with ``overrides`` applied; values are normalised and validated like YAML values."""
        return from_mapping({**to_mapping(self), **overrides})

    @property
    def loses_messages(self) -> bool:
        """Whether the loss model can lose a message (it answers for itself, ``network.LOSS_MODELS``)."""
        return LOSS_MODELS[self.loss_model].loses_messages(self)

    @property
    def faulty(self) -> bool:
        """Whether messages can be lost or delayed, or agents fail (the network is not perfect)."""
        return self.loses_messages or self.max_delay > 0 or self.dropouts > 0 or bool(self.dropout_schedule)

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
        return 2 if self.loses_messages else 0

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



TaskAllocConfig = dataclasses.make_dataclass(
    "TaskAllocConfig", [(f.name, Any, dataclasses.field(default=f.default)) for f in FACTS.values()],
    bases=(_ConfigBehaviour,), frozen=True)
TaskAllocConfig.__module__ = __name__
TaskAllocConfig.__doc__ = ("All settings of one task-allocation environment, one field per fact of ``FACTS`` "
                           "(docs/configuration.md). Defaults: thesis §3.3.2's test scenario, E5.10's L_j = 4.")

# the groups as the rest of the code names them: what generates an instance, how it is scored, how agents agree
GENERATION_FIELDS = tuple(f.name for f in GENERATION_GROUP)
SCORING_FIELDS = tuple(f.name for f in SCORING_GROUP)
PROTOCOL_FIELDS = tuple(name for name in FACTS if name not in GENERATION_FIELDS + SCORING_FIELDS)


def _normalise(name: str, value: Any) -> Any:
    """Turn YAML/keyword values into the field types (lists → tuples, mappings → records, integers → floats)."""
    kind = FACTS[name].kind
    if value is None:
        return value
    if name == "task_mix":
        return rules.task_mix(value)
    if name == "prerequisites":
        return rules.prerequisites(value)
    if name == "dropout_schedule":
        return tuple(tuple(e) if isinstance(e, (list, tuple)) else e for e in rules.as_tuple(name, value))
    if name == "join_at":
        return rules.join_pairs(value)
    if kind in ("ints", "names") and (isinstance(value, (list, tuple)) or not FACTS[name].scalar):
        return rules.as_tuple(name, value)
    if kind == "numbers":
        return tuple(rules.as_float(v) for v in rules.as_tuple(name, value))
    if kind in ("number", "probability"):
        return rules.as_float(value)
    return value


def from_mapping(values: Mapping[str, Any]) -> TaskAllocConfig:
    """Build a config from a flat mapping (YAML contents plus overrides); unknown keys are errors."""
    unknown = sorted(map(str, set(values) - set(FACTS)))
    if unknown:
        raise ConfigError(did_you_mean(unknown, list(FACTS)))
    kwargs = {name: _normalise(name, value) for name, value in values.items()}
    return TaskAllocConfig(**kwargs)


def to_mapping(cfg: TaskAllocConfig) -> dict[str, Any]:
    """The flat mapping that ``from_mapping`` reads back (nested records as plain mappings)."""
    out: dict[str, Any] = {}
    for name in FACTS:
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
    unknown = sorted(map(str, set(data) - set(FACTS)))
    if unknown:
        raise ConfigError(did_you_mean(unknown, list(FACTS), where=f"scenario file {str(source)!r}: "))
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
