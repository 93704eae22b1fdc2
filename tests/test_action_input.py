"""What the env takes as an action: exactly what ``action_space.contains`` accepts (a bool excepted), each refusal a
one-line ``InvalidActionError`` under ``raise`` and a flagged, counted pass under ``noop``; an action for an agent that
is not live is one refusal of its own key; a bad ``render_path`` is refused at construction."""

from __future__ import annotations

from decimal import Decimal

import numpy as np
import pytest

from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, InvalidActionError

KW = {"n_agents": 3, "n_tasks": 4, "agents_per_task": 1}
N_ACTIONS = 1 + 2 * KW["n_tasks"]
# (label, value): integers, NumPy integers of every kind, 0-d arrays, and what only looks like an integer
CANDIDATES = [
    ("int 0", 0), ("int 1", 1), ("np.int64", np.int64(1)), ("np.int8", np.int8(1)), ("np.uint8", np.uint8(1)),
    ("np.uint64", np.uint64(1)), ("0-d int array", np.array(1)), ("0-d int32 array", np.array(1, dtype=np.int32)),
    ("0-d uint64 array", np.array(1, dtype=np.uint64)), ("True", True), ("False", False), ("np.bool_", np.bool_(True)),
    ("float", 1.0), ("np.float64", np.float64(1.0)), ("Decimal", Decimal(1)), ("(1, 1) array", np.array([[1]])),
    ("(1,) array", np.array([1])), ("0-d float array", np.array(1.0)), ("str", "1"), ("None", None),
    ("negative", -1), ("too large", N_ACTIONS), ("huge", 10**30), ("list", [1]),
]


def fresh(mode: str) -> TaskAllocEnv:
    env = TaskAllocEnv(invalid_action=mode, **KW)
    env.reset(seed=0)
    return env


def contained(value) -> bool:
    """What the env should accept: ``Discrete.contains``, less Python's bools (ours: a flag is never an action)."""
    return TaskAllocEnv(**KW).action_space("uav_0").contains(value) and not isinstance(value, bool)


@pytest.mark.parametrize(("label", "value"), CANDIDATES, ids=[c[0] for c in CANDIDATES])
def test_an_action_is_taken_exactly_when_the_action_space_contains_it(label, value):
    """uav_0's mask allows every bid at the start (agents_per_task 1, no prerequisites): a contained value is taken
    as that action; anything else raises one line under ``raise`` and is a flagged, counted pass under ``noop``."""
    strict, lenient = fresh("raise"), fresh("noop")
    assert strict.validate_action("uav_0", 1) == 1, "the bid on task 0 is allowed"
    actions = {"uav_0": value, "uav_1": 0, "uav_2": 0}
    if contained(value):
        assert fresh("raise").validate_action("uav_0", value) == int(value)
        strict.step(actions)
        _, _, _, _, infos = lenient.step(actions)
        assert not infos["uav_0"]["invalid_action"]
        assert strict.protocol.knowledge.bundles[0] == ([int(value) - 1] if int(value) > 0 else [])
        return
    with pytest.raises(InvalidActionError):
        fresh("raise").validate_action("uav_0", value)
    with pytest.raises(InvalidActionError) as raised:
        strict.step(actions)
    message = str(raised.value)
    assert "\n" not in message and "uav_0" in message and len(message) < 300
    assert strict.protocol.knowledge.bundles[0] == [], "nothing was applied"
    _, _, _, _, infos = lenient.step(actions)
    assert infos["uav_0"]["invalid_action"] and not infos["uav_1"]["invalid_action"]
    assert lenient.protocol.knowledge.bundles[0] == [], "the refused action became a pass"
    assert lenient.evaluate().counters.invalid_actions == 1


def test_the_table_covers_both_answers():
    accepted = {label for label, value in CANDIDATES if contained(value)}
    assert {"int 1", "np.int64", "np.uint8", "0-d int array"} <= accepted
    assert not accepted & {"True", "np.bool_", "float", "Decimal", "(1, 1) array", "np.uint64", "huge"}


def test_an_action_for_an_agent_that_is_not_live_is_one_refusal_of_its_own():
    """Under ``noop`` the stray key is flagged and counted once; the live agents' actions are taken, none flagged.
    Under ``raise`` the error names the key."""
    env = fresh("noop")
    _, _, _, _, infos = env.step({"uav_0": 1, "uav_1": 0, "uav_2": 0, "drone_9": 0})
    assert not any(info["invalid_action"] for info in infos.values())
    assert set(env.invalid_action_reasons) == {"drone_9"}
    assert env.evaluate().counters.invalid_actions == 1
    assert env.protocol.knowledge.bundles[0] == [0], "uav_0's bid was taken"
    with pytest.raises(InvalidActionError, match="drone_9"):
        fresh("raise").step({"uav_0": 1, "uav_1": 0, "uav_2": 0, "drone_9": 0})


@pytest.mark.parametrize(("path", "match"), [("missing_dir/f.png", "does not exist"), (".", "is a directory"),
                                              ("f.notaformat", "matplotlib saves")])
def test_a_bad_render_path_is_refused_at_construction(tmp_path, path, match):
    with pytest.raises(ConfigError, match=match):
        TaskAllocEnv(render_mode="human", render_path=tmp_path / path, **KW)


def test_a_good_render_path_is_written_at_the_end_of_the_episode(tmp_path):
    env = TaskAllocEnv(render_mode="human", render_path=tmp_path / "allocation.png", max_cycles=2, **KW)
    env.reset(seed=0)
    while env.agents:
        env.step({a: 0 for a in env.agents})
    assert (tmp_path / "allocation.png").stat().st_size > 0
