"""The PettingZoo contract, determinism, bad input and rendering of ``taskalloc/TaskAlloc-v0``.

Every PettingZoo check runs with the default constructor arguments: ``max_cycles_test``, ``parallel_seed_test`` and
``state_test`` sample actions without the mask, which the default ``invalid_action="noop"`` turns into flagged
passes. PettingZoo 1.27's ``parallel_seed_test`` compares only one step, so ``test_long_runs_are_deterministic``
compares whole episodes.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import warnings

import numpy as np
import pettingzoo
import pytest
from gymnasium.utils.env_checker import data_equivalence
from helpers import agent, build, task
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
    state_test,
)

import taskalloc_env
from taskalloc.policies import CBGAPolicy
from taskalloc_env import InvalidActionError, TaskAllocEnv, taskalloc_v0
from taskalloc_env.observation import TASK_FEATURES

CONFIGS = {
    "small": {"n_agents": 3, "n_tasks": 5, "agents_per_task": [1, 2], "start_time_range": [0.0, 30.0]},
    "equipment": {"n_agents": 4, "n_tasks": 5, "agent_types": ["A", "B"],
                  "task_mix": [{"count": 2, "equipment": ["A"]}, {"count": 2, "equipment": ["A", "B"]},
                               {"count": 1, "agents": 1}]},
    "prerequisites": {"n_agents": 3, "n_tasks": 6, "agents_per_task": [1, 2],
                      "prerequisites": {"chains": 1, "length": 3}},
    "comm_range": {"n_agents": 5, "n_tasks": 5, "agents_per_task": [1, 2], "comm_range": 2.0,
                   "require_known_capacity": True},
    "every_step": {"n_agents": 3, "n_tasks": 5, "agents_per_task": [1, 2], "consensus": "every_step"},
    "task_quitting": {"n_agents": 4, "n_tasks": 5, "agents_per_task": 3, "task_quitting": True},
    # a task needing more agents than exist is infeasible, which is reported, not an error
    "infeasible_groups": {"n_agents": 2, "n_tasks": 3, "agents_per_task": [1, 3]},
    # pop-up tasks in the synchronous protocol, and the asynchronous protocol (one step = one tick) with pop-ups
    "sync_popups": {"n_agents": 3, "n_tasks": 5, "agents_per_task": [1, 2], "popup_tasks": 2, "popup_period": 3},
    "acbba": {"n_agents": 3, "n_tasks": 5, "agents_per_task": [1, 2], "consensus": "acbba"},
    "acbba_popups": {"n_agents": 4, "n_tasks": 6, "agents_per_task": [1, 2], "consensus": "acbba", "popup_tasks": 3,
                     "popup_period": 8, "popup_arrivals": "poisson", "message_loss": 0.1, "max_delay": 1,
                     "task_quitting": True},
    # late joiners enter env.agents mid-episode (join_at), synchronous and asynchronous
    "late_joiners": {"n_agents": 4, "n_tasks": 5, "agents_per_task": [1, 2], "join_at": {1: 2, 3: 4}},
    "acbba_joiners": {"n_agents": 4, "n_tasks": 5, "agents_per_task": 1, "consensus": "acbba", "join_at": {0: 3}},
}
CONFIG_IDS = list(CONFIGS)


@pytest.fixture(autouse=True)
def _quiet_api_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)     # Dict observation spaces make api_test warn (harmless)
        yield


@pytest.mark.parametrize("name", CONFIG_IDS)
def test_parallel_api(name):
    parallel_api_test(taskalloc_v0.parallel_env(**CONFIGS[name]), num_cycles=300)


@pytest.mark.parametrize("name", CONFIG_IDS)
def test_aec_api(name):
    api_test(taskalloc_v0.env(**CONFIGS[name]), num_cycles=300)


@pytest.mark.parametrize("name", CONFIG_IDS)
def test_seed_tests(name):
    kw = CONFIGS[name]
    parallel_seed_test(lambda: taskalloc_v0.parallel_env(**kw))
    seed_test(lambda: taskalloc_v0.env(**kw))


@pytest.mark.parametrize("name", CONFIG_IDS)
def test_state(name):
    kw = CONFIGS[name]
    state_test(taskalloc_v0.env(**kw), taskalloc_v0.parallel_env(**kw))


@pytest.mark.parametrize("name", [n if n == "small" else pytest.param(n, marks=pytest.mark.slow) for n in CONFIG_IDS])
def test_render(name, tmp_path):
    kw = CONFIGS[name]
    render_test(lambda render_mode: taskalloc_v0.env(render_mode=render_mode, render_path=tmp_path / "f.png", **kw))
    assert (tmp_path / "f.png").exists()


def _line_scenario():
    """6 agents on a line (D = 5): convergence needs 6 quiet rounds, so 4 steps can never end the episode early."""
    return build([agent(float(i)) for i in range(6)], [task(float(i) + 0.5, agents=2) for i in range(5)])


@pytest.mark.parametrize("kwargs", [
    pytest.param({"scenario": "default"}, id="default"),
    pytest.param({"scenario": _line_scenario(), "comm_range": 1.0}, id="line"),
    pytest.param({"scenario": _line_scenario(), "comm_range": 1.0, "consensus": "every_step"}, id="line-every-step"),
    pytest.param({"scenario": _line_scenario(), "comm_range": 1.0, "consensus": "acbba", "popup_tasks": 2},
                 id="line-acbba-popups"),
])
def test_max_cycles(kwargs):
    module = types.SimpleNamespace(
        parallel_env=functools.partial(taskalloc_v0.parallel_env, **kwargs),
        env=functools.partial(taskalloc_v0.env, **kwargs))
    max_cycles_test(module)


def test_registry_make():
    """Importing the package registers taskalloc/TaskAlloc-v0 for both APIs; keyword arguments pass through."""
    par = pettingzoo.make("parallel", taskalloc_env.ENV_ID, n_agents=3, n_tasks=4)
    assert isinstance(par.unwrapped, TaskAllocEnv)
    assert par.possible_agents == ["uav_0", "uav_1", "uav_2"]
    obs, _ = par.reset(seed=1)
    assert set(obs) == set(par.agents)
    aec = pettingzoo.make("aec", "taskalloc/TaskAlloc-v0", n_agents=3, n_tasks=4)
    aec.reset(seed=1)
    assert aec.agent_selection == "uav_0"
    assert aec.unwrapped.config.n_tasks == 4
    unversioned = pettingzoo.make("parallel", "taskalloc/TaskAlloc", n_agents=2, n_tasks=2)
    assert isinstance(unversioned.unwrapped, TaskAllocEnv)


def test_spaces_and_masks():
    """Discrete(1 + 2M): pass, bid on j, quit j; masks are int8, pass always allowed, quits only with quitting on."""
    env = TaskAllocEnv(n_agents=3, n_tasks=4, agents_per_task=2)
    obs, _ = env.reset(seed=0)
    assert env.action_space("uav_0").n == 1 + 2 * 4
    assert env.action_space("uav_0") is env.action_space("uav_0")
    for a in env.agents:
        mask = obs[a]["action_mask"]
        assert mask.dtype == np.int8 and mask.shape == (9,)
        assert mask[0] == 1 and not mask[5:].any()
        assert env.observation_space(a).contains(obs[a])


@pytest.mark.parametrize("name", CONFIG_IDS)
def test_observations_stay_in_their_space(name):
    """Every observation of a whole masked-random episode lies in the declared observation space."""
    trace, _ = _masked_random_episode(CONFIGS[name], seed=4)
    env = TaskAllocEnv(**CONFIGS[name])
    space = env.observation_space("uav_0")
    observations = [trace[0][0]] + [step[1] for step in trace[1:]]
    for step, obs in enumerate(observations):
        for a, o in obs.items():
            assert space.contains(o), f"step {step}: observation of {a} out of bounds: {_outside(env, o)}"


def _outside(env: TaskAllocEnv, o) -> str:
    box = env.observation_space("uav_0")["observation"]
    layout = env.observation_layout
    x = o["observation"]
    out = []
    for b in np.flatnonzero((x < box.low) | (x > box.high))[:4]:
        if b < layout.own_size:
            name = layout.own_names[b]
        else:
            task_id, feature = divmod(int(b) - layout.own_size, layout.task_size)
            name = f"task {task_id} {TASK_FEATURES[feature]}"
        out.append(f"{name} = {x[b]:.3g} not in [{box.low[b]:.3g}, {box.high[b]:.3g}]")
    return "; ".join(out)


# -- determinism --------------------------------------------------------------------------------------------------
def _masked_random_episode(kw: dict, seed: int):
    env = TaskAllocEnv(**kw)
    rng = np.random.default_rng(seed + 1000)
    obs, infos = env.reset(seed=seed)
    trace = [(obs, infos)]
    while env.agents:
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(actions)
        trace.append((actions, obs, rew, term, trunc, infos))
    return trace, env.evaluate()


@pytest.mark.parametrize("name", [*CONFIG_IDS, "default"])
def test_long_runs_are_deterministic(name):
    """Two whole episodes with the same seeds agree step by step: observations, masks, rewards, flags and infos."""
    kw = {**CONFIGS.get(name, {}), "max_cycles": 400}
    for seed in (0, 1):
        first, alloc1 = _masked_random_episode(kw, seed)
        second, alloc2 = _masked_random_episode(kw, seed)
        assert len(first) == len(second)
        for step, (a, b) in enumerate(zip(first, second)):
            assert data_equivalence(a, b), f"episodes diverge at step {step}"
        assert alloc1 == alloc2
    other, _ = _masked_random_episode(kw, 2)
    assert not data_equivalence(first[0][0], other[0][0]), "a different seed should draw a different instance"


def test_reset_with_the_same_seed_replays_the_instance():
    env = TaskAllocEnv(n_agents=3, n_tasks=4)
    obs1, _ = env.reset(seed=5)
    env.step({a: 0 for a in env.agents})
    obs2, _ = env.reset(seed=5)
    assert data_equivalence(obs1, obs2)


# -- episode return (the team score, thesis §5.3.1) --------------------------------------------------------------
@pytest.mark.parametrize("scale", ["total_reward", "raw", 100.0])
def test_episode_return_equals_evaluate_score(scale):
    env = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=[1, 2], reward_scale=scale)
    rng = np.random.default_rng(3)
    obs, _ = env.reset(seed=3)
    total = 0.0
    while env.agents:
        obs, rew, *_ = env.step({a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents})
        total += rew["uav_0"]
    assert total * env.reward_scale == pytest.approx(env.evaluate().score, abs=1e-6)


def test_round_bound_truncates():
    """A run that has not converged by our round bound T_max (``max_rounds``) is truncated, not terminated."""
    e = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=2, max_rounds=1)
    obs, infos = e.reset(seed=0)
    policy = CBGAPolicy()
    policy.start(e)
    while e.agents:
        obs, _, term, trunc, infos = e.step(policy.act(obs, infos))
    assert all(trunc.values()) and not any(term.values())
    assert e.protocol.round == 1 and not e.evaluate().converged


@pytest.mark.parametrize("consensus", ["sync", "every_step"])
def test_the_step_bound_never_cuts_a_round_the_round_bound_allows(consensus):
    """``step_bound`` = T_max · (M + 1)² (sync) or T_max (one round per step), the limit that leaves the round bound
    alone (``max_cycles=env.step_bound``): no sync round takes more than (M + 1)² steps, even under a random policy
    that quits and re-bids (``quit_block=none`` lets a quit task be re-bid; a quit drops what follows it, which may
    be bid again). The default ``max_cycles`` is tests/test_rewards.py's."""
    from taskalloc.policies import make_policy

    longest = 0
    for seed in range(12):
        e = TaskAllocEnv(n_agents=4, n_tasks=5, agents_per_task=[1, 2, 3], task_quitting=True, delta=0,
                         quit_block="none", consensus=consensus)
        per_round = (e.config.n_tasks + 1) ** 2 if consensus == "sync" else 1
        assert e.step_bound == e.unwrapped._max_rounds * per_round
        e.max_cycles = e.step_bound
        policy = make_policy("random")
        obs, infos = e.reset(seed=seed)
        policy.start(e, seed=seed)
        steps, last_round = 0, 0
        while e.agents:
            obs, *_, infos = e.step(policy.act(obs, infos))
            steps += 1
            if e.protocol.round != last_round:
                longest, steps, last_round = max(longest, steps), 0, e.protocol.round
        assert longest <= per_round
    assert consensus == "every_step" or longest > 3      # the random policy does use several steps per round


