"""The eight symmetries of a square floor, acting on observations (ours; not in the sources).

``taskalloc_env.scenario.generate`` draws agents uniformly on the floor [0, W] × [0, D] and tasks uniformly above
it; every score, bid and time of the problem depends on positions only through distances (thesis (3.2)–(3.5)).
So on a square floor (W = D) a mirror or quarter turn of an instance is an instance as likely as the first, with
the same allocation turned with it. In an observation only four kinds of column move: the agent's own ``x`` and
``y`` (÷ the arena, so in [0, 1]) and each task's ``dx`` and ``dy``; every other column is a distance, time, bid,
flag or count, and stays. Each symmetry is thus a column permutation, a sign and a shift:
``turned = obs[:, permutation] · sign + shift``. ``research.training.planner`` draws one per state (``augment``) and
``research.policies.round_zero`` averages its estimate over all eight (``symmetric``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np


def square_symmetries(own_names: Sequence[str], task_names: Sequence[str], n_tasks: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(8, D) column permutations, signs and shifts of the observation (own features, then ``n_tasks`` blocks of
    ``task_names``), one row per symmetry: swap x and y or not, then mirror x or not, then mirror y or not.
    Row 0 is the identity."""
    own_size, task_size = len(own_names), len(task_names)
    size = own_size + n_tasks * task_size
    blocks = own_size + task_size * np.arange(n_tasks)
    own_x, own_y = own_names.index("x"), own_names.index("y")
    dx, dy = blocks + task_names.index("dx"), blocks + task_names.index("dy")
    permutations, signs, shifts = [], [], []
    for swap, mirror_x, mirror_y in itertools.product((False, True), repeat=3):
        permutation, sign, shift = np.arange(size), np.ones(size), np.zeros(size)
        if swap:
            permutation[[own_x, own_y]] = own_y, own_x
            permutation[dx], permutation[dy] = dy, dx
        for mirrored, own, task in ((mirror_x, own_x, dx), (mirror_y, own_y, dy)):
            if mirrored:                 # x ÷ W ↦ 1 − x ÷ W on the floor [0, W]; a relative dx ↦ −dx
                sign[own], shift[own], sign[task] = -1.0, 1.0, -1.0
        permutations.append(permutation)
        signs.append(sign)
        shifts.append(shift)
    return np.stack(permutations), np.stack(signs), np.stack(shifts)


def is_square(arena: Sequence[float]) -> bool:
    """The floor of ``arena`` (W, D, H) is square, so all eight symmetries map the generator onto itself."""
    return bool(np.isclose(arena[0], arena[1]))
