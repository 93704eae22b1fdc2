"""A privileged policy: every agent bids along the exact optimum, through the consensus protocol.

It sees the whole scenario, as no decentralised agent can, and solves it at the start of each episode with
``taskalloc.policies.centralised.exact`` (``oracle-lns``: with the group search ``taskalloc.policies.local_search``, a
lower bound on the optimum, for instances too large for ``exact``); then each agent bids on the first task of its path
(in path order) that its action mask allows, and passes when none is left; it never quits. It is not a baseline: it
measures the ceiling of the environment's action space, how close bids and passes through the protocol (Alg 5's bundle
phase, the consensus as the dynamics) can come to the optimum, and it is the teacher of ``research.training.distil``.
The optimum's size limits apply (``exact``: at most ``MAX_AGENTS`` × ``MAX_TASKS``). It reaches the optimum on every
held-out ``train_small`` instance, under 20 % message loss too (docs/learning.md); not on every configuration (a limited
communication range, pop-up tasks or a bundle limit can stop it).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy
from taskalloc.policies.centralised import exact
from taskalloc.policies.local_search import local_search
from taskalloc_env.actions import PASS, encode_bid

SOLVERS = {"exact": exact, "lns": local_search}


def bid_along(path: Sequence[int], mask: np.ndarray) -> int:
    """The bid on the first task of ``path`` that ``mask`` allows, or pass (0) when none is left."""
    return next((encode_bid(j) for j in path if mask[encode_bid(j)]), PASS)


class OraclePolicy(Policy):
    """Bids along the paths of ``solver``'s allocation, the exact optimum by default (privileged: it reads the
    scenario, not only the observation)."""

    def __init__(self, solver: str = "exact") -> None:
        super().__init__()
        if solver not in SOLVERS:
            raise ValueError(f"oracle: unknown solver {solver!r}; known: {', '.join(SOLVERS)}")
        self.solver = solver
        self.name = "oracle" if solver == "exact" else f"oracle-{solver}"
        self.paths: tuple[tuple[int, ...], ...] = ()

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.paths = SOLVERS[self.solver](self.env.scenario, self.env.config).paths

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        return {agent: bid_along(self.paths[self.env.agent_index[agent]], obs["action_mask"])
                for agent, obs in observations.items()}

    def targets(self, agents: Sequence[str], masks: np.ndarray) -> np.ndarray:
        """(A, 1 + 2M) bool: the actions that keep each agent on the optimum, every allowed bid on a task of its
        optimal path (the optimum fixes the tasks, not the order of the bids), or pass when none is allowed. The
        action ``act`` picks is always among them."""
        good = np.zeros(masks.shape, dtype=bool)
        for row, agent in enumerate(agents):
            for j in self.paths[self.env.agent_index[agent]]:
                good[row, encode_bid(j)] = masks[row, encode_bid(j)]
        good[:, 0] = ~good.any(axis=1)
        return good
