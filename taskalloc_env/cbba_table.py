"""The CBBA decision table for single-agent tasks (Choi et al. 2009; Johnson §3.4.1, Table 3.1; thesis Table 2.1).

``decide`` is pure: the receiver's and the sender's beliefs about each task's winner in, an action per task out
(``LEAVE``, ``UPDATE``: copy the sender's winner and bid, ``RESET``: clear). It is vectorised over any leading
shape, so one call decides a whole message, or one message for many receivers at once.

Bids compare lexicographically on (bid, winner id): equal bids go to the higher id (thesis §3.2.3 and App. A.1;
the table itself has no tie rule). ``table="canonical"`` is Choi et al. 2009 as Johnson §3.4.1 Table 3.1 restates
it; ``table="thesis"`` is the thesis's transcription (thesis §2.2.4, Table 2.1), which differs in two cells:
(sender i, receiver m) leaves instead of resetting, and (sender m, receiver i) updates when the sender is fresher
*or* bids higher instead of *and*.
"""

from __future__ import annotations

import numpy as np

LEAVE, UPDATE, RESET = 0, 1, 2
NONE = -1


def outbids(bid_a: np.ndarray, agent_a: np.ndarray, bid_b: np.ndarray, agent_b: np.ndarray) -> np.ndarray:
    """(bid_a, agent_a) ≻ (bid_b, agent_b): a higher bid, or an equal bid from a higher agent id."""
    return (bid_a > bid_b) | ((bid_a == bid_b) & (agent_a > agent_b))


def decide(receiver: np.ndarray, sender: np.ndarray, z_i: np.ndarray, y_i: np.ndarray, z_k: np.ndarray,
           y_k: np.ndarray, s_i: np.ndarray, s_k: np.ndarray, table: str = "canonical") -> np.ndarray:
    """Action of receiver i for each task on a message from sender k.

    ``receiver``/``sender`` are ids broadcastable against the (…, M) belief arrays ``z_*`` (winner id or NONE)
    and ``y_*`` (winning bid, 0 for none); ``s_i``/``s_k`` are (…, N) timestamp vectors, compared before the
    receiver stamps this message.
    """
    i = np.asarray(receiver)[..., None] if np.ndim(receiver) == np.ndim(z_i) - 1 else np.asarray(receiver)
    k = np.asarray(sender)[..., None] if np.ndim(sender) == np.ndim(z_k) - 1 else np.asarray(sender)

    z_i_at = np.where(z_i == NONE, 0, z_i)
    z_k_at = np.where(z_k == NONE, 0, z_k)
    if np.ndim(s_i) == 2 and np.ndim(z_i) == 2:       # (R, N) stamps, (R, M) beliefs: index rows directly
        rows = np.arange(len(s_i))[:, None]

        def stamp(s: np.ndarray, z: np.ndarray) -> np.ndarray:
            return s[rows, z]
    else:
        def stamp(s: np.ndarray, z: np.ndarray) -> np.ndarray:
            return np.take_along_axis(s, z, axis=-1)

    sk_zk, si_zk = stamp(s_k, z_k_at), stamp(s_i, z_k_at)
    fresh_zk = sk_zk > si_zk                          # sender heard from its winner m more recently
    stale_zk = si_zk > sk_zk                          # receiver heard from m more recently
    fresh_zi = stamp(s_k, z_i_at) > stamp(s_i, z_i_at)  # sender heard from the receiver's winner more recently
    better = outbids(y_k, z_k, y_i, z_i)

    snd_k, snd_i, snd_none = z_k == k, z_k == i, z_k == NONE
    snd_m = ~(snd_k | snd_i | snd_none)
    rcv_i, rcv_k, rcv_none = z_i == i, z_i == k, z_i == NONE
    rcv_third = ~(rcv_i | rcv_k | rcv_none)
    rcv_same, rcv_other = rcv_third & (z_i == z_k), rcv_third & (z_i != z_k)
    canonical = table == "canonical"

    update = (
        # sender believes k (itself)
        (snd_k & rcv_i & better) | (snd_k & rcv_k) | (snd_k & rcv_third & (fresh_zi | better)) | (snd_k & rcv_none)
        # sender believes m ∉ {i, k}
        | (snd_m & rcv_i & ((fresh_zk & better) if canonical else (fresh_zk | better)))
        | (snd_m & rcv_k & fresh_zk)
        | (snd_m & rcv_same & fresh_zk)
        | (snd_m & rcv_other & fresh_zk & (fresh_zi | better))
        | (snd_m & rcv_none & fresh_zk)
        # sender believes nobody
        | (snd_none & rcv_k)
        | (snd_none & rcv_third & fresh_zi)
    )
    reset = (
        (snd_i & rcv_k)
        | ((snd_i & rcv_third & fresh_zi) if canonical else np.zeros_like(update))
        | (snd_m & rcv_k & ~fresh_zk)
        | (snd_m & rcv_other & fresh_zi & stale_zk)
    )
    return np.where(update, UPDATE, np.where(reset, RESET, LEAVE))