# -- bad input ----------------------------------------------------------------------------------------------------
@pytest.fixture
def env():
    e = TaskAllocEnv(n_agents=3, n_tasks=4, agents_per_task=[1, 2], invalid_action="raise")
    e.reset(seed=0)
    return e


def _blocked_action(env) -> tuple[str, int]:
    """An agent and an action its mask forbids (a quit: task quitting is off)."""
    return "uav_0", 1 + env.config.n_tasks


def test_action_outside_the_mask_raises(env):
    agent_id, action = _blocked_action(env)
    actions = {a: 0 for a in env.agents}
    actions[agent_id] = action
    with pytest.raises(InvalidActionError, match=r"uav_0.*not allowed by its mask"):
        env.step(actions)


@pytest.mark.parametrize("action", [-1, 9, 1.5, "bid", None])
def test_action_outside_the_space_raises(env, action):
    actions = {a: 0 for a in env.agents}
    actions["uav_1"] = action
    with pytest.raises(InvalidActionError, match="uav_1"):
        env.step(actions)


def test_missing_agent_raises(env):
    with pytest.raises(InvalidActionError, match="uav_2"):
        env.step({"uav_0": 0, "uav_1": 0})


@pytest.mark.parametrize("key", ["uav_7", "drone_0"])
def test_unknown_agent_raises(env, key):
    with pytest.raises(InvalidActionError, match=key):
        env.step({**{a: 0 for a in env.agents}, key: 0})


