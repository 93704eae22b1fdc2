"""Warm-starting a release actor (``kinds=3``) from one without release logits (``with_release_head``, MAPPO's
``init_from``): the pass, bid and quit logits are the source's, the release logit starts as ``RELEASE_BIAS``, a weight
left uncopied shows, and other mismatches are refused in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch as th

from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.networks import (
    RELEASE_BIAS,
    AttentionActor,
    PoolingActor,
    with_new_features,
    with_release_head,
)
from taskalloc.training import mappo
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import release_columns

RELEASE_ENV = {"scenario": "train_small", "task_quitting": True, "delta": 1, "release_actions": True}
MODELS = Path(__file__).parents[1] / "models"
N_TASKS = 8         # train_small


def small_actor(network: str, kinds: int) -> th.nn.Module:
    return (PoolingActor(7, 22, 16, kinds=kinds) if network == "pooling"
            else AttentionActor(7, 22, 16, heads=2, layers=1, kinds=kinds))


def distinct_source(network: str) -> th.nn.Module:
    """A two-kind actor whose every weight (layer norms too) is away from any fresh initialisation."""
    th.manual_seed(1)
    actor = small_actor(network, 2)
    with th.no_grad():
        for parameter in actor.parameters():
            parameter.normal_(0, 0.3)
    return actor.eval()


def observations() -> tuple[th.Tensor, th.Tensor]:
    """Observations and release-layout masks from CBGA's first steps on train_small with release actions."""
    rows, masks = [], []
    for seed in range(3):
        env = TaskAllocEnv(**RELEASE_ENV)
        obs, infos = env.reset(seed=seed)
        cbga = make_policy("cbga")
        cbga.start(env, seed)
        for _ in range(8):
            if not env.agents:
                break
            rows += [o["observation"] for o in obs.values()]
            masks += [o["action_mask"] for o in obs.values()]
            obs, _, _, _, infos = env.step(cbga.act(obs, infos))
    return th.as_tensor(np.stack(rows), dtype=th.float32), th.as_tensor(np.stack(masks) > 0)


