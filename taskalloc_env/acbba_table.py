"""The ACBBA decision table for single-agent tasks (Johnson §4.1.2, Table 4.1 and its remarks), cell by cell.

``decide`` is pure and vectorised like ``cbba_table.decide``: the sender k's record of each task (z_kj, y_kj,
t_kj) and the receiver i's (z_ij, y_ij, t_ij) in, the receiver's action and the table row that chose it out.
``apply`` turns the action into the receiver's new record and whether the task is rebroadcast. Times are the unique
triples of ``stamps`` (ε = one bump, ε_t = 0). Citations are to the plain-text extraction of Johnson's thesis
(Table 4.1 at lines 830–866, the actions at 826–828 and 870–871, the remarks at 873–906).

The five actions of Johnson §4.1.2 and how the table's marks refine them (the legend of † and ‡ is lost in the
extraction; the readings are the only ones consistent with the remarks, docs/decisions.md):

=================  ==============================================================================================
``UPDATE``         update & rebroadcast (action 1, line 826): copy (z_kj, y_kj, t_kj)
``OUTBID``         update† & rebroadcast (rows 1 and 17, lines 833, 849; also the tie rows 2 and 18, printed as a
                   plain update, by the remarks 875, 891): the receiver loses its bid; copy (z_kj, y_kj, t_kj);
                   with ``outbid_time="bump"`` (the † reading) a time not later than the receiver's losing time
                   becomes that time + ε ("the winning bid has a later time than the losing bid", 875)
``UPDATE_TIME``    update time & rebroadcast (action 5, line 871; printed "update‡" in rows 3 and 19): the
                   receiver keeps its own bid and makes its time later than t_kj if it is not (875, 891)
``LEAVE``          leave & rebroadcast (action 2, line 827; the table's default, line 832): own record unchanged
``LEAVE_REFRESH``  leave‡ & rebroadcast (rows 15, 29): keep (z_ij, y_ij), time later than t_kj if needed (903)
``LEAVE_QUIET``    leave & no-rebroadcast (action 3, line 828): the sink
``RESET_EMPTY``    reset & rebroadcast* (action 4, line 870; row 14): (∅, 0, current time)
``EMPTY``          leave & rebroadcast* (row 16): the receiver already holds ∅; it sends the empty bid with the
                   current time, "later than the one posted by the sender" (885–887)
``ADOPT_TIME``     row 13 by its remark, "if the receiver has old information, then update" (882): take t_kj
=================  ==============================================================================================

What is rebroadcast (the table's NOTE, line 865–866): the receiver's record after the action, which is its own
record for leave, the sender's for update, and the empty bid with the current time for rebroadcast*.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.cbba_table import NONE
from taskalloc_env.stamps import later_than, stamp

LEAVE_QUIET, UPDATE, OUTBID, UPDATE_TIME, LEAVE, LEAVE_REFRESH, RESET_EMPTY, EMPTY, ADOPT_TIME = range(9)
ACTION_NAMES = ("leave & no-rebroadcast", "update & rebroadcast", "update† & rebroadcast",
                "update time & rebroadcast", "leave & rebroadcast", "leave‡ & rebroadcast",
                "reset & rebroadcast*", "leave & rebroadcast*", "update time (adopt) & rebroadcast")
DEFAULT_ROW = 0          # a condition no cell covers: the header's "default: leave & rebroadcast" (line 832)


def decide(receiver: np.ndarray | int, sender: np.ndarray | int, z_k: np.ndarray, y_k: np.ndarray, t_k: np.ndarray,
           z_i: np.ndarray, y_i: np.ndarray, t_i: np.ndarray, *, row11: str = "update", row15: str = "leave_bump",
           row20_guard: bool = True, row28_guard: bool = True, ties: str = "lowest_id",
           equal_bids: str = "trust_later") -> tuple[np.ndarray, np.ndarray]:
    """(action, row) of receiver i for each task of a message from sender k (Johnson Table 4.1).

    ``receiver``/``sender`` broadcast against the (…, M) records; z is a winner id or NONE, y the bid (0 for none),
    t a packed time. ``row`` is the number of the table row that fired (1–32, the numbering of the remarks) or
    ``DEFAULT_ROW``. Options (named config fields ``acbba_*``, docs/configuration.md): ``row11`` follows the cell
    (``update``) or the remark's "trusts the later timestamp" (``trust_later``); ``row15`` the cell (``leave_bump``),
    leave without the time refresh (``leave``) or answer with an empty bid (``empty``, not in the thesis);
    ``row20_guard``/``row28_guard`` add the remarks' time guards to the unconditional cells; ``ties`` is the tie
    rule of rows 2 and 18 (``lowest_id``, line 875, or the repository's CBBA ``higher_id``); ``equal_bids`` is what
    a receiver does with an equal bid of another agent in row 9 and the uncovered m | n case: ``leave`` (the cell and
    the default) or ``trust_later``, Johnson's rule for the unstable states of rows 10–11 and 26–27 (not in the
    table for equal bids; docs/decisions.md).
    """
    i = _ids(receiver, z_i)
    k = _ids(sender, z_k)
    shape = np.broadcast_shapes(np.shape(z_k), np.shape(z_i))
    action = np.full(shape, LEAVE, dtype=np.int64)
    row = np.full(shape, DEFAULT_ROW, dtype=np.int64)

    eq, gt, lt = t_k == t_i, t_k > t_i, t_k < t_i          # ε_t = 0: equality is tested exactly (stamps)
    y_gt, y_eq, y_lt = y_k > y_i, y_k == y_i, y_k < y_i
    tie_won = y_eq & ((z_k < z_i) if ties == "lowest_id" else (z_k > z_i))   # rows 2 and 18
    snd_k, snd_i, snd_none = z_k == k, z_k == i, z_k == NONE
    snd_m = ~(snd_k | snd_i | snd_none)
    rcv_i, rcv_k, rcv_none = z_i == i, z_i == k, z_i == NONE
    rcv_other = ~(rcv_i | rcv_k | rcv_none)

    def cell(where: np.ndarray, number: int, what: int | np.ndarray) -> None:
        action[where] = np.broadcast_to(what, shape)[where]
        row[where] = number

    # -- sender thinks k (itself) -----------------------------------------------------------------------------
    own = snd_k & rcv_i                                        # rows 1-3 (remark, line 875)
    cell(own & y_gt, 1, OUTBID)
    cell(own & tie_won, 2, OUTBID)                             # the tie: lowest id; † as in row 1 (our reading)
    cell(own & ~y_gt & ~tie_won, 3, UPDATE_TIME)               # y_k < y_i, and the tie the receiver wins
    both = snd_k & rcv_k                                       # rows 4-6 (line 876)
    cell(both & gt, 4, UPDATE)
    cell(both & eq, 5, LEAVE_QUIET)
    cell(both & lt, 6, LEAVE_QUIET)
    third = snd_k & rcv_other                                  # rows 7-11 (line 877-879)
    cell(third & y_gt & ~lt, 7, UPDATE)
    cell(third & y_lt & ~gt, 8, LEAVE)
    cell(third & y_eq, 9, np.where(gt & (equal_bids == "trust_later"), UPDATE, LEAVE))
    cell(third & y_lt & gt, 10, UPDATE)
    cell(third & y_gt & lt, 11, UPDATE if row11 == "update" else LEAVE)
    cell(snd_k & rcv_none, 12, UPDATE)                         # row 12 (line 881)
    # -- sender thinks i (the receiver) -----------------------------------------------------------------------
    mine = snd_i & rcv_i                                       # row 13: cell (sink) and remark (line 882)
    cell(mine & eq, 13, LEAVE_QUIET)
    cell(mine & gt & y_eq, 13, ADOPT_TIME)
    cell(mine & ~eq & ~(gt & y_eq), 13, LEAVE_REFRESH)         # never adopt another's value of one's own bid
    cell(snd_i & rcv_k, 14, RESET_EMPTY)                       # row 14 (line 883)
    cell(snd_i & rcv_other, 15, {"leave_bump": LEAVE_REFRESH, "leave": LEAVE, "empty": RESET_EMPTY}[row15])
    cell(snd_i & rcv_none, 16, EMPTY)                          # row 16 (lines 885-887)
    # -- sender thinks m (a third agent) ----------------------------------------------------------------------
    outbid = snd_m & rcv_i                                     # rows 17-19 (line 889-891)
    cell(outbid & y_gt, 17, OUTBID)
    cell(outbid & tie_won, 18, OUTBID)
    cell(outbid & ~y_gt & ~tie_won, 19, UPDATE_TIME)
    cell(snd_m & rcv_k, 20, np.where(lt & row20_guard, LEAVE, UPDATE))      # row 20 (line 893)
    agree = snd_m & rcv_other & (z_i == z_k)                   # rows 21-23 (line 895)
    cell(agree & gt, 21, UPDATE)
    cell(agree & eq, 22, LEAVE_QUIET)
    cell(agree & lt, 23, LEAVE)
    differ = snd_m & rcv_other & (z_i != z_k)                  # rows 24-27 (line 897); y equal: the default
    cell(differ & y_gt & ~lt, 24, UPDATE)
    cell(differ & y_lt & ~gt, 25, LEAVE)
    cell(differ & y_lt & gt, 26, UPDATE)
    cell(differ & y_gt & lt, 27, LEAVE)
    cell(differ & y_eq & gt & (equal_bids == "trust_later"), DEFAULT_ROW, UPDATE)
    cell(snd_m & rcv_none, 28, np.where(lt & row28_guard, LEAVE, UPDATE))   # row 28 (lines 899-901)
    # -- sender thinks nobody ---------------------------------------------------------------------------------
    cell(snd_none & rcv_i, 29, LEAVE_REFRESH)                  # row 29 (line 903)
    cell(snd_none & rcv_k, 30, UPDATE)                         # row 30 (line 904): "propagation of dropped bids"
    cell(snd_none & rcv_other & gt, 31, UPDATE)                # row 31 (line 905); otherwise the default
    cell(snd_none & rcv_none & eq, 32, LEAVE_QUIET)            # "Both think none" (line 906)
    cell(snd_none & rcv_none & gt, 32, UPDATE)
    cell(snd_none & rcv_none & lt, 32, LEAVE)
    return action, row


def apply(action: np.ndarray, receiver: np.ndarray | int, now: int, z_i: np.ndarray, y_i: np.ndarray,
          t_i: np.ndarray, z_k: np.ndarray, y_k: np.ndarray, t_k: np.ndarray, refresh: str = "epsilon",
          outbid_time: str = "sender") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The receiver's new (z, y, t) after ``action`` at tick ``now``, and whether the task is rebroadcast.

    ``refresh`` is how far a winner moves its own time (``UPDATE_TIME``, ``LEAVE_REFRESH``): past t_kj by ε
    (``epsilon``, line 875) or to the current time (``now``, line 871); either only "if it is necessary to make it
    later" (line 891). ``outbid_time`` is the time an outbid receiver gives the winner's record (``OUTBID``):
    ``bump``, the † reading (later than its own losing time, line 875), or ``sender``, the sender's time as a plain
    update does (our option: the bump can outdate the winner's own later withdrawal, docs/decisions.md).
    """
    i = _ids(receiver, z_i)
    take = (action == UPDATE) | (action == OUTBID)
    empty = (action == RESET_EMPTY) | (action == EMPTY)
    z = np.where(take, z_k, np.where(empty, NONE, z_i))
    y = np.where(take, y_k, np.where(empty, 0.0, y_i))
    t = np.where(action == UPDATE, t_k, t_i)
    t = np.where(action == ADOPT_TIME, t_k, t)
    refreshed = (action == UPDATE_TIME) | (action == LEAVE_REFRESH)
    t = np.where(refreshed & (t_i <= t_k), later_than(t_k, i, now, refresh), t)
    if outbid_time == "bump":
        t = np.where(action == OUTBID, np.where(t_k > t_i, t_k, later_than(t_i, i, now, "epsilon")), t)
    else:
        t = np.where(action == OUTBID, t_k, t)
    current = stamp(now, i)                                    # the empty bid "with current time", later than t_kj
    t = np.where(empty, np.where(current > t_k, current, later_than(t_k, i, now, "epsilon")), t)
    return z, y, t, action != LEAVE_QUIET


def _ids(agent: np.ndarray | int, like: np.ndarray) -> np.ndarray:
    """Agent ids broadcastable against (…, M) records: a (…,) array gains the task axis."""
    agent = np.asarray(agent)
    return agent[..., None] if agent.ndim == np.ndim(like) - 1 and agent.ndim > 0 else agent