def test_non_dict_actions_raise(env):
    with pytest.raises(InvalidActionError):
        env.step([0, 0, 0])


def test_step_after_the_end_raises():
    e = TaskAllocEnv(n_agents=2, n_tasks=2, max_cycles=1, invalid_action="raise")
    e.reset(seed=0)
    e.step({a: 0 for a in e.agents})
    assert e.agents == []
    with pytest.raises(InvalidActionError, match="reset"):
        e.step({"uav_0": 0, "uav_1": 0})


def test_invalid_actions_become_flagged_passes_with_noop():
    """The default ``noop``: a bad action becomes a pass, flagged in infos and counted in ``evaluate()``."""
    kw = {"n_agents": 3, "n_tasks": 4, "agents_per_task": [1, 2]}
    strict = TaskAllocEnv(invalid_action="raise", **kw)
    lenient = TaskAllocEnv(**kw)
    strict.reset(seed=0)
    lenient.reset(seed=0)
    bad = {"uav_0": 1 + 4, "uav_1": 0}          # uav_0: forbidden quit; uav_2: missing
    _, _, _, _, infos = lenient.step(bad)
    _, _, _, _, ref_infos = strict.step({"uav_0": 0, "uav_1": 0, "uav_2": 0})
    assert infos["uav_0"]["invalid_action"] and infos["uav_2"]["invalid_action"]
    assert not infos["uav_1"]["invalid_action"]
    assert "not allowed by its mask" in lenient.invalid_action_reasons["uav_0"]
    assert "no action given" in lenient.invalid_action_reasons["uav_2"]
    assert infos["uav_0"]["round"] == 1, "everyone passed, so the round ended"
    for a in ("uav_0", "uav_1", "uav_2"):         # the step had the same effect as passing
        assert infos[a]["round"] == ref_infos[a]["round"]
        assert infos[a]["score"] == ref_infos[a]["score"]
    assert lenient.protocol.knowledge.groups == strict.protocol.knowledge.groups
    assert lenient.evaluate().counters.invalid_actions == 2 and strict.evaluate().counters.invalid_actions == 0
    _, _, _, _, infos = lenient.step({"uav_0": float("inf"), "uav_1": np.array(0), "uav_2": np.int64(0)})
    assert infos["uav_0"]["invalid_action"] and "not an integer" in lenient.invalid_action_reasons["uav_0"]
    assert not infos["uav_1"]["invalid_action"] and not infos["uav_2"]["invalid_action"]


