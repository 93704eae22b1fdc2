"""The SB3 vector-env adapter's contract (training/vec_env.py): shapes, masks, resets, truncation, seeding.

SB3's ``check_env`` only takes a single ``gym.Env``; ``check_step_contract`` below makes the same checks for the
vector env (observations inside the space, dtypes, done infos with ``terminal_observation`` inside the space).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported

from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns
from taskalloc_env.env import InvalidActionError
from taskalloc_env.rewards import EPISODE_FIGURES

ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1, "reward_scale": 100.0}


def make(n_copies: int = 3, n_procs: int = 0, scripted: dict | None = None, **kw) -> TaskAllocVecEnv:
    return TaskAllocVecEnv(make_env_fns(n_copies, **{**ENV, **kw}), scripted_agents=scripted, n_procs=n_procs)


def random_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.choice(np.flatnonzero(m)) for m in masks])


def check_step_contract(venv: TaskAllocVecEnv, obs, rewards=None, dones=None, infos=None) -> None:
    assert venv.observation_space["observation"].contains(obs["observation"][0])
    for key in ("observation", "action_mask"):
        assert obs[key].shape == (venv.num_envs, *venv.observation_space[key].shape)
        assert obs[key].dtype == venv.observation_space[key].dtype
    for row in range(venv.num_envs):
        assert venv.observation_space.contains({k: obs[k][row] for k in obs})
    if rewards is None:
        return
    assert rewards.shape == (venv.num_envs,) and np.issubdtype(rewards.dtype, np.floating)
    assert dones.shape == (venv.num_envs,) and dones.dtype == bool
    assert isinstance(infos, list) and len(infos) == venv.num_envs
    for done, info in zip(dones, infos):
        assert isinstance(info, dict)
        assert ("terminal_observation" in info) == bool(done)
        if done:
            assert venv.observation_space.contains(info["terminal_observation"])
            assert isinstance(info["TimeLimit.truncated"], bool)


def rollout(venv: TaskAllocVecEnv, steps: int, seed: int) -> list[tuple]:
    rng = np.random.default_rng(seed)
    venv.seed(seed)
    obs = venv.reset()
    trace = [(obs["observation"].copy(),)]
    for _ in range(steps):
        obs, rewards, dones, _ = venv.step(random_actions(venv.action_masks(), rng))
        trace.append((obs["observation"].copy(), rewards.copy(), dones.copy()))
    return trace


def test_shapes_spaces_and_step_contract():
    venv = make(n_copies=3)
    assert venv.num_envs == 3 * 4 and venv.agents_per_copy == 4
    assert venv.action_space.n == 1 + 2 * 8
    obs = venv.reset()
    check_step_contract(venv, obs)
    rng = np.random.default_rng(0)
    for _ in range(60):
        obs, rewards, dones, infos = venv.step(random_actions(venv.action_masks(), rng))
        check_step_contract(venv, obs, rewards, dones, infos)
    venv.close()


def test_masks_for_maskable_ppo_match_observations_and_are_enforced():
    venv = make(n_copies=2)
    venv.seed(11)                         # the same instances as `strict` below, so its masks are venv's
    obs = venv.reset()
    assert is_masking_supported(venv) and venv.has_attr("action_masks")
    masks = get_action_masks(venv)        # sb3-contrib's own reader: np.stack(env.env_method("action_masks"))
    assert masks.shape == (venv.num_envs, venv.action_space.n) and masks.dtype == bool
    np.testing.assert_array_equal(masks, obs["action_mask"].astype(bool))
    assert masks[:, 0].all() and masks[:, 1:].any()
    # the adapter sends actions unchanged: a masked-out action reaches the env, which raises under "raise"
    strict = make(n_copies=2, invalid_action="raise")
    strict.seed(11)
    strict.reset()
    invalid = np.zeros(venv.num_envs, dtype=np.int64)
    row = int(np.flatnonzero(~masks.all(axis=1))[0])
    invalid[row] = int(np.flatnonzero(~masks[row])[0])
    with pytest.raises(InvalidActionError):
        strict.step(invalid)


def test_episode_end_reports_once_per_copy_and_resets():
    venv = make(n_copies=2)
    venv.seed(5)
    venv.reset()
    rng = np.random.default_rng(1)
    episodes, returns = [], np.zeros(venv.num_envs)
    for _ in range(300):
        obs, rewards, dones, infos = venv.step(random_actions(venv.action_masks(), rng))
        returns += rewards
        for copy in range(venv.n_copies):
            block = slice(copy * 4, copy * 4 + 4)
            assert dones[block].all() or not dones[block].any(), "agents of one copy end together"
            if dones[block].all():
                first = infos[copy * 4]
                assert [("episode" in i) for i in infos[block]] == [True, False, False, False]
                # the env's record (the return is the final team score / reward_scale) and the wall time
                record = first["episode"]
                assert set(record) == {"r", "l", "t", *EPISODE_FIGURES}
                assert record["r"] == pytest.approx(record["score"] / 100.0, abs=1e-9)
                assert returns[block] == pytest.approx(record["r"], abs=1e-4)
                assert not first["TimeLimit.truncated"]                     # random play converges here
                assert obs["observation"][block][:, 5].max() == 0.0         # fresh episode: round feature 0
                episodes.append(first["episode"])
                returns[block] = 0.0
    assert len(episodes) >= 4


def test_truncation_sets_timelimit_flag_and_terminal_observation():
    venv = make(n_copies=2, max_cycles=1)
    venv.seed(0)
    venv.reset()
    _, _, dones, infos = venv.step(np.zeros(venv.num_envs, dtype=np.int64))
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] is True
        assert venv.observation_space.contains(info["terminal_observation"])
    assert infos[0]["episode"]["l"] == 1


def test_seeding_reproduces_a_run_across_episodes_and_differs_between_seeds():
    a, b, c = make(n_copies=2), make(n_copies=2), make(n_copies=2)
    run_a, run_b, run_c = rollout(a, 120, seed=11), rollout(b, 120, seed=11), rollout(c, 120, seed=12)
    assert sum(int(step[2].any()) for step in run_a[1:]) >= 2, "the run must cross episode boundaries"
    for x, y in zip(run_a, run_b):
        for u, v in zip(x, y):
            np.testing.assert_array_equal(u, v)
    assert not np.array_equal(run_a[0][0], run_c[0][0])
    assert a.seed(3) == [3] * 4 + [4] * 4      # copy c gets seed + c; one entry per slot


@pytest.mark.slow
def test_subprocess_copies_match_in_process_copies():
    local = make(n_copies=3)
    remote = make(n_copies=3, n_procs=2)
    try:
        for x, y in zip(rollout(local, 40, seed=2), rollout(remote, 40, seed=2)):
            for u, v in zip(x, y):
                np.testing.assert_array_equal(u, v)
        assert remote.get_attr("max_cycles") == local.get_attr("max_cycles")     # attributes of remote copies
        assert remote.env_method("describe_action", 0, indices=[0]) == ["pass"]
    finally:
        remote.close()


def test_mixed_team_gives_slots_to_learned_agents_only():
    venv = make(n_copies=2, scripted={"uav_0": "cbgabi", "uav_2": "cbga"})
    assert venv.learned_agents == ["uav_1", "uav_3"] and venv.num_envs == 4
    venv.seed(0)
    obs = venv.reset()
    check_step_contract(venv, obs)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(80):
        obs, rewards, dones, infos = venv.step(random_actions(venv.action_masks(), rng))
        check_step_contract(venv, obs, rewards, dones, infos)
        ended += sum("episode" in i for i in infos)
    assert ended >= 2
    with pytest.raises(ValueError, match="unknown agents"):
        make(n_copies=1, scripted={"uav_9": "cbga"})
    with pytest.raises(ValueError, match="every agent"):
        make(n_copies=1, scripted={f"uav_{i}": "cbga" for i in range(4)})


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["maskable_ppo", "ppo"])
def test_sb3_algorithms_run_on_the_adapter_with_a_seed(algo):
    from sb3_contrib import MaskablePPO
    from stable_baselines3 import PPO

    from taskalloc.training.sb3_policy import TaskMaskablePolicy, TaskPolicy

    algo_class, policy = (MaskablePPO, TaskMaskablePolicy) if algo == "maskable_ppo" else (PPO, TaskPolicy)
    venv = make(n_copies=2)
    model = algo_class(policy, venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)   # invalid_action="raise": any unmasked sample would raise here
    assert model.num_timesteps >= 256
    assert len(model.ep_info_buffer) >= 1
