"""The batched environment (``taskalloc_env.vector``): instance k is exactly a single env seeded ``seed + k``.

The equality property drives K single envs and the batch with the same joint actions, chosen by a policy from the
single envs' own observations (random masked, CBGABI, a committed learned policy; now and then an action outside the
mask), over random scenarios and options (both synchronous consensus modes and the asynchronous one; perfect, lossy,
bursty, fading and delayed links; pop-up tasks; release actions under every guard), across autoresets, and compares
observations, masks, rewards, flags, infos, states and the allocations with their counters byte for byte, on both
engines (``arrays``: the compiled step over the instance axis, within its scope; ``instances``: each env in turn).
Then the autoreset modes, seeding, the choice of engine and bad input.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_properties import scenario_config

import taskalloc_env
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv, kernels
from taskalloc_env.errors import ConfigError, InvalidActionError
from taskalloc_env.vector import INFO_KEYS, TaskAllocVectorEnv
from taskalloc_env.vector_arrays import ArrayBatch

K = 3


@st.composite
def batch_options(draw) -> dict:
    kw = draw(scenario_config(small=True))
    network = draw(st.sampled_from(["perfect", "lossy", "bursty", "correlated", "fading", "delay", "range"]))
    if network == "lossy":
        kw["message_loss"] = draw(st.sampled_from([0.1, 0.4]))
    elif network == "bursty":
        kw["loss_model"] = "gilbert_elliott"
    elif network == "correlated":
        kw.update(loss_model="gilbert_elliott_rho", message_loss=0.3)
    elif network == "fading":
        kw["loss_model"] = "rayleigh"
    elif network == "delay":
        kw["max_delay"] = draw(st.integers(1, 2))
    elif network == "range":
        kw["comm_range"] = draw(st.floats(0.5, 4.0))
    if draw(st.integers(0, 5)) == 0:
        kw["consensus"] = "acbba"
    if draw(st.integers(0, 4)) == 0 and kw["n_tasks"] >= 3:
        kw["popup_tasks"] = 1
    if draw(st.integers(0, 4)) == 0:
        kw["release_actions"] = True
    return kw


@st.composite
def arrays_options(draw) -> dict:
    """Options inside the arrays engine's scope: both synchronous modes, perfect or lossy links, limited range."""
    kw = draw(scenario_config(small=True))
    network = draw(st.sampled_from(["perfect", "lossy", "range", "lossy_range"]))
    if network.startswith("lossy"):
        kw["message_loss"] = draw(st.sampled_from([0.1, 0.4]))
    if network.endswith("range"):
        kw["comm_range"] = draw(st.floats(0.5, 4.0))
    kw["task_quitting"] = draw(st.booleans())
    if draw(st.integers(0, 2)) == 0:
        kw.update(release_actions=True, release_guard=draw(st.sampled_from(["none", "exchange", "once"])))
    return kw


def random_masked(rng: np.random.Generator, obs: dict, slip: float) -> dict:
    """A random allowed action per agent; with probability ``slip`` a random action that may be outside the mask."""
    actions = {}
    for agent, o in obs.items():
        mask = o["action_mask"]
        if rng.random() < slip:
            actions[agent] = int(rng.integers(len(mask)))
        else:
            actions[agent] = int(rng.choice(np.flatnonzero(mask)))
    return actions


