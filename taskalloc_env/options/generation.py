"""Scenario generation (thesis §3.3.2, §3.3.4, §5.3.1): what draws an instance. Read by ``scenario.generate``
and the generators registered there."""

from __future__ import annotations

import dataclasses

from taskalloc_env.fields import MAX_COUNT, Field, group


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


GENERATION_GROUP = group("generation", (
    Field('n_agents', 'int', low=1, high=MAX_COUNT, default=10,
          meaning='N_n',
          source='thesis §3.3.2, §5.3.1'),
    Field('n_tasks', 'int', low=1, high=MAX_COUNT, default=20,
          meaning='N_m',
          source='thesis §3.3.2'),
    Field('agents_per_task', 'ints', low=1, high=MAX_COUNT, scalar=True, default=4,
          meaning='L_j: one value, or a list to draw from uniformly per task',
          source='thesis §3.1.2; 4 as in Fig 5.16'),
    Field('arena', 'numbers', shape='three sizes [W, W, H]', low=0, strict=True, length=3, default=(5.0, 5.0, 2.0),
          meaning='W × W × H; agents start on the floor (z = 0), tasks anywhere',
          source='thesis §3.3.2'),
    Field('speed', 'number', low=0, strict=True, default=20.0,
          meaning='m/s under `units=km_min` (1.2 km/min), arena units per time unit under `raw`',
          source='thesis §3.3.2'),
    Field('units', 'choice', choices=('km_min', 'raw'), default='km_min',
          meaning=('`km_min` (distances in km, times in minutes, λ per minute, γ per km: our reading, since the '
                   'thesis gives no unit for λ, γ or the "5m" windows) \\| `raw`'),
          source='choice'),
    Field('reward', 'number', low=0, strict=True, default=100.0,
          meaning='c̄_j, paid to every member of a valid task',
          source='thesis §3.2.2, §3.3.2'),
    Field('time_discount', 'number', low=0, default=0.8,
          meaning='λ in c̄ e^{−λ(τ − start_j)}',
          source='thesis (3.8), §3.3.2'),
    Field('distance_discount', 'number', low=0, default=0.8,
          meaning='γ, cost per unit distance',
          source='thesis (3.9), §3.3.2'),
    Field('window', 'number', low=0, strict=True, default=5.0,
          meaning='minutes in which a task must be started (end = start + window)',
          source='thesis §3.3.2, (3.7)'),
    Field('duration', 'number', low=0, default=5.0,
          meaning='minutes a task takes',
          source='thesis §3.3.2'),
    Field('start_time_range', 'numbers', shape='two times [earliest, latest]', length=2, default=(0.0, 100.0),
          meaning=('start_j ~ U(a, b); the thesis says only "random" (the range is the public MIT CBBA code\'s)'),
          source='choice'),
    Field('agent_types', 'names', shape='null or a list of distinct type names', optional=True, default=None,
          meaning='equipment types, one per agent, split evenly with extras to the first types (E3.14)',
          source='thesis §3.1.3, §3.3.4'),
    Field('agent_type_counts', 'ints', low=0, high=MAX_COUNT, optional=True, default=None,
          meaning='explicit agents per type (must sum to `n_agents`)',
          source='thesis §3.3.4'),
    Field('task_mix', 'record', optional=True, default=None,
          meaning=('list of `{count, agents, equipment}`: te_j as a multiset; L_j = \\|te_j\\| unless `agents` is '
                   'given; counts sum to `n_tasks`'),
          source='thesis §3.1.3, (3.5); E3.12–E3.14'),
    Field('prerequisites', 'record', optional=True, default=None,
          meaning=('`{chains, length, followup_window}`: prerequisite chains T → B → C (E3.15); `followup_window: '
                   'false` leaves follow-ups without a deadline'),
          source='thesis §3.1.3, (3.6); E3.15'),
    Field('generator', 'name', default='uniform',
          meaning=('the scenario generator, by its name in `generators.GENERATORS` (`register_generator(name, fn)` '
                   'adds one): `uniform` draws positions, start times and L_j uniformly (below) \\| `visit`: the '
                   'collaborative visit, `n_agents` evenly along the floor\'s edge x = 0, `n_tasks` known targets '
                   'on the floor, open from time 0 with no deadline (`start_time_range`, `window` unused; no '
                   'equipment or prerequisites)'),
          source=('`uniform`: thesis §3.3.2 (the distribution is ours); `visit`: ours, after the collaborative visit '
                  'of Nayak et al., IEEE RA-L 2020, and the DCTA benchmark (4 robots on one edge, 10 targets); the '
                  'registry is ours')),
    Field('grid', 'bool', default=False,
          meaning=('`visit` only: agents and targets on integer cells of the floor, the targets on distinct cells '
                   'none of which is an agent\'s start (the DCTA benchmark\'s 19 × 19 grid is `arena: [18, 18, 1]`)'),
          source='ours, after the DCTA benchmark\'s grid'),
))
