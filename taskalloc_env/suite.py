"""The benchmark's task suite ``v0``: each task a registered id ``taskalloc/<Task>-v0`` (``parallel`` and ``aec``).

A task is a scenario (a base scenario of ``configs/scenarios`` plus field overrides, drawn by the named generator
its config selects), a fixed list of test seeds and, apart from them, validation seeds, and a card: what it tests
and which source it comes from (docs/benchmark.md prints the cards from this module). ``pettingzoo.make("parallel",
"taskalloc/Default-v0")`` builds the task's environment; ``reset(seed=s)`` for s in ``test_seeds`` draws its test
instances.

Versioning rule (ours): a task's id changes (``-v0`` → ``-v1``) whenever anything changes its instances or dynamics:
a field of its config, its seeds, the generator's draws, the protocol's rules or the scoring. Refactors that leave
every episode identical (``benchmarks/episode_digests.py``) keep the id.

Seeds (ours): test seeds ``50_000 …`` and validation seeds ``60_000 …`` are disjoint from each other and from the
project's other ranges (``taskalloc.evaluation.seeds``: held-out tests ``10_000 …``, training validation ``20_000 …``,
demonstrations ``100_000 …``, training copies from small seeds).
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping
from typing import Any

import pettingzoo

from taskalloc_env.config import TaskAllocConfig, load_config, to_mapping
from taskalloc_env.errors import ConfigError

SUITE = "v0"
TEST_SEED_START = 50_000
VALIDATION_SEED_START = 60_000
ENTRY_POINTS = {"parallel": "taskalloc_env.taskalloc_v0:parallel_env", "aec": "taskalloc_env.taskalloc_v0:env"}


@dataclasses.dataclass(frozen=True)
class SuiteTask:
    """One task of the suite: its scenario, seeds, normalising baseline, best-known solver and card."""

    name: str                                   # ``Default``: the id is ``taskalloc/Default-v0``
    scenario: str                               # base scenario of configs/scenarios
    overrides: Mapping[str, Any]                # config fields on top of it
    tests: str                                  # card: what the task tests
    source: str                                 # card: where its setting comes from
    episodes: int = 30                          # test seeds (validation seeds: as many)
    normaliser: str = "cbgabi"                  # the baseline whose mean score is 1
    best_known: str = "lns"                     # exact optimum or the LNS group search (a lower bound)

    @property
    def id(self) -> str:
        return f"taskalloc/{self.name}-{SUITE}"

    @property
    def test_seeds(self) -> tuple[int, ...]:
        return tuple(range(TEST_SEED_START, TEST_SEED_START + self.episodes))

    @property
    def validation_seeds(self) -> tuple[int, ...]:
        return tuple(range(VALIDATION_SEED_START, VALIDATION_SEED_START + self.episodes))

    def config(self) -> TaskAllocConfig:
        """The task's config: the base scenario with the overrides applied (validated like any config)."""
        return load_config(self.scenario, **self.overrides)


HETERO = {"agent_types": ["A", "B", "C"],
          "task_mix": [{"count": 8, "equipment": ["A"]}, {"count": 6, "equipment": ["A", "B"]},
                       {"count": 6, "equipment": ["A", "B", "C"]}],
          "prerequisites": {"chains": 5, "length": 3}}
JOHNSON_ASYNC = {"n_agents": 8, "n_tasks": 35, "agents_per_task": 1, "max_bundle": 5, "distance_cost": "from_start",
                 "marginal_gain": "frozen", "consensus": "acbba", "popup_tasks": 25, "popup_period": 50}
LADDER = ((6, 12), (8, 16), (12, 24), (16, 32))      # rungs above Small's 4 × 8, M = 2 N as in Small

