"""CBAA, the consensus-based auction algorithm (Choi, Brunet & How 2009; recapped in thesis §2.2.3, Alg 1–2,
Figs 2.3–2.4): single assignment, each agent holds at most one task.

Phase 1 (thesis Alg 1): an agent with no task (Σ_j x_ij = 0, l. 4) computes h_ij = I(c_ij > y_ij) (l. 5, eq. (2.2)),
takes J_i = argmax_j c_ij · h_ij (l. 7) and bids y_{i,J_i} = c_{i,J_i} (l. 8–9); an agent that holds a task skips the
selection. Phase 2 (Alg 2): agents exchange their winning bids and an agent outbid on its task loses it (l. 4–7).

Here both phases are the environment's, as for CBBA: the mask is h_ij (the outbid test with the strict ">" of
eq. (2.2), ``outbid_ties = strict``), the bid is the marginal gain of the task on the agent's empty path, i.e. the
score of doing that task alone (c_ij of Alg 1), and the consensus is CBBA's table. "When the number of assignments an
agent is allowed is limited to 1, the CBBA will produce the same result as the CBAA" (thesis §2.2.4), so CBAA is CBBA
whose agents hold one task. The bundle of one is Alg 1's own condition (l. 4: select only while unassigned), applied
by this policy: it pins no option, so the environment (and a suite task) stays the one it was built as; in an
environment with ``max_bundle = 1`` CBBA and CBAA take the same actions (``tests/test_cbaa.py``).
"""

from __future__ import annotations

import numpy as np

from taskalloc.policies.scripted import CBBAPolicy
from taskalloc_env.actions import PASS


class CBAAPolicy(CBBAPolicy):
    """CBAA (Choi et al. 2009): CBBA's greedy bid while the agent holds no task, else pass (thesis Alg 1 l. 4)."""

    def __init__(self) -> None:
        super().__init__()
        self.name = "CBAA"

    @property
    def columns(self) -> tuple[str, ...]:
        """The marginal gain (c_ij) and whether the task is in the agent's bundle (x_ij)."""
        return ("gain", "in_bundle")

    def choose(self, mask: np.ndarray, gain: np.ndarray, in_bundle: np.ndarray) -> np.ndarray:  # type: ignore[override]
        """Actions (A,): CBBA's choice (the best valid bid, lowest task id on ties; thesis Alg 1 l. 7) for an agent
        without a task, pass for one that holds a task (Alg 1 l. 4)."""
        return np.where(in_bundle.any(axis=1), PASS, super().choose(mask, gain))