def no_release_rows(obs: th.Tensor, masks: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
    """The rows whose mask allows no release (where the warm start must play as its source)."""
    keep = ~masks[:, release_columns(N_TASKS)].any(dim=1)
    assert 0 < int(keep.sum()) < len(keep)      # both kinds of row occur, so the selection means something
    return obs[keep], masks[keep]


def assert_plays_as_source(source: th.nn.Module, warm: th.nn.Module, obs: th.Tensor, masks: th.Tensor,
                           bias: float = RELEASE_BIAS) -> None:
    """Where no release is allowed the masked logits equal the source's; unmasked, every release logit is the
    constant and the other logits are the source's."""
    width = 1 + 2 * N_TASKS
    obs_n, masks_n = no_release_rows(obs, masks)
    with th.no_grad():
        th.testing.assert_close(warm(obs_n, masks_n)[:, :width], source(obs_n, masks_n[:, :width]),
                                rtol=1e-5, atol=1e-5)
        everything = warm(obs, th.ones_like(masks))
        th.testing.assert_close(everything[:, :width], source(obs, th.ones_like(masks[:, :width])),
                                rtol=1e-5, atol=1e-5)
    assert th.equal(everything[:, width:], th.full_like(everything[:, width:], bias))


@pytest.mark.parametrize("network", ["pooling", "attention"])
def test_a_warm_started_release_actor_plays_as_its_source_and_releases_start_at_the_constant(network):
    source, warm = distinct_source(network), small_actor(network, 3).eval()
    warm.load_state_dict(with_release_head(warm, source.state_dict()))
    assert_plays_as_source(source, warm, *observations())


@pytest.mark.parametrize("network", ["pooling", "attention"])
def test_any_weight_left_uncopied_fails_the_check(network):
    """A planted bug: each weight in turn left at the release actor's fresh initialisation; the check fails."""
    source, obs, masks = distinct_source(network), *observations()
    fresh = small_actor(network, 3).state_dict()
    widened = with_release_head(small_actor(network, 3), source.state_dict())
    for key in widened:
        warm = small_actor(network, 3).eval()
        warm.load_state_dict({**widened, key: fresh[key]})
        with pytest.raises(AssertionError):
            assert_plays_as_source(source, warm, obs, masks)


def test_with_release_head_refuses_other_mismatches_in_one_line():
    source = distinct_source("pooling").state_dict()
    with pytest.raises(ValueError, match=r"^with_release_head widens into an actor with release logits \(kinds=3\), "
                                         r"not a PoolingActor with kinds=2$"):
        with_release_head(small_actor("pooling", 2), source)
    with pytest.raises(ValueError, match=r"^the source's actor\.encode\.0\.weight has shape \(16, 29\), this actor's "
                                         r"\(32, 29\) \(hidden, heads and layers must match\)$"):
        with_release_head(PoolingActor(7, 22, 32, kinds=3), source)
    with pytest.raises(ValueError, match=r"^the source does not fit this attention actor: weights \[.*\] differ$"):
        with_release_head(small_actor("attention", 3), source)


def test_mappo_init_from_starts_the_release_run_from_the_committed_model(tmp_path):
    """``taskalloc mappo --config mappo_small_release --init-from mappo_small_pooling_1m`` (no updates): the saved
    actor plays as the committed one with the release logit at the constant (or at ``--release-bias``), and the
    critic is loaded too; a
    release actor cannot start a run without release actions, nor a source of another width a release run."""
    summary = mappo.main(["--config", "mappo_small_release", "--init-from", "mappo_small_pooling_1m",
                          "--total-steps", "0", "--eval-episodes", "1", "--out-dir", str(tmp_path / "warm")])
    assert summary["init_from"] == ["actor", "critic"]
    source, warm = checkpoint.load(MODELS / "mappo_small_pooling_1m").actor, checkpoint.load(tmp_path / "warm").actor
    assert warm.kinds == 3
    assert_plays_as_source(source, warm, *observations())
    mappo.main(["--config", "mappo_small_release", "--init-from", "mappo_small_pooling_1m", "--release-bias", "-2",
                "--total-steps", "0", "--eval-episodes", "1", "--out-dir", str(tmp_path / "warm2")])
    assert_plays_as_source(source, checkpoint.load(tmp_path / "warm2").actor, *observations(), bias=-2.0)
    with pytest.raises(mappo.ConfigError, match=r"^init_from .*warm: its actor has release logits and this run has "
                                                r"no release_actions; only an actor without them can start one with "
                                                r"them$"):
        mappo.main(["--config", "mappo_small_pooling", "--init-from", str(tmp_path / "warm"), "--total-steps", "0",
                    "--out-dir", str(tmp_path / "back")])
    with pytest.raises(mappo.ConfigError, match=r"^init_from mappo_small_pooling_1m: the source's actor\.encode\.0"
                                                r"\.weight has shape \(64, 29\), this actor's \(32, 29\)"):
        mappo.main(["--config", "mappo_small_release", "--hidden", "32", "--init-from", "mappo_small_pooling_1m",
                    "--total-steps", "0", "--out-dir", str(tmp_path / "narrow")])


def test_new_observation_features_start_at_zero_so_the_widened_actor_plays_as_its_source():
    """``with_new_features``: a pooling actor over one more per-task feature (inserted in the middle) and one more own
    feature gives the source's logits on the same observations, whatever the new features hold; a source feature
    the run lacks, and an attention actor, are refused in one line."""
    source = distinct_source("pooling")                              # own 7, per task 22
    own, task = [f"o{k}" for k in range(7)], [f"t{k}" for k in range(22)]
    wide_own, wide_task = [*own, "o_new"], [*task[:5], "t_new", *task[5:]]
    widened = PoolingActor(8, 23, 16, kinds=2)
    widened.load_state_dict(with_new_features(widened, source.state_dict(), (own, task), (wide_own, wide_task)))
    rng = np.random.default_rng(0)
    own_rows, task_rows = rng.normal(size=(6, 7)), rng.normal(size=(6, N_TASKS, 22))
    masks = th.ones((6, 1 + 2 * N_TASKS), dtype=th.bool)
    plain = th.as_tensor(np.concatenate([own_rows, task_rows.reshape(6, -1)], axis=1), dtype=th.float32)
    wide_tasks = np.concatenate([task_rows[:, :, :5], rng.normal(size=(6, N_TASKS, 1)), task_rows[:, :, 5:]], axis=2)
    wide = th.as_tensor(np.concatenate([own_rows, rng.normal(size=(6, 1)), wide_tasks.reshape(6, -1)], axis=1),
                        dtype=th.float32)
    with th.no_grad():
        th.testing.assert_close(widened.eval()(wide, masks), source(plain, masks))
    with pytest.raises(ValueError, match=r"^this run's observation lacks the source's features \['t3'\]$"):
        with_new_features(widened, source.state_dict(), (own, task), (wide_own, [t for t in wide_task if t != "t3"]))
    with pytest.raises(ValueError, match=r"^only the pooling actor takes new observation features, not the "
                                         r"attention actor$"):
        with_new_features(small_actor("attention", 2), source.state_dict(), (own, task), (wide_own, wide_task))


def test_a_release_run_on_a_faulty_network_starts_from_the_perfect_link_model(tmp_path):
    """``taskalloc mappo --config mappo_lossy_release --init-from mappo_small_pooling_s0`` (no updates): the Lossy
    observation has the fault feature the source lacks, so the actor is widened and the critic starts afresh."""
    summary = mappo.main(["--config", "mappo_lossy_release", "--init-from", "mappo_small_pooling_s0",
                          "--total-steps", "0", "--eval-episodes", "1", "--out-dir", str(tmp_path / "lossy")])
    assert summary["init_from"] == ["actor"]
    assert "member_silence" in checkpoint.load(tmp_path / "lossy").task_features