class Driver:
    """K single envs seeded seed + k, each played by its own policy, and the joint actions they choose."""

    def __init__(self, kw: dict, policy_name: str, seed: int, slip: float) -> None:
        self.envs = [TaskAllocEnv(**kw) for _ in range(K)]
        self.policy_name, self.slip = policy_name, slip
        self.rng = np.random.default_rng(seed)
        self.policies = [make_policy(policy_name) if policy_name != "random" else None for _ in range(K)]
        self.obs, self.infos = [], []
        for k, env in enumerate(self.envs):
            o, i = env.reset(seed=seed + k)
            self._start(k, seed + k)
            self.obs.append(o), self.infos.append(i)

    def _start(self, k: int, seed: int | None) -> None:
        if self.policies[k] is not None:
            self.policies[k].start(self.envs[k], seed)

    def actions(self) -> np.ndarray:
        joint = np.zeros((K, len(self.envs[0].possible_agents)), dtype=np.int64)
        for k, env in enumerate(self.envs):
            if not env.agents:
                continue                    # the batch restarts this instance and ignores its actions
            if self.policies[k] is None or self.rng.random() < self.slip:
                chosen = random_masked(self.rng, self.obs[k], self.slip)
            else:
                chosen = self.policies[k].act(self.obs[k], self.infos[k])
            joint[k] = [chosen[a] for a in env.possible_agents]
        return joint

    def step(self, joint: np.ndarray) -> list[tuple]:
        """Each env's step (or, after its episode ended, its next episode's start), as the batch reports it."""
        out = []
        for k, env in enumerate(self.envs):
            if not env.agents:
                o, i = env.reset()
                self._start(k, None)
                self.obs[k], self.infos[k] = o, i
                out.append((o, None, False, False, i, 0))
                continue
            o, r, te, tr, i = env.step(dict(zip(env.possible_agents, joint[k].tolist())))
            self.obs[k], self.infos[k] = o, i
            agent = env.possible_agents[0]
            flagged = sum(info["invalid_action"] for info in i.values())
            out.append((o, r[agent], te[agent], tr[agent], i, flagged))
        return out


def check_instance(k: int, env: TaskAllocEnv, single: tuple, batch: tuple) -> None:
    """Instance k of the batch's outputs equals the single env's, byte for byte."""
    o, reward, terminated, truncated, infos, flagged = single
    b_obs, b_rewards, b_term, b_trunc, b_infos = batch
    for i, agent in enumerate(env.possible_agents):
        assert o[agent]["observation"].tobytes() == b_obs["observation"][k, i].tobytes(), (k, agent)
        assert o[agent]["action_mask"].tobytes() == b_obs["action_mask"][k, i].tobytes(), (k, agent)
        assert infos[agent]["passed"] == b_infos["passed"][k, i]
    if reward is not None:
        assert np.all(b_rewards[k] == reward)
    else:
        assert np.all(b_rewards[k] == 0.0)
    assert (bool(b_term[k]), bool(b_trunc[k])) == (terminated, truncated)
    first = infos[env.possible_agents[0]]
    for key in INFO_KEYS:
        assert b_infos[key][k] == first[key], (k, key)
    assert b_infos["invalid_actions"][k] == flagged
    assert b_infos["unresolved"][k] == first.get("unresolved")


@dataclasses.dataclass
class Played:
    """What ``run_equal`` played: the episodes that ended and the release actions taken in them."""

    ended: int
    releases: int


def run_equal(kw: dict, policy_name: str, seed: int, steps: int, slip: float = 0.05, engine: str = "auto") -> Played:
    """Drive the batch (on ``engine``) and the single envs together for ``steps`` steps, then compare every
    instance's allocation and counters (``evaluate``, the batch's instance written back into its env) and its release
    guard's state."""
    if policy_name != "random":
        kw = {**kw, **make_policy(policy_name).env_overrides}
    venv = taskalloc_env.vector_env(K, engine=engine, **kw)
    assert engine == "auto" or venv.engine == engine
    driver = Driver(kw, policy_name, seed, slip)
    b_obs, b_infos = venv.reset(seed=seed)
    for k, env in enumerate(driver.envs):
        check_instance(k, env, (driver.obs[k], None, False, False, driver.infos[k], 0),
                       (b_obs, np.zeros((K, 1)), np.zeros(K, bool), np.zeros(K, bool), b_infos))
    assert venv.state().tobytes() == np.stack([e.state() for e in driver.envs]).tobytes()
    ended = releases = 0
    for _ in range(steps):
        joint = driver.actions()
        batch = venv.step(joint)
        for k, (env, single) in enumerate(zip(driver.envs, driver.step(joint))):
            check_instance(k, env, single, batch)
            if single[2] or single[3]:
                ended += 1
                releases += env.protocol.counters.releases
                assert venv.evaluate(k) == env.evaluate()
        assert venv.state().tobytes() == np.stack([e.state() for e in driver.envs]).tobytes()
    for k, env in enumerate(driver.envs):
        releases += env.protocol.counters.releases
        assert venv.evaluate(k) == env.evaluate()                  # with the counters (``releases`` too)
        mine, theirs = venv.envs[k].protocol, env.protocol
        assert np.array_equal(mine._bid_round, theirs._bid_round) and np.array_equal(mine._released, theirs._released)
    return Played(ended, releases)


