"""The action codec: one integer per decision of the bundle phase, ``Discrete(1 + 2M)``, or ``Discrete(1 + 3M)`` with
``release_actions``.

    0              pass
    1 … M          bid on task j = a − 1          (thesis §3.2.2, Alg 5: a bid at the agent's best path slot)
    M + 1 … 2M     quit task j = a − M − 1        (thesis §5.2.2, Alg 9; only with ``task_quitting``)
    2M + 1 … 3M    release task j = a − 2M − 1    (only with ``release_actions``: drop j and what follows it in the
                                                   bundle, as an outbid release does, thesis §2.2.4; ours)

The numbering is ours. Every module that reads or writes an action or a column of an action mask goes through these
names, so the layout is defined here only. Without ``release_actions`` the release columns do not exist, and the
layout is the first three rows exactly.
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
    RELEASE = 3


_PASS, _BID, _QUIT, _RELEASE = ActionKind.PASS, ActionKind.BID, ActionKind.QUIT, ActionKind.RELEASE   # lookups cost


def n_actions(n_tasks: int, release: bool = False) -> int:
    """The size of the action space (and of a mask row): 1 + 2M, or 1 + 3M with release actions."""
    return 1 + (3 if release else 2) * n_tasks


def encode_bid(task: int | np.ndarray) -> int | np.ndarray:
    """The action that bids on ``task`` (an int or an array of task ids)."""
    return 1 + task


def encode_quit(task: int | np.ndarray, n_tasks: int) -> int | np.ndarray:
    """The action that quits ``task`` (an int or an array of task ids)."""
    return 1 + n_tasks + task


def encode_release(task: int | np.ndarray, n_tasks: int) -> int | np.ndarray:
    """The action that releases ``task`` (an int or an array of task ids; with ``release_actions`` only)."""
    return 1 + 2 * n_tasks + task


def bid_columns(n_tasks: int) -> slice:
    """The mask columns (or logits) of the bids, task 0 first."""
    return slice(1, 1 + n_tasks)


def quit_columns(n_tasks: int) -> slice:
    """The mask columns (or logits) of the quits, task 0 first."""
    return slice(1 + n_tasks, 1 + 2 * n_tasks)


def release_columns(n_tasks: int) -> slice:
    """The mask columns (or logits) of the releases, task 0 first (with ``release_actions`` only)."""
    return slice(1 + 2 * n_tasks, 1 + 3 * n_tasks)


def decode(action: int, n_tasks: int) -> tuple[ActionKind, int]:
    """(kind, task) of a valid action ``0 ≤ action < n_actions``; the task of a pass is −1. An action above 2M is a
    release (it exists only in the layout with ``release_actions``)."""
    if action == PASS:
        return _PASS, -1
    if action <= n_tasks:
        return _BID, action - 1
    if action <= 2 * n_tasks:
        return _QUIT, action - n_tasks - 1
    return _RELEASE, action - 2 * n_tasks - 1


def decode_array(actions: np.ndarray, n_tasks: int) -> tuple[np.ndarray, np.ndarray]:
    """``decode`` over an integer array: the kinds (``ActionKind`` values) and tasks (−1 for a pass), each of the
    array's shape."""
    actions = np.asarray(actions, dtype=np.int64)
    kinds = np.select([actions == PASS, actions <= n_tasks, actions <= 2 * n_tasks],
                      [ActionKind.PASS, ActionKind.BID, ActionKind.QUIT], ActionKind.RELEASE)
    tasks = np.where(actions == PASS, -1, (actions - 1) % max(n_tasks, 1))
    return kinds.astype(np.int64), tasks.astype(np.int64)


_VERBS = {_BID: "bid on", _QUIT: "quit", _RELEASE: "release"}


def describe(action: int, n_tasks: int) -> str:
    """``pass``, ``bid on task j``, ``quit task j`` or ``release task j``."""
    kind, task = decode(action, n_tasks)
    return "pass" if kind is ActionKind.PASS else f"{_VERBS[kind]} task {task}"
