"""ACBBA bid timestamps as exact, unique (tick, bump, stamper) triples packed into one int64 (Johnson §4.1.2).

Johnson's t_kj is "the timestamp of when this winning bid was made" (Johnson §4.1.2, extraction line 822), set when
a bid is made ("the current time is sampled and recorded as the bid time", Module 1, line 812) and moved "ε greater
than the losing time" when a bid is confirmed (remark on Table 4.1 rows 1–3, line 875). Johnson gives no value for
ε or for the equality tolerance ε_t of rows 5, 13, 22 and 32. Our choice (docs/decisions.md): a time is the triple

    (tick, bump, stamper)     compared lexicographically

* a new bid, or an empty bid "with current time" (Table 4.1's rebroadcast*, line 866), is ``(now, 0, i)``;
* ε: a bump of time t by agent i is ``(t.tick, t.bump + 1, i)``, later than t and earlier than the next tick;
* ε_t = 0: equal times are the same triple. The stamper makes every stamping event unique, so two different
  records never carry equal times (the sink rows compare times only, never bids; with (tick, bump) alone two agents
  bumping the same losing time would freeze a disagreement).

Packing: ``(tick + 1) << 40 | bump << 16 | stamper``; ``NEVER`` (0) precedes every real time, as the initial belief
(∅, 0, never) of every task.
"""

from __future__ import annotations

import numpy as np

NEVER = 0
TICK_SHIFT, BUMP_SHIFT = 40, 16
MAX_AGENTS = 1 << BUMP_SHIFT                      # stamper ids 0 .. 65535
MAX_BUMPS = 1 << (TICK_SHIFT - BUMP_SHIFT)        # bumps of one tick's time before it would overflow
MAX_TICKS = (1 << (63 - TICK_SHIFT)) - 2          # ticks 0 .. 8 388 606


def stamp(tick: int | np.ndarray, agent: int | np.ndarray) -> np.ndarray:
    """(tick, 0, agent): a bid made, or an empty bid sent, at ``tick`` by ``agent``."""
    return (np.asarray(tick, dtype=np.int64) + 1) << TICK_SHIFT | np.asarray(agent, dtype=np.int64)


def bump(time: np.ndarray, agent: int | np.ndarray) -> np.ndarray:
    """time + ε, stamped by ``agent``: the same tick, one bump more."""
    time = np.asarray(time, dtype=np.int64)
    bumps = bumps_of(time) + 1
    if np.any(bumps >= MAX_BUMPS):
        raise OverflowError(f"a timestamp was bumped {MAX_BUMPS} times within one tick (a livelock; cap the ticks)")
    return (time >> TICK_SHIFT) << TICK_SHIFT | bumps << BUMP_SHIFT | np.asarray(agent, dtype=np.int64)


def tick_of(time: np.ndarray) -> np.ndarray:
    """The tick of a time (−1 for ``NEVER``)."""
    return (np.asarray(time, dtype=np.int64) >> TICK_SHIFT) - 1


def bumps_of(time: np.ndarray) -> np.ndarray:
    return (np.asarray(time, dtype=np.int64) >> BUMP_SHIFT) & (MAX_BUMPS - 1)


def stamper_of(time: np.ndarray) -> np.ndarray:
    return np.asarray(time, dtype=np.int64) & (MAX_AGENTS - 1)


def later_than(time: np.ndarray, agent: int | np.ndarray, now: int, refresh: str) -> np.ndarray:
    """A time of ``agent`` later than ``time``: ``time`` + ε (``refresh="epsilon"``, the remark of rows 1–3, line 875)
    or the current time if that is later (``"now"``, action 5 "to reflect the current time", line 871)."""
    bumped = bump(time, agent)
    return bumped if refresh == "epsilon" else np.maximum(bumped, stamp(now, agent))