@pytest.mark.parametrize("policy_name", ["random", "cbgabi"])
@given(kw=batch_options(), seed=st.integers(0, 10_000))
@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_instance_k_is_the_single_env_seeded_seed_plus_k(policy_name, kw, seed):
    run_equal(kw, policy_name, seed, steps=60)


@pytest.mark.parametrize("policy_name", ["random", "cbgabi"])
@given(kw=arrays_options(), seed=st.integers(0, 10_000))
@settings(max_examples=examples(60), deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_the_arrays_engine_is_the_single_env(policy_name, kw, seed):
    run_equal(kw, policy_name, seed, steps=60, engine="arrays")


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["arrays", "instances"])
def test_equal_under_a_learned_policy_across_autoresets(engine):
    played = run_equal({"scenario": "train_small"}, "learned:train_small", seed=7, steps=120, slip=0.0, engine=engine)
    assert played.ended >= K                # every instance went through at least one autoreset


@pytest.mark.parametrize("engine", ["arrays", "instances"])
@pytest.mark.parametrize("policy_name, loss", [("random", 0.0), ("random", 0.2), ("cbgabi", 0.0), ("cbgabi", 0.2)])
def test_equal_on_the_default_scenario(engine, policy_name, loss):
    run_equal({"scenario": "default", "message_loss": loss}, policy_name, seed=1, steps=80, slip=0.02, engine=engine)


@pytest.mark.parametrize("order", ["bundle", "path"])
@pytest.mark.parametrize("consensus", ["sync", "every_step"])
@pytest.mark.parametrize("guard", ["none", "exchange", "once"])
def test_the_arrays_engine_releases_as_the_single_env(guard, consensus, order):
    """Random masked play with release actions under each guard and release order, with and without task quitting,
    on perfect and lossy links: the arrays engine is the single env (the release columns of the masks, the releases
    and what they drop, the ``releases`` counter, the guard's state), and releases were taken."""
    for quitting, loss in [(False, 0.0), (True, 0.3)]:
        kw = {"scenario": "train_small", "release_actions": True, "release_guard": guard, "release_order": order,
              "consensus": consensus, "task_quitting": quitting, "message_loss": loss}
        played = run_equal(kw, "random", seed=11, steps=80, slip=0.02, engine="arrays")
        assert played.releases > 0


@pytest.mark.parametrize("guard, loss", [("none", 0.2), ("exchange", 0.0), ("once", 0.0)])
def test_the_arrays_engine_releases_as_the_single_env_on_the_default_scenario(guard, loss):
    """Bundles long enough that a path's cost sums pairwise: a release after a change in the same step re-times the
    changed paths first, as the single env's ``release_options`` does (skipping that fails two cases here)."""
    kw = {"scenario": "default", "release_actions": True, "release_guard": guard, "task_quitting": True,
          "message_loss": loss}
    assert run_equal(kw, "random", seed=1, steps=80, slip=0.02, engine="arrays").releases > 0