def test_step_before_reset_is_a_clear_error():
    with pytest.raises(InvalidActionError, match=r"before reset\(\)"):
        TaskAllocEnv(n_agents=2, n_tasks=2).step({"uav_0": 0, "uav_1": 0})


def test_infos_carry_the_action_mask_on_request():
    """AgileRL reads the mask from infos; TorchRL 0.14 fails on a mask in both places, so it is opt-in."""
    assert "action_mask" not in TaskAllocEnv(n_agents=3, n_tasks=4).reset(seed=1)[1]["uav_0"]
    e = TaskAllocEnv(n_agents=3, n_tasks=4, mask_in_infos=True)
    obs, infos = e.reset(seed=1)
    for name in e.agents:
        np.testing.assert_array_equal(infos[name]["action_mask"], obs[name]["action_mask"])
        assert infos[name]["action_mask"].dtype == np.int8
    assert obs["uav_0"]["observation"].dtype == np.float32 and e.state().dtype == np.float32
    wide = TaskAllocEnv(n_agents=3, n_tasks=4, dtype="float64")
    assert wide.reset(seed=1)[0]["uav_0"]["observation"].dtype == np.float64


def test_noop_step_after_the_end_is_harmless():
    e = TaskAllocEnv(n_agents=2, n_tasks=2, max_cycles=1)
    e.reset(seed=0)
    e.step({a: 0 for a in e.agents})
    result = e.step({"uav_0": 0})
    assert all(part == {} for part in result)


