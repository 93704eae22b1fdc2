"""Every agent's action mask, compiled; ``engine.action_masks_reference`` (numpy) is the reference.

``fill_masks`` writes, per agent, pass (always allowed), then the valid bids, the allowed quits and, when the mask
has release columns (``release_actions``), the allowed releases, unless the agent has passed, in the column layout
of ``taskalloc_env.actions`` (pass, the bid columns, the quit columns, the release columns). It saves the numpy calls
and the (N, 1 + 2M) temporaries of the reference at every step (``tests/test_engine.py`` compares the two).
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit


@jit
def fill_masks(can_bid: np.ndarray, can_quit: np.ndarray, can_release: np.ndarray, passed: np.ndarray,
               mask: np.ndarray) -> None:
    """Fill ``mask`` (N, 1 + 2M) or (N, 1 + 3M) int8 from ``can_bid``, ``can_quit`` and ``can_release`` (N, M) and
    ``passed`` (N,); ``can_release`` is read only when ``mask`` has the release columns."""
    n, m = can_bid.shape
    release = mask.shape[1] > 1 + 2 * m
    for i in range(n):
        mask[i, 0] = 1
        acting = not passed[i]
        for j in range(m):
            mask[i, 1 + j] = can_bid[i, j] and acting              # actions.encode_bid(j)
            mask[i, 1 + m + j] = can_quit[i, j] and acting         # actions.encode_quit(j, m)
            if release:
                mask[i, 1 + 2 * m + j] = can_release[i, j] and acting      # actions.encode_release(j, m)
