"""``research.policies.symmetry``: a mirror or quarter turn of an instance on a square floor turns its observations the
way ``square_symmetries`` says, and leaves the exact optimum's allocation and score as they were."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from research.policies.local_plan import SOLVERS
from research.policies.symmetry import is_square, square_symmetries
from taskalloc_env import TaskAllocEnv

CASES = [(swap, mirror_x, mirror_y) for swap in (False, True) for mirror_x in (False, True)
         for mirror_y in (False, True)]


def turned(positions: np.ndarray, width: float, swap: bool, mirror_x: bool, mirror_y: bool) -> np.ndarray:
    """Positions (K, 3) on the floor [0, W]²: swap x and y, then mirror x, then mirror y (``square_symmetries``)."""
    out = positions[:, [1, 0, 2]].copy() if swap else positions.copy()
    for axis, mirrored in ((0, mirror_x), (1, mirror_y)):
        if mirrored:
            out[:, axis] = width - out[:, axis]
    return out


@pytest.mark.parametrize("team", [False, True])
def test_each_symmetry_of_the_instance_is_the_same_symmetry_of_every_observation(team):
    env = TaskAllocEnv("train_small", team_features=team, task_quitting=True, delta=1)
    layout = env.observation_layout
    permutations, signs, shifts = square_symmetries(layout.own_names, layout.task_names, layout.n_tasks)
    assert len({p.tobytes() + s.tobytes() + t.tobytes() for p, s, t in zip(permutations, signs, shifts)}) == 8
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        scenario = env.scenario
        first = np.stack([obs[a]["observation"] for a in env.possible_agents]).astype(np.float64)
        width = scenario.arena[0]
        for k, case in enumerate(CASES):
            moved = dataclasses.replace(scenario, agent_pos=turned(scenario.agent_pos, width, *case),
                                        task_pos=turned(scenario.task_pos, width, *case))
            other = TaskAllocEnv(moved, team_features=team, task_quitting=True, delta=1)
            obs2, _ = other.reset(seed=seed)
            second = np.stack([obs2[a]["observation"] for a in other.possible_agents])
            np.testing.assert_allclose(first[:, permutations[k]] * signs[k] + shifts[k], second, atol=1e-6)
            if seed == 0:
                assert SOLVERS["exact"](moved, other.config).paths == SOLVERS["exact"](scenario, env.config).paths


def test_row_0_is_the_identity_and_only_positions_move():
    env = TaskAllocEnv("train_small")
    layout = env.observation_layout
    permutations, signs, shifts = square_symmetries(layout.own_names, layout.task_names, layout.n_tasks)
    np.testing.assert_array_equal(permutations[0], np.arange(layout.size))
    assert (signs[0] == 1).all() and (shifts[0] == 0).all()
    moving = {layout.own_names.index("x"), layout.own_names.index("y")} | {
        layout.own_size + j * layout.task_size + layout.task_column(name)
        for j in range(layout.n_tasks) for name in ("dx", "dy")}
    changed = {c for c in range(layout.size)
               if ((permutations[:, c] != c) | (signs[:, c] != 1) | (shifts[:, c] != 0)).any()}
    assert changed == moving


def test_only_a_square_floor_is_square():
    assert is_square((5.0, 5.0, 2.0)) and not is_square((5.0, 4.0, 2.0))
