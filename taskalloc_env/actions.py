"""The action codec: one integer per decision of the bundle phase, ``Discrete(1 + 2M)``.

    0            pass
    1 … M        bid on task j = a − 1          (thesis §3.2.2, Alg 5: a bid at the agent's best path slot)
    M + 1 … 2M   quit task j = a − M − 1        (thesis §5.2.2, Alg 9; only with ``task_quitting``)

The numbering is ours. Every module that reads or writes an action or a column of an action mask goes through these
names, so the layout is defined here only.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np

PASS = 0


class ActionKind(IntEnum):
    """What an action does."""

    PASS = 0
    BID = 1
    QUIT = 2


_PASS, _BID, _QUIT = ActionKind.PASS, ActionKind.BID, ActionKind.QUIT     # an enum member lookup costs a call


def n_actions(n_tasks: int) -> int:
    """The size of the action space (and of a mask row): 1 + 2M."""
    return 1 + 2 * n_tasks


def encode_bid(task: int | np.ndarray) -> int | np.ndarray:
    """The action that bids on ``task`` (an int or an array of task ids)."""
    return 1 + task


def encode_quit(task: int | np.ndarray, n_tasks: int) -> int | np.ndarray:
    """The action that quits ``task`` (an int or an array of task ids)."""
    return 1 + n_tasks + task


def bid_columns(n_tasks: int) -> slice:
    """The mask columns (or logits) of the bids, task 0 first."""
    return slice(1, 1 + n_tasks)


def quit_columns(n_tasks: int) -> slice:
    """The mask columns (or logits) of the quits, task 0 first."""
    return slice(1 + n_tasks, 1 + 2 * n_tasks)


def decode(action: int, n_tasks: int) -> tuple[ActionKind, int]:
    """(kind, task) of a valid action ``0 ≤ action < 1 + 2M``; the task of a pass is −1."""
    if action == PASS:
        return _PASS, -1
    if action <= n_tasks:
        return _BID, action - 1
    return _QUIT, action - n_tasks - 1


def decode_array(actions: np.ndarray, n_tasks: int) -> tuple[np.ndarray, np.ndarray]:
    """``decode`` over an integer array: the kinds (``ActionKind`` values) and tasks (−1 for a pass), each of the
    array's shape."""
    actions = np.asarray(actions, dtype=np.int64)
    kinds = np.where(actions == PASS, ActionKind.PASS, np.where(actions <= n_tasks, ActionKind.BID, ActionKind.QUIT))
    tasks = np.where(actions == PASS, -1, np.where(actions <= n_tasks, actions - 1, actions - n_tasks - 1))
    return kinds.astype(np.int64), tasks.astype(np.int64)


def describe(action: int, n_tasks: int) -> str:
    """``pass``, ``bid on task j`` or ``quit task j``."""
    kind, task = decode(action, n_tasks)
    return "pass" if kind is ActionKind.PASS else f"{'bid on' if kind is ActionKind.BID else 'quit'} task {task}"
