"""The reward every agent receives and the episode record of the final infos: one home for both, shared by
``TaskAllocEnv.step`` and any batched environment that must hand out the same numbers.

Reward (cooperative, potential-based with the team score as the potential, Ng, Harada & Russell 1999): every live
agent receives ``(score_t − score_{t−1}) / scale``, score being the team score of thesis (3.4) and §5.3.1 ("the sum
of all rewards for completed tasks minus the cost of agents travelling", ``scoring.team_score``), which is 0 before
the first bid. The return of a whole episode is therefore ``score / scale``. ``reward_scale`` chooses the scale
(ours; the sources define the score, not a learning signal):

* ``"total_reward"`` (default): the instance's total task reward Σ_j L_j · pay_j (pay_j = c̄_j per member under
  ``reward_split="per_agent"``, c̄_j / L_j under ``"total"``; ``ScoringModel.pay``), the most any allocation can
  earn: every task valid, its L_j members paid in full (the discount of (3.8) is at most 1) and no travel cost (3.9).
  The return is the share of that ceiling the team earned net of travel: at most 1, about 0.6–0.8 for the scripted
  baselines on the suite's tasks (docs/decisions.md). An instance whose tasks pay nothing is scaled by 1.
* ``"raw"``: 1, the score's own units (the return is the score).
* a finite number > 0: that number, the same for every instance.

Episode record: on the step where an agent's episode ends (the episode terminates or is truncated, or the agent
fails), its info carries ``episode`` with ``r`` (the return: the sum of the rewards it received), ``l`` (the steps it
took) and the allocation's figures ``score`` (raw), ``valid_tasks``, ``conflicts``, ``rounds``, ``messages`` and
``converged``: Gymnasium's and stable-baselines3's ``info["episode"]`` convention (``r``, ``l``; no wall time ``t``,
so the infos stay deterministic).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc_env.errors import ConfigError
from taskalloc_env.scoring import ScoringModel

REWARD_SCALES = ("total_reward", "raw")
DEFAULT_REWARD_SCALE = "total_reward"
# the record's figures and the info key each is read from
EPISODE_FIGURES = {"score": "score", "valid_tasks": "valid_tasks", "conflicts": "conflicts", "rounds": "round",
                   "messages": "messages", "converged": "converged"}


def check_reward_scale(value: Any) -> str | float:
    """``value`` as a scale rule (a name of ``REWARD_SCALES`` or a float); anything else is a one-line
    ``ConfigError`` naming the allowed values."""
    if isinstance(value, str) and value in REWARD_SCALES:
        return value
    if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_)) \
            and 0 < value < math.inf:
        return float(value)
    raise ConfigError(f"reward_scale must be one of {REWARD_SCALES} or a finite number > 0, got {value!r}")


def total_reward(model: ScoringModel) -> float:
    """Σ_j L_j · pay_j: what the instance pays when every task is valid and on time, and nobody travels."""
    return float(np.dot(model.pay, model.scenario.task_agents))


def episode_scale(rule: str | float, model: ScoringModel) -> float:
    """The divisor of an episode's rewards under ``rule`` (checked by ``check_reward_scale``) on ``model``'s
    instance."""
    if rule == "raw":
        return 1.0
    if rule == "total_reward":
        ceiling = total_reward(model)
        return ceiling if ceiling > 0 else 1.0
    return float(rule)


def step_reward(score: float, last_score: float, scale: float) -> float:
    """The reward of one step: the change of the team score divided by the episode's scale."""
    return (score - last_score) / scale


def episode_record(episode_return: float, length: int, info: Mapping[str, Any]) -> dict[str, Any]:
    """``info["episode"]`` of an agent whose episode ends: its return ``r``, its length ``l`` (steps) and the
    figures of ``EPISODE_FIGURES`` read from its final ``info``."""
    return {"r": episode_return, "l": length, **{key: info[source] for key, source in EPISODE_FIGURES.items()}}
