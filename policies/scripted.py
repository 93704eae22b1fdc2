"""Scripted baselines that read only the observation: CBBA, ACBBA, CBGA and its variants, random, always-pass.

Bundle construction (thesis §3.2.2, Alg 5): among the valid bids (the action mask: eligibility filters and the
outbid test h_ij, Alg 5 l. 8–20), pick the largest marginal gain c_ij (J_i = argmax_j c_ij·h_ij, Alg 5 l. 21), one
bid per step; pass when nothing is valid. Ties go to the lower task id (our choice; the thesis is silent, see
docs/decisions.md). The environment stores the bid, inserts the task at the agent's best slot and runs the
consensus.

* ``team_bidding`` (thesis §5.2.1, eq. (5.5); h_ij as in Alg 8): the final choice maximises the group total after
  the bid, ``team_value = net`` (default: Σ_k X_i[k][j] − displaced bid + c_ij, our reading of the text's "taking
  into account any replaced bids") or ``literal`` ((5.5) as printed, without subtracting the displaced bid). Bid
  values and validity are unchanged.
* ``task_quitting`` (thesis §5.2.2, Alg 9, eq. (5.6); article eq. (10)): before bidding, quit a multi-agent task
  whose group is still incomplete once the group-synchronised timer passed δ rounds, once per task. The environment
  keeps the timer and allows the quit only when Alg 9's conditions hold (δ is the config field ``delta``), so the
  policy needs an environment with ``task_quitting=True`` (``env_overrides``) and takes δ from it: a config or an
  experiment sweep that sets ``delta`` sets the policy's threshold too. ``quit_threshold=k`` pins δ = k instead
  (``env_overrides`` then also holds ``delta=k``). Quits go in task-id order, one per step, as Alg 9 loops over
  tasks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy, stack_observations
from taskalloc.policies.greedy import greedy_actions
from taskalloc_env import kernels
from taskalloc_env.actions import PASS, bid_columns, encode_bid, encode_quit, quit_columns
from taskalloc_env.observation import ObservationLayout

TEAM_VALUES = ("net", "literal")


class CBGAPolicy(Policy):
    """CBGA (Hunt 2014), with team-improving bids and task quitting as options; both on = CBGABI."""

    def __init__(self, team_bidding: bool = False, task_quitting: bool = False, quit_threshold: int | None = None,
                 team_value: str = "net") -> None:
        super().__init__()
        if team_value not in TEAM_VALUES:
            raise ValueError(f"team_value {team_value!r} is not one of {TEAM_VALUES}")
        if quit_threshold is not None and (isinstance(quit_threshold, bool) or not isinstance(quit_threshold, int)
                                           or quit_threshold < 0):
            raise ValueError(f"quit_threshold must be None (the environment's delta) or an integer >= 0, "
                             f"got {quit_threshold!r}")
        self.team_bidding = team_bidding
        self.task_quitting = task_quitting
        self.quit_threshold = quit_threshold
        self.team_value = team_value
        suffix = {(False, False): "", (False, True): "+TQ", (True, False): "+TB", (True, True): "BI"}
        self.name = "CBGA" + suffix[(team_bidding, task_quitting)]

    @property
    def env_overrides(self) -> dict[str, Any]:
        if not self.task_quitting:
            return {}
        if self.quit_threshold is None:         # δ is the environment's ``delta``
            return {"task_quitting": True}
        return {"task_quitting": True, "delta": self.quit_threshold}

    @property
    def delta(self) -> int | None:
        """The δ this policy quits with: its pinned ``quit_threshold``, else the bound environment's ``delta``."""
        if not self.task_quitting:
            return None
        if self.quit_threshold is not None:
            return self.quit_threshold
        return self._env.config.delta if self._env is not None else None

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        if not observations:
            return {}
        agents = list(observations)
        obs, masks = stack_observations(observations, agents)
        return dict(zip(agents, self.decide(obs, masks.astype(bool), self.layout).tolist()))

    def decide(self, obs: np.ndarray, masks: np.ndarray, layout: ObservationLayout) -> np.ndarray:
        """Actions (A,) from stacked observations (A, D) of ``layout`` and boolean masks (A, 1 + 2M)."""
        # task j's column c sits at own_size + j · task_size + c: every task's value of one column is a strided slice
        columns = (obs[:, layout.own_size + layout.task_column(name)::layout.task_size] for name in self.columns)
        return self.choose(masks, *columns)

    @property
    def columns(self) -> tuple[str, ...]:
        """The observation's task columns the rule reads, in ``choose``'s argument order."""
        if not self.team_bidding:
            return ("gain",)
        return ("gain", "group_total", "displaced_bid") if self.team_value == "net" else ("gain", "group_total")

    def choose(self, mask: np.ndarray, gain: np.ndarray, group_total: np.ndarray | None = None,
               displaced_bid: np.ndarray | None = None) -> np.ndarray:
        """Actions (A,) from action masks (A, 1 + 2M) and the observation's task ``columns`` (A, M) — gain, and with
        team bidding the group total (and the displaced bid for ``net``): the first allowed quit (task order), else
        the best allowed bid (lowest task id on ties), else pass. The one home of the rule, for ``act`` and for the
        direct solver (``taskalloc.policies.fast``): ``taskalloc.policies.greedy.greedy_actions`` compiled, else
        ``choose_reference``."""
        if not kernels.COMPILED:
            return self.choose_reference(mask, gain, group_total, displaced_bid)
        return greedy_actions(mask, gain, gain if group_total is None else group_total,
                              gain if displaced_bid is None else displaced_bid,
                              self.team_bidding, self.team_value == "net", self.task_quitting)

    def choose_reference(self, mask: np.ndarray, gain: np.ndarray, group_total: np.ndarray | None = None,
                         displaced_bid: np.ndarray | None = None) -> np.ndarray:
        """``choose`` in numpy (the reference of ``taskalloc.policies.greedy.greedy_actions``)."""
        m = gain.shape[1]
        valid = mask[:, bid_columns(m)]
        value = gain
        if self.team_bidding:
            value = value + group_total
            if self.team_value == "net":
                value = value - displaced_bid
        actions = np.where(valid.any(axis=1), encode_bid(np.argmax(np.where(valid, value, -np.inf), axis=1)), PASS)
        if self.task_quitting:
            quits = mask[:, quit_columns(m)]
            if quits.any():
                actions = np.where(quits.any(axis=1), encode_quit(np.argmax(quits, axis=1), m), actions)
        return actions