def same_outputs(a, b) -> None:
    """Two nested step or reset outputs (dicts, tuples, arrays) are equal byte for byte."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            same_outputs(a[key], b[key])
    elif isinstance(a, tuple):
        for x, y in zip(a, b, strict=True):
            same_outputs(x, y)
    else:
        assert a.dtype == b.dtype and a.shape == b.shape
        assert (a.tolist() == b.tolist()) if a.dtype == object else a.tobytes() == b.tobytes()


@pytest.mark.parametrize("mode", ["next_step", "same_step", "disabled"])
@pytest.mark.parametrize("kw", [{"scenario": "train_small", "task_quitting": True},
                                {"scenario": "default", "message_loss": 0.3, "n_tasks": 8, "comm_range": 3.0}])
def test_the_engines_agree_under_every_autoreset_mode(mode, kw):
    """The arrays engine equals the instances engine (itself the single env, above) in every output, including the
    final observations of same-step resets and the restarts of a reset mask, with actions outside the masks."""
    venvs = [taskalloc_env.vector_env(4, engine=engine, autoreset_mode=mode, max_cycles=40, **kw)
             for engine in ("arrays", "instances")]
    outputs = [v.reset(seed=3) for v in venvs]
    same_outputs(*outputs)
    rng = np.random.default_rng(3)
    ends = 0
    for _ in range(150):
        mask = outputs[0][0]["action_mask"]
        actions = (rng.random(mask.shape) * mask).argmax(axis=2)
        slip = rng.random(actions.shape) < 0.03
        actions[slip] = rng.integers(0, mask.shape[2], int(slip.sum()))
        outputs = [v.step(actions) for v in venvs]
        same_outputs(*outputs)
        assert venvs[0].state().tobytes() == venvs[1].state().tobytes()
        ended = outputs[0][2] | outputs[0][3]
        ends += int(ended.sum())
        for k in np.flatnonzero(ended).tolist():
            assert venvs[0].evaluate(k) == venvs[1].evaluate(k)
        if mode == "disabled" and ended.any():
            outputs = [v.reset(options={"reset_mask": ended}) for v in venvs]
            same_outputs(*outputs)
    assert ends >= 4


BATCHED_EPISODES = """
import numpy as np
import taskalloc_env
from taskalloc_env import kernels
for kw in ({"scenario": "default"}, {"scenario": "default", "message_loss": 0.2}, {"scenario": "train_small"}):
    venv = taskalloc_env.vector_env(4, **kw)
    assert venv.engine == "arrays"
    obs, _ = venv.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(60):
        obs, *_ = venv.step((rng.random(obs["action_mask"].shape) * obs["action_mask"]).argmax(axis=2))
