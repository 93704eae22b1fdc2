"""The BenchMARL MAPPO models (``taskalloc benchmarl train``) without BenchMARL: the committed seeds load by name and
play Small with valid actions only, BenchMARL's actor weights map onto ``MlpActor``, and the safetensors files
written without the safetensors package load with it."""

from __future__ import annotations

import numpy as np
import pytest

th = pytest.importorskip("torch")
pytest.importorskip("safetensors")

from taskalloc.policies import make_policy  # noqa: E402
from taskalloc.policies.checkpoint import CheckpointError, write_safetensors  # noqa: E402
from taskalloc.policies.networks import MASKED_LOGIT, MlpActor  # noqa: E402
from taskalloc.training.benchmarl_mappo import actor_from_state_dict, env_config  # noqa: E402
from taskalloc_env import suite  # noqa: E402
from taskalloc_env.env import TaskAllocEnv  # noqa: E402
from taskalloc_env.errors import ConfigError  # noqa: E402

SEEDS = ("benchmarl_mappo_small_s0", "benchmarl_mappo_small_s1", "benchmarl_mappo_small_s2")
SMALL = suite.task("taskalloc/Small-v0")
PREFIX = "module.0.module.0.mlp.params"         # BenchMARL 1.5.2's policy state_dict: shared MultiAgentMLP


@pytest.mark.parametrize("name", SEEDS)
def test_committed_benchmarl_models_load_by_name_and_play_small_with_valid_actions(name):
    policy = make_policy(f"learned:{name}")
    assert policy.env_overrides == {"task_quitting": True, "delta": 1}
    env = TaskAllocEnv(**env_config(SMALL, policy.env_overrides))
    obs, infos = env.reset(seed=SMALL.test_seeds[0])
    policy.start(env, SMALL.test_seeds[0])
    steps = 0
    while env.agents:
        actions = policy.act({a: obs[a] for a in env.agents}, {a: infos[a] for a in env.agents})
        assert sorted(actions) == sorted(env.agents)
        for agent, action in actions.items():
            assert obs[agent]["action_mask"][action], (agent, action)
        obs, _, _, _, infos = env.step(actions)
        steps += 1
    assert 0 < steps < env.max_cycles and env.unwrapped.evaluate().score > 0


def _benchmarl_state(actor: MlpActor) -> dict[str, object]:
    """``actor``'s weights under the keys BenchMARL's MAPPO policy gives them (plus its batch-size entry)."""
    state = {f"{PREFIX}.{key.split('.', 1)[1]}": value for key, value in actor.state_dict().items()}
    return {**state, f"{PREFIX}.__batch_size": th.Size([])}


def test_benchmarl_weights_become_an_mlp_actor_with_the_same_logits():
    th.manual_seed(0)
    source = MlpActor(obs_size=11, n_actions=5, hidden=7)
    actor = actor_from_state_dict(_benchmarl_state(source), obs_size=11, n_actions=5)
    assert actor.hidden == 7
    obs, mask = th.randn(6, 11), th.rand(6, 5) > 0.3
    expected = source.actor(obs).masked_fill(~mask, MASKED_LOGIT)
    assert th.equal(actor(obs, mask), expected)


def test_a_benchmarl_actor_of_another_shape_is_refused():
    three_layers = MlpActor(obs_size=11, n_actions=5, hidden=7)
    state = _benchmarl_state(three_layers)
    state[f"{PREFIX}.6.weight"] = th.zeros(5, 5)
    with pytest.raises(ConfigError, match=r"linear layers at \[0, 2, 4, 6\]"):
        actor_from_state_dict(state, obs_size=11, n_actions=5)
    with pytest.raises(ConfigError, match="does not fit MlpActor"):
        actor_from_state_dict(_benchmarl_state(three_layers), obs_size=12, n_actions=5)


def test_safetensors_written_by_hand_load_with_safetensors(tmp_path):
    from safetensors.torch import load_file

    tensors = {"b": th.arange(3, dtype=th.int64), "a": th.randn(4, 3), "c": th.randn(2, dtype=th.float64)}
    write_safetensors(tensors, str(tmp_path / "w.safetensors"))
    loaded = load_file(str(tmp_path / "w.safetensors"))
    assert loaded.keys() == tensors.keys()
    for key, value in tensors.items():
        assert loaded[key].dtype == value.dtype and th.equal(loaded[key], value), key
    with pytest.raises(CheckpointError, match="dtype bool"):
        write_safetensors({"m": th.ones(2, dtype=th.bool)}, str(tmp_path / "m.safetensors"))
    assert np.frombuffer((tmp_path / "w.safetensors").read_bytes()[:8], "<u8")[0] % 8 == 0