_TASKS = [
    SuiteTask("Small", "train_small", {}, episodes=100, best_known="exact",
              tests="the training scenario: 4 agents, 8 tasks, L_j drawn from {1, 2}; small enough for the exact "
                    "optimum",
              source="thesis §3.3.2 test scenario (start times U(0, 40) min, ours, so agents chain tasks); the "
                     "first rung of the size ladder"),
    SuiteTask("Default", "default", {}, episodes=30,
              tests="the headline setting: 10 agents, 20 tasks, every task needs L_j = 4 agents",
              source="thesis §3.3.2 test scenario at the setting of §5.3.2, Fig 5.16 (E5.10); article Fig 7"),
    SuiteTask("Large", "default", {"n_agents": 50, "n_tasks": 100}, episodes=5,
              tests="scale: 50 agents, 100 tasks, L_j = 4 (observation and action spaces five times Default's); "
                    "here random masked bidding outscores CBGABI on average, so the normalised scale is inverted "
                    "and the share of the best known is the figure to report",
              source="ours: Default's generator at five times the size (the sources stop at 16 agents)"),
    SuiteTask("Hetero", "default", {"n_agents": 10, "n_tasks": 20, **HETERO}, episodes=20,
              tests="equipment and prerequisites: types A, B, C; tasks needing A, AB or ABC (one agent per item); "
                    "5 prerequisite chains of 3 tasks",
              source="thesis §3.3.4: E3.14 Exp3 (Fig 3.23, heterogeneous agents) with E3.15 Exp2's chains "
                     "(Fig 3.25); the combination is ours"),
    SuiteTask("TightWindows", "default", {"window": 1.0}, episodes=20,
              tests="timing: each task must be started within 1 min of its start time instead of 5, so L_j = 4 "
                    "agents must arrive nearly together",
              source="thesis §3.3.2 test scenario with the window cut from 5 min to 1 min (ours)"),
    SuiteTask("Range", "default", {"agents_per_task": 2, "comm_range": 2.0, "require_known_capacity": True},
              episodes=20,
              tests="limited communication: range 2 km on the 5 × 5 km floor (often two groups), multi-hop "
                    "messages, agents bid only on tasks whose L_j = 2 capable agents they know",
              source="thesis §4.3, Figs 4.6–4.7 (E4.3; Figs 4.3–4.4 at r = 2 show two groups), CBGA's L_j = 2 "
                     "series"),
    SuiteTask("Lossy", "default", {"message_loss": 0.02, "loss_model": "gilbert_elliott"}, episodes=30,
              tests="bursty message loss: each link a Gilbert–Elliott channel (2 % loss when good, bursts of total "
                    "loss entered with probability 0.05 and left with 0.5 per round)",
              source="beyond the sources (ours; Gilbert 1960, Elliott 1963); Johnson §3.5 motivates unreliable "
                     "links"),
    SuiteTask("Delay", "default", {"max_delay": 3}, episodes=30,
              tests="message delay: every message arrives 0–3 rounds late",
              source="beyond the sources (ours); Johnson §2.2 names delayed links"),
    SuiteTask("Dropout", "default", {"dropouts": 2, "dropout_rounds": [1, 3]}, episodes=30,
              tests="agent failure: 2 agents fail at the start of a round drawn from 1–3; the others clear their "
                    "bids after a silence timeout",
              source="beyond the sources (ours; configs/experiments/comm_dropout.yaml at k = 2)"),
    SuiteTask("Async", "default", JOHNSON_ASYNC, episodes=20, normaliser="acbba",
              tests="asynchronous consensus (ACBBA, one step one tick) with pop-up tasks: 10 tasks at the start, "
                    "25 more released one every 50 ticks; episodes end at local convergence",
              source="Johnson §4.1.3 (8 agents, 35 tasks, bundles of 5, Figs 4-3–4-4); CBGABI does not apply "
                     "(single-agent tasks, asynchronous), ACBBA normalises"),
    *[SuiteTask(f"Ladder{n}x{m}", "train_small", {"n_agents": n, "n_tasks": m}, episodes=20 if n <= 8 else 10,
                best_known="lns",
                tests=f"size generalisation: Small's generator at {n} agents and {m} tasks, start times still over "
                      "40 min (spread with M, the instances get so easy that random masked bidding ties CBGABI; "
                      "train on Small, test here)",
                source="ours: the size ladder over the thesis §3.3.2 scenario")
      for n, m in LADDER],
]
TASKS: dict[str, SuiteTask] = {task.id: task for task in _TASKS}


def task(task_id: str) -> SuiteTask:
    """The task of ``task_id``; an unknown id is a ``ConfigError`` listing the suite's ids."""
    if task_id in TASKS:
        return TASKS[task_id]
    close = difflib.get_close_matches(task_id, TASKS, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ConfigError(f"unknown task {task_id!r}{hint}; suite {SUITE} has: {', '.join(TASKS)}")


def cards() -> str:
    """The suite's cards as markdown (docs/benchmark.md holds this text; ``taskalloc benchmark --cards``)."""
    blocks = []
    for t in TASKS.values():
        changed = ", ".join(f"{k}={v}" for k, v in t.overrides.items()) or "none"
        blocks.append(f"### `{t.id}`\n\n- **Tests:** {t.tests}.\n- **Source:** {t.source}.\n"
                      f"- **Scenario:** `{t.scenario}`, overridden: {changed}.\n"
                      f"- **Seeds:** test {t.test_seeds[0]}–{t.test_seeds[-1]}, validation "
                      f"{t.validation_seeds[0]}–{t.validation_seeds[-1]} ({t.episodes} each).\n"
                      f"- **Normalised by:** random = 0, {t.normaliser} = 1; best known: {t.best_known}.\n")
    return "\n".join(blocks)


def register_suite() -> None:
    """Register every task id for ``pettingzoo.make("parallel", id)`` and ``pettingzoo.make("aec", id)``; the
    config is resolved once here, so a bad task definition fails at import."""
    if not hasattr(pettingzoo, "register"):      # PettingZoo < 1.27 has no registry
        return
    for suite_task in TASKS.values():
        kwargs = {"scenario": to_mapping(suite_task.config())}
        for env_type, entry_point in ENTRY_POINTS.items():
            pettingzoo.register(env_type, suite_task.id, entry_point=entry_point, kwargs=kwargs)
