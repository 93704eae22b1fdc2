"""Preferred-duo CBBA (Choi et al. 2010, as thesis §2.2.5, §3.3.3 (E3.7) and §4.3 describe it).

A *preferred duo* task "can be completed by either one or two agents. The assignment of a single agent is acceptable
and provides the same reward as a solo task. Assigning two agents to the task provides a greater reward" (thesis
§2.2.5); in E3.7 one agent earns 100 and "if a second agent assisted with the task they would receive an additional
reward of 50 for a total score of 150" (thesis §3.3.3). Choi et al. 2010 keep CBBA's vectors and split every duo task
j into two sub-tasks j_1 and j_2, with the restriction (thesis eq. (4.1), §4.3)

    c'_ij1 = c_ij1 · (1 − 1(z_ij2 = i)),    c'_ij2 = c_ij2 · (1 − 1(z_ij1 = i)):

an agent never holds both parts of one task. Here that is:

* ``split_duo`` (the scenario transformation): task j of a single-agent scenario (M tasks) becomes the lead part j
  (L = 1, reward c̄_j) and the helper part j + M (L = 1, reward ``helper_fraction`` · c̄_j = 50 for c̄_j = 100), at
  the same place with the same window and duration. The helper names the lead as its prerequisite, so the helper is
  biddable only while some agent holds the lead (``prereq_mode = all_have_bid``) and pays only if the lead is done
  (``scoring.prerequisites_valid``), and it is timed as a separate visit of the same place
  (``prereq_timing = none``: no waiting for the lead to finish; each agent is paid for its own arrival, as CBGA's
  members are, since neither source synchronises the two).
* ``DuoCBBAPolicy``: the CBBA policy with (4.1): a part whose other part is in the agent's own bundle is never
  bid, so the helper is always done by *another* agent than the lead.
* ``preferred_duo_cbba``: a solver on an instance of a single-agent config (``taskalloc.evaluation.episodes`` runs it as
  ``cbba-duo``): split, run CBBA with the restriction to convergence, check the exclusion.

Choi et al. 2010's outer loop (thesis Alg 4) re-runs CBBA after eliminating *required* duo tasks with one part
assigned; with preferred duo tasks only, that set is empty and a single CBBA run is the whole algorithm. Choi et al.
2010 itself is not among the sources; this follows the thesis's account of it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.rollout import rollout
from taskalloc.policies.scripted import CBBAPolicy
from taskalloc_env.actions import bid_columns
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import GENERATION_FIELDS, TaskAllocConfig, to_mapping
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.scenario import Scenario

HELPER_FRACTION = 0.5       # E3.7: 100 for the lead, an additional 50 for the helper (thesis §3.3.3)
DUO_OPTIONS = {"prereq_timing": "none", "prereq_mode": "all_have_bid"}


def split_duo(scenario: Scenario, helper_fraction: float = HELPER_FRACTION) -> Scenario:
    """The preferred-duo version of a single-agent scenario: lead parts 0..M−1, helper parts M..2M−1 (see above)."""
    if (scenario.task_agents != 1).any():
        raise ValueError("split_duo needs single-agent tasks (every L_j = 1): each becomes a lead and a helper part")
    if scenario.has_prerequisites:
        raise ValueError("split_duo needs a scenario without prerequisites (the helper parts use them)")
    if not helper_fraction > 0:
        raise ValueError(f"helper_fraction must be > 0, got {helper_fraction!r}")
    m = scenario.n_tasks
    prereqs = np.zeros((2 * m, 2 * m), dtype=bool)
    prereqs[np.arange(m, 2 * m), np.arange(m)] = True           # helper j + M needs lead j

    def twice(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a, a])

    return Scenario(
        agent_pos=scenario.agent_pos, agent_speed=scenario.agent_speed, agent_equipment=scenario.agent_equipment,
        task_pos=twice(scenario.task_pos),
        task_reward=np.concatenate([scenario.task_reward, helper_fraction * scenario.task_reward]),
        task_start=twice(scenario.task_start), task_end=twice(scenario.task_end),
        task_duration=twice(scenario.task_duration), task_agents=twice(scenario.task_agents),
        task_equipment=twice(scenario.task_equipment), task_prereqs=prereqs,
        time_discount=scenario.time_discount, distance_discount=scenario.distance_discount,
        equipment_names=scenario.equipment_names, arena=scenario.arena)


def duo_partners(scenario: Scenario) -> np.ndarray:
    """(2M,) the other part of every part of a ``split_duo`` scenario; ValueError for any other scenario."""
    size = scenario.n_tasks
    m = size // 2
    expected = np.zeros((size, size), dtype=bool)
    expected[np.arange(m, size), np.arange(m)] = True
    if size % 2 or not np.array_equal(scenario.task_prereqs, expected):
        raise ValueError("not a preferred-duo scenario (build it with policies.duo.split_duo)")
    return np.concatenate([np.arange(m, size), np.arange(m)])


def both_parts(allocation: Allocation, n_duo: int) -> list[tuple[int, int]]:
    """(agent, task) for every agent whose path holds both parts of a duo task (empty under the restriction)."""
    return [(i, j) for i, path in enumerate(allocation.paths) for j in path if j < n_duo and j + n_duo in path]


class DuoCBBAPolicy(CBBAPolicy):
    """CBBA on a ``split_duo`` scenario, never bidding a part whose other part it holds (thesis eq. (4.1))."""

    def __init__(self) -> None:
        super().__init__()
        self.name = "CBBA preferred duo"
        self.partner = np.zeros(0, dtype=np.int64)

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.partner = duo_partners(self.env.scenario)

    def restrict(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """The action mask with (4.1) applied: no bid on the other part of a held task."""
        mask = np.array(obs["action_mask"], copy=True)
        held = self.layout.task_feature(obs["observation"], "in_bundle") > 0.5
        mask[bid_columns(self.n_tasks)] &= ~held[self.partner]
        return mask

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        restricted = {agent: {**obs, "action_mask": self.restrict(obs)} for agent, obs in observations.items()}
        return super().act(restricted, infos)


def duo_env(scenario: Scenario, cfg: TaskAllocConfig, helper_fraction: float = HELPER_FRACTION) -> TaskAllocEnv:
    """The environment of the preferred-duo version of ``scenario``, with ``cfg``'s scoring and protocol options."""
    options = {k: v for k, v in to_mapping(cfg).items() if k not in GENERATION_FIELDS}
    options.update(DUO_OPTIONS)
    options.pop("max_bundle", None)     # the cap counts duo parts differently; M_m is not used in E3.7
    return TaskAllocEnv(split_duo(scenario, helper_fraction), **options)


def preferred_duo_cbba(scenario: Scenario, cfg: TaskAllocConfig) -> Allocation:
    """Solve an instance of a single-agent config by preferred-duo CBBA (the parts' allocation, scored as above)."""
    if cfg.comm_range is not None:
        raise ValueError("preferred_duo_cbba runs with full communication (comm_range = null), as E3.7 does")
    env = duo_env(scenario, cfg)
    allocation = rollout(env, DuoCBBAPolicy(), seed=0)
    clash = both_parts(allocation, scenario.n_tasks)
    if clash:
        raise AssertionError(f"preferred-duo CBBA gave both parts of a task to one agent: {clash}")
    return allocation
