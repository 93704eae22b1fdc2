"""The two-pass merge of multi-agent task columns (thesis §3.2.3, Alg 6 l. 7–23, with the guards needed to run it).

``merge`` is pure: the receivers' bid columns and the senders' bid columns in, the receivers' updated columns
out. Arrays carry a leading receiver axis R (one message per receiver), an agent axis N and a task axis M, so a
round's messages at one position of every receiver's inbox are merged in one call.

Pass A (Alg 6 l. 7–12) refreshes what the receiver i already believes: for each member m ≠ i of column j, the
sender's entry wins if m is the sender or the sender heard from m more recently (it may be 0: m left or was
displaced). Pass B (Alg 6 l. 13–23) imports the sender's members that i does not hold, best (bid, id) first: a
newcomer takes a free slot if the group has room and its equipment fills an unmet need; otherwise it displaces the
(bid, id)-lowest member with the same equipment ((3.15)) if it outbids it (ties: the higher id, thesis §3.2.3).
The displaced member may be i itself: that is how i learns it lost. Guards added to the listing (our choices, see
docs/algorithm.md): i is authoritative on its own row, Pass B also trusts the sender's own entry, and it takes the
sender's members in a fixed order.

``merge`` decides trust by the per-agent timestamps of the synchronous protocol; ``merge_stamped`` by per-entry
times, for the asynchronous consensus (``async_consensus``), where a message carries only the columns that changed
and may arrive late or out of order. Both run the same ``two_pass``.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.cbba_table import NONE
from taskalloc_env.groups import Equipment, admit


def merge(bids_i: np.ndarray, bids_k: np.ndarray, receiver: np.ndarray, sender: np.ndarray, s_i: np.ndarray,
          s_k: np.ndarray, required_agents: np.ndarray, equipment: Equipment) -> np.ndarray:
    """Merge sender columns ``bids_k`` (R, N, M) into receiver columns ``bids_i``; returns the new columns.

    ``s_i``/``s_k`` (R, N) are the timestamps before this message; ``required_agents`` is L_j per column.
    """
    agents = np.arange(bids_i.shape[1])
    trust = (agents[None, :] == sender[:, None]) | (s_k > s_i)
    trust &= agents[None, :] != receiver[:, None]                          # i is authoritative on its own row
    trust = np.broadcast_to(trust[:, :, None], bids_i.shape)
    return two_pass(bids_i, bids_k, trust, trust, required_agents, equipment)[0]


def merge_stamped(bids_i: np.ndarray, t_i: np.ndarray, bids_k: np.ndarray, t_k: np.ndarray, receiver: np.ndarray,
                  required_agents: np.ndarray, equipment: Equipment) -> tuple[np.ndarray, np.ndarray]:
    """The asynchronous merge: every entry X[m][j] carries the time it was made or withdrawn (``t_*``, (R, N, M)
    packed ``stamps``) in place of the per-agent timestamps s[m]; returns the new columns and their times.

    Pass A trusts a sender entry that is newer than the receiver's (t_k > t_i): a bid made or withdrawn later. Pass B
    also offers the admission test a sender member whose time equals the receiver's record of it, which the receiver
    holds at 0 only because it saw it displaced: if the displacer has gone, it is re-admitted (our choice,
    docs/decisions.md). The receiver is authoritative on its own row, as in ``merge``.
    """
    own = (np.arange(bids_i.shape[1])[None, :] == receiver[:, None])[:, :, None]
    out, copied = two_pass(bids_i, bids_k, (t_k > t_i) & ~own, (t_k >= t_i) & ~own, required_agents, equipment)
    return out, np.where(copied, t_k, t_i)


def two_pass(bids_i: np.ndarray, bids_k: np.ndarray, trust_a: np.ndarray, trust_b: np.ndarray,
             required_agents: np.ndarray, equipment: Equipment) -> tuple[np.ndarray, np.ndarray]:
    """Pass A and Pass B with the (R, N, M) trust masks of each pass; returns the columns and the entries copied from
    the sender (Pass A's refreshed members and Pass B's admitted newcomers)."""
    r_count, n_agents, _ = bids_i.shape
    # Pass A
    refresh = (bids_i > 0) & trust_a
    out = np.where(refresh, bids_k, bids_i)
    admitted = np.zeros(bids_i.shape, dtype=bool)
    # Pass B
    candidates = (bids_k > 0) & (out == 0) & trust_b
    rows = np.arange(r_count)[:, None]
    cols = np.arange(bids_i.shape[2])[None, :]
    while candidates.any():
        active = candidates.any(axis=1)                                            # (R, M)
        keyed = np.where(candidates, bids_k, -np.inf)
        newcomer = n_agents - 1 - np.argmax(keyed[:, ::-1, :], axis=1)             # best bid, ties: higher id
        bid = bids_k[rows, newcomer, cols]
        admission = admit(out, newcomer, bid, required_agents, equipment)
        r_idx, j_idx = np.nonzero(active & (admission.displaced != NONE))
        out[r_idx, admission.displaced[r_idx, j_idx], j_idx] = 0.0
        r_idx, j_idx = np.nonzero(active & admission.accepted)
        out[r_idx, newcomer[r_idx, j_idx], j_idx] = bid[r_idx, j_idx]
        admitted[r_idx, newcomer[r_idx, j_idx], j_idx] = True
        r_idx, j_idx = np.nonzero(active)
        candidates[r_idx, newcomer[r_idx, j_idx], j_idx] = False
    return out, refresh | (admitted & (out > 0))
