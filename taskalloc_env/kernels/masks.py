"""Every agent's action mask, compiled; ``engine.action_masks_reference`` (numpy) is the reference.

``fill_masks`` writes, per agent, pass (always allowed), then the valid bids and the allowed quits unless the agent
has passed, in the column layout of ``taskalloc_env.actions`` (pass, the bid columns, the quit columns). It saves
the numpy calls and the (N, 1 + 2M) temporaries of the reference at every step (``tests/test_engine.py`` compares the
two).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def fill_masks(can_bid: np.ndarray, can_quit: np.ndarray, passed: np.ndarray, mask: np.ndarray) -> None:
    """Fill ``mask`` (N, 1 + 2M) int8 from ``can_bid`` and ``can_quit`` (N, M) and ``passed`` (N,)."""
    n, m = can_bid.shape
    for i in range(n):
        mask[i, 0] = 1
        acting = not passed[i]
        for j in range(m):
            mask[i, 1 + j] = can_bid[i, j] and acting              # actions.encode_bid(j)
            mask[i, 1 + m + j] = can_quit[i, j] and acting         # actions.encode_quit(j, m)