print(kernels.NOTICE.compiles)
"""


@pytest.mark.slow
@pytest.mark.skipif(not kernels.COMPILED, reason="numba is not installed")
def test_the_arrays_engine_compiles_nothing_once_the_cache_is_warm(tmp_path):
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)

    def compiles() -> int:
        done = subprocess.run([sys.executable, "-c", BATCHED_EPISODES], cwd=Path(__file__).resolve().parents[1],
                              env=env, capture_output=True, text=True, check=True)
        return int(done.stdout.split()[-1])

    assert compiles() > 0
    assert compiles() == 0


def test_the_engine_follows_the_options():
    assert taskalloc_env.vector_env(2, scenario="default").engine == "arrays"
    assert taskalloc_env.vector_env(2, scenario="default", message_loss=0.1).engine == "arrays"
    assert taskalloc_env.vector_env(2, scenario="train_small", release_actions=True).engine == "arrays"
    assert taskalloc_env.vector_env(2, scenario="train_small", release_actions=True, release_guard="once",
                                    task_quitting=True, message_loss=0.2).engine == "arrays"
    assert taskalloc_env.vector_env(2, scenario="default", engine="instances").engine == "instances"
    assert taskalloc_env.vector_env(2, scenario="train_small", consensus="acbba").engine == "instances"
    with pytest.raises(ConfigError, match="engine='arrays' does not cover loss_model='gilbert_elliott'"):
        taskalloc_env.vector_env(2, scenario="train_small", loss_model="gilbert_elliott", engine="arrays")
    with pytest.raises(ConfigError, match="engine 'fast' is not one of"):
        taskalloc_env.vector_env(2, scenario="train_small", engine="fast")


@pytest.mark.slow
@pytest.mark.parametrize("policy_name", ["random", "cbga", "cbgabi"])
@given(kw=batch_options(), seed=st.integers(0, 10_000))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_equal_over_long_runs(policy_name, kw, seed):
    run_equal(kw, policy_name, seed, steps=300)


# -- autoreset, seeding, spaces --------------------------------------------------------------------------------------
def play_until_an_end(venv, seed: int = 0):
    obs, _ = venv.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(10_000):
        actions = (rng.random(obs["action_mask"].shape) * obs["action_mask"]).argmax(axis=2)
        obs, rewards, term, trunc, infos = venv.step(actions)
        if (term | trunc).any():
            return obs, rewards, term, trunc, infos
    raise AssertionError("no episode ended")


@pytest.mark.parametrize("engine", ["arrays", "instances"])
def test_next_step_autoreset_starts_the_next_episode_with_zero_reward(engine):
    venv = taskalloc_env.vector_env(2, scenario="train_small", engine=engine)
    _, _, term, trunc, infos = play_until_an_end(venv)
    k = int(np.flatnonzero(term | trunc)[0])
    rounds_before = infos["round"][k]
    actions = np.zeros((2, venv.n_agents), dtype=np.int64)
    actions[k] = 10**6                                 # outside the action space: ignored by a restarting instance
    _, rewards, term2, trunc2, infos2 = venv.step(actions)
    assert rewards[k].tolist() == [0.0] * venv.n_agents
    assert not term2[k] and not trunc2[k]
    assert infos2["round"][k] == 0 < rounds_before and infos2["score"][k] == 0.0
    assert infos2["invalid_actions"][k] == 0          # the ignored actions of a restarting instance count for nothing


@pytest.mark.parametrize("engine", ["arrays", "instances"])
def test_same_step_autoreset_reports_the_final_observation_state_and_figures(engine):
    venv = taskalloc_env.vector_env(2, scenario="train_small", autoreset_mode="same_step", engine=engine)
    single = taskalloc_env.vector_env(2, scenario="train_small", engine=engine)
    obs, _, term, trunc, infos = play_until_an_end(venv, seed=5)
    s_obs, _, s_term, s_trunc, s_infos = play_until_an_end(single, seed=5)
    assert np.array_equal(term, s_term) and np.array_equal(trunc, s_trunc)
    k = int(np.flatnonzero(term | trunc)[0])
    assert infos["_final"][k]
    assert np.array_equal(infos["final_obs"]["observation"][k], s_obs["observation"][k])
    assert infos["final_info"]["score"][k] == s_infos["score"][k]
    assert infos["final_state"][k].tobytes() == single.state()[k].tobytes()
    assert infos["round"][k] == 0                    # the returned observation is the next episode's first
    assert obs["observation"][k].tobytes() != s_obs["observation"][k].tobytes()


def test_seeds_a_sequence_and_none():
    a = taskalloc_env.vector_env(3, scenario="train_small")
    b = taskalloc_env.vector_env(3, scenario="train_small")
    obs_a, _ = a.reset(seed=10)
    obs_b, _ = b.reset(seed=[10, 11, 12])
    assert np.array_equal(obs_a["observation"], obs_b["observation"])
    obs_c, _ = b.reset()                               # continues each instance's generator: new instances
    assert not np.array_equal(obs_a["observation"], obs_c["observation"])
    fresh = [taskalloc_env.vector_env(2, scenario="train_small") for _ in range(2)]
    unseeded = [v.reset()[0]["observation"] for v in fresh]
    assert not np.array_equal(unseeded[0][0], unseeded[0][1])       # the clones do not share one generator


def test_spaces_and_shapes():
    venv = taskalloc_env.vector_env(4, scenario="train_small")
    obs, infos = venv.reset(seed=0)
    n, a = venv.n_agents, venv.single_action_space.n
    assert venv.observation_space.contains(obs)
    assert obs["observation"].dtype == np.float32 and obs["action_mask"].dtype == np.int8
    assert venv.action_space.shape == (4, n) and venv.state().shape == venv.state_space.shape
    assert all(v.shape[0] == 4 for v in infos.values())
    assert obs["action_mask"].shape == (4, n, a)


# -- bad input --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("num_envs", [0, -1, True, 2.0, "4", 10**7])
def test_bad_num_envs(num_envs):
    with pytest.raises(ConfigError, match="num_envs"):
        taskalloc_env.vector_env(num_envs, scenario="train_small")


def test_too_large_for_memory_is_refused_with_the_estimate():
    with pytest.raises(ConfigError, match=r"num_envs=100,000 .* GiB.*limit is 1.0 GiB \(memory_limit_gb\)"):
        taskalloc_env.vector_env(100_000, scenario="default", memory_limit_gb=1.0)


@pytest.mark.skipif(not kernels.COMPILED, reason="the arrays engine needs the compiled kernels")
def test_memory_estimate_counts_the_arrays_engine(monkeypatch):
    template = TaskAllocEnv("train_small")
    engine_bytes = ArrayBatch.bytes_per_instance(template)
    with_arrays = TaskAllocVectorEnv._per_instance_bytes(template, arrays=True)
    assert engine_bytes > 0 and with_arrays == TaskAllocVectorEnv._per_instance_bytes(template, False) + engine_bytes
    # a limit between 4 instances without the engine's arrays and 4 with them: only engine="arrays" is refused
    limit_gb = 4 * (with_arrays - engine_bytes / 2) / 2**30
    built, init = [], ArrayBatch.__init__

    def recorded(self: ArrayBatch, k: int, *args: object) -> None:
        built.append(k)
        init(self, k, *args)

    monkeypatch.setattr(ArrayBatch, "__init__", recorded)
    assert taskalloc_env.vector_env(4, scenario="train_small", engine="instances", memory_limit_gb=limit_gb)
    assert taskalloc_env.vector_env(3, scenario="train_small", engine="arrays", memory_limit_gb=limit_gb)
    with pytest.raises(ConfigError, match="num_envs=4 "):
        taskalloc_env.vector_env(4, scenario="train_small", engine="arrays", memory_limit_gb=limit_gb)
    assert 4 not in built                       # the refused batch allocated nothing


@pytest.mark.parametrize("option", [{"dropouts": 1}, {"dropout_schedule": [[0, 2]]}, {"join_at": {1: 2}},
                                    {"render_mode": "ansi"},
                                    {"autoreset_mode": "never"}])
def test_unsupported_options_are_named(option):
    with pytest.raises(ConfigError, match=next(iter(option))):
        taskalloc_env.vector_env(2, scenario="train_small", **option)


@pytest.mark.parametrize("actions, match", [
    (np.zeros((2, 3), dtype=np.int64), r"shape \(num_envs, n_agents\) = \(2, 4\)"),
    (np.zeros((2, 4), dtype=bool), "integer array"),
    (np.zeros((2, 4)), "integer array"),
])
def test_bad_action_arrays(actions, match):
    venv = taskalloc_env.vector_env(2, scenario="train_small")
    venv.reset(seed=0)
    with pytest.raises(InvalidActionError, match=match):
        venv.step(actions)


@pytest.mark.parametrize("engine", ["arrays", "instances"])
def test_invalid_actions_are_counted_under_noop_and_named_under_raise(engine):
    venv = taskalloc_env.vector_env(2, scenario="train_small", engine=engine)
    obs, _ = venv.reset(seed=0)
    actions = np.zeros((2, 4), dtype=np.int64)
    actions[1, 2] = obs["action_mask"].shape[2] + 5                  # outside Discrete(A)
    masked = np.flatnonzero(obs["action_mask"][0, 1] == 0)
    actions[0, 1] = masked[0]
    _, _, _, _, infos = venv.step(actions)
    assert infos["invalid_actions"].tolist() == [1, 1]
    strict = taskalloc_env.vector_env(2, scenario="train_small", invalid_action="raise", engine=engine)
    strict.reset(seed=0)
    with pytest.raises(InvalidActionError, match=r"instance 0: action \d+ \(.*\) of uav_1 is not allowed by its mask"):
        strict.step(actions)
    with pytest.raises(InvalidActionError, match="step\\(\\) called before reset"):
        taskalloc_env.vector_env(1, scenario="train_small").step(np.zeros((1, 4), dtype=np.int64))