def test_passed_agent_may_only_pass_until_the_round_ends():
    """In the synchronous protocol a round ends when every agent has passed; until then a passed agent may only pass."""
    e = TaskAllocEnv(n_agents=3, n_tasks=4, agents_per_task=1, invalid_action="raise")
    obs, _ = e.reset(seed=0)
    bids = {a: np.flatnonzero(obs[a]["action_mask"][1:5]) + 1 for a in e.agents}
    bidder, waiter = "uav_0", "uav_1"
    assert bids[bidder].size and bids[waiter].size
    obs, _, _, _, infos = e.step({"uav_0": int(bids[bidder][0]), "uav_1": 0, "uav_2": 0})
    assert infos[waiter]["passed"] and not infos[bidder]["passed"]
    assert obs[waiter]["action_mask"].tolist() == [1] + [0] * 8
    with pytest.raises(InvalidActionError, match="passed"):
        e.step({"uav_0": 0, "uav_1": int(bids[waiter][0]), "uav_2": 0})


@pytest.mark.parametrize("kwargs, field", [
    ({"invalid_action": "ignore"}, "invalid_action"),
    ({"render_mode": "video"}, "render_mode"),
    ({"max_cycles": 0}, "max_cycles"),
    ({"reward_scale": 0.0}, "reward_scale"),
])
def test_bad_constructor_arguments(kwargs, field):
    with pytest.raises(ValueError, match=field):
        TaskAllocEnv(n_agents=2, n_tasks=2, **kwargs)


def test_render_modes_return_types():
    for mode, check in (("ansi", lambda r: isinstance(r, str) and "uav_0" in r),
                        ("rgb_array", lambda r: r.dtype == np.uint8 and r.ndim == 3 and r.shape[2] == 3)):
        e = TaskAllocEnv(n_agents=3, n_tasks=4, render_mode=mode)
        e.reset(seed=0)
        assert check(e.render())
        e.close()
    e = TaskAllocEnv(n_agents=3, n_tasks=4)
    e.reset(seed=0)
    with pytest.raises(ValueError, match="render_mode"):
        e.render()


def test_the_aec_view_refuses_a_bad_action_when_it_is_given():
    """Under ``raise`` the AEC view names the agent at its own turn, not when the last agent of the turn acts."""
    env = taskalloc_v0.env(n_agents=3, n_tasks=4, invalid_action="raise")
    env.reset(seed=0)
    first = env.agent_selection
    with pytest.raises(InvalidActionError, match=first):
        env.step(1 + 4)                        # a quit; task quitting is off
    lenient = taskalloc_v0.env(n_agents=3, n_tasks=4)
    lenient.reset(seed=0)
    lenient.step(1 + 4)                        # noop: accepted now, turned into a flagged pass with the turn
    assert lenient.agent_selection != first


def test_the_scenario_arrays_are_read_only():
    """The instance the protocol plans on cannot be edited in place through ``env.scenario`` (a replaced scenario
    is a new, checked one); every array field refuses a write."""
    env = TaskAllocEnv("default")
    env.reset(seed=0)
    scenario = env.unwrapped.scenario
    arrays = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(scenario)
              if isinstance(getattr(scenario, f.name), np.ndarray)}
    assert {"agent_pos", "task_reward", "task_prereqs"} <= set(arrays)
    for array in arrays.values():
        with pytest.raises(ValueError, match="read-only"):
            array[...] = array