class CBBAPolicy(CBGAPolicy):
    """CBBA (Choi et al. 2009) on single-agent tasks: the same greedy rule, consensus by the CBBA table."""

    def __init__(self) -> None:
        super().__init__()
        self.name = "CBBA"

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        if self.env.config.task_mix is not None or (self.env.scenario.task_agents > 1).any():
            raise ValueError(f"{self.name} assigns single-agent tasks only (every L_j = 1); {self.multi_agent_hint}")

    @property
    def multi_agent_hint(self) -> str:
        """What to use instead on multi-agent tasks (L_j > 1)."""
        return "use CBGAPolicy for L_j > 1"


class ACBBAPolicy(CBBAPolicy):
    """ACBBA (Johnson §4.1): CBBA's greedy rule in the asynchronous environment. A ready builder bids its best valid
    task, one per tick ("the module attempts to build its bundle identically to CBBA", Johnson §4.1.1), and passes
    when none is left, which completes the build and rebroadcasts; agents that are not ready only pass."""

    def __init__(self) -> None:
        super().__init__()
        self.name = "ACBBA"

    @property
    def env_overrides(self) -> dict[str, Any]:
        return {"consensus": "acbba"}

    @property
    def multi_agent_hint(self) -> str:
        """Johnson's ACBBA is stated for single-agent tasks (§4.1); CBGA's merge runs per message (docs §9.6)."""
        return ('CBGA and CBGABI run asynchronously with consensus="acbba" (e.g. make_policy("cbgabi") in an env '
                'with consensus="acbba")')


class RandomPolicy(Policy):
    """Uniform over each agent's action mask; reseeded by ``start(env, seed)`` when a seed is given."""

    name = "random"

    def __init__(self, seed: int | None = None) -> None:
        super().__init__()
        self.rng = np.random.default_rng(seed)

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        # a uniform index into the valid actions: the draw rng.choice(valid) makes, without its overhead
        choices = {}
        for agent, obs in observations.items():
            valid = np.flatnonzero(obs["action_mask"])
            choices[agent] = int(valid[self.rng.integers(len(valid))])
        return choices


class PassPolicy(Policy):
    """Every agent passes: the empty allocation (score 0), a floor for comparisons and a test driver."""

    name = "pass"

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        return dict.fromkeys(observations, 0)
