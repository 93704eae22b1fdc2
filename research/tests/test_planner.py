"""The learned round-0 plan: its labels, its loss, how it plays and hands over, its checkpoint and its command line
(``research.training.planner``, ``research.policies.round_zero``)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch as th
from helpers import assert_same_actions

from research.policies.handover import Handover
from research.policies.oracle import OraclePolicy
from research.policies.round_zero import RoundZeroPlanner, bid_log_odds
from research.training import planner
from taskalloc.policies import make_policy, rollout
from taskalloc.policies.base import stack_observations
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc.policies.networks import PoolingActor
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli

OVERRIDES = {"task_quitting": True, "delta": 1}
SMALL = Path(__file__).parents[2] / "configs" / "scenarios" / "train_small.yaml"


# three epochs on 20 train_small instances with exact labels, handed over to CBGABI
SHORT_RUN = ["--config", "planner_default", "--scenario", "train_small", "--solver", "exact", "--then", "cbgabi",
             "--episodes", "20", "--epochs", "3", "--eval-episodes", "3", "--jobs", "1", "--torch-threads", "1"]


def losses(run: object) -> list[float]:
    with open(f"{run}/planner.csv") as fh:
        return [float(row["loss"]) for row in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A planner of ``SHORT_RUN``."""
    out = tmp_path_factory.mktemp("planner") / "run"
    planner.main([*SHORT_RUN, "--out-dir", str(out)])
    return out


def test_the_labels_are_the_optimums_paths_on_the_round_0_states_the_oracle_visits():
    """Every round-0 state where an agent may bid, with the oracle's allowed bids (``OraclePolicy.targets``) as the
    tasks on its path; the oracle plays the same bids, so the states are the same."""
    seeds = [3, 4, 5]
    got = planner.label(("train_small", OVERRIDES, "exact", seeds))
    env, oracle = TaskAllocEnv("train_small", **OVERRIDES), OraclePolicy()
    agents, m = env.possible_agents, env.observation_layout.n_tasks
    obs_rows, allowed_rows, path_rows = [], [], []
    for seed in seeds:
        observations, infos = env.reset(seed=seed)
        oracle.start(env, seed)
        while env.agents and infos[agents[0]]["round"] == 0:
            obs, masks = stack_observations(observations, agents)
            keep = masks[:, 1: m + 1].any(axis=1)
            obs_rows.append(obs[keep])
            allowed_rows.append(masks[keep, 1: m + 1] > 0)
            path_rows.append(oracle.targets(agents, masks.astype(bool))[keep, 1: m + 1])
            observations, _, _, _, infos = env.step(oracle.act(observations))
    np.testing.assert_array_equal(got.obs, np.concatenate(obs_rows))
    np.testing.assert_array_equal(got.allowed, np.concatenate(allowed_rows))
    np.testing.assert_array_equal(got.on_path, np.concatenate(path_rows))
    assert got.on_path.any() and (got.allowed & ~got.on_path).any()


def test_the_loss_is_the_binary_cross_entropy_over_the_allowed_tasks_only():
    th.manual_seed(0)
    actor = PoolingActor(3, 2, 8)
    obs = th.randn(4, 3 + 5 * 2)
    allowed = th.rand(4, 5) < 0.6
    on_path = (th.rand(4, 5) < 0.5) & allowed
    p = th.sigmoid(bid_log_odds(actor, obs))
    terms = -(on_path * th.log(p) + (~on_path) * th.log(1 - p))
    assert planner.plan_loss(actor, obs, allowed, on_path).item() == pytest.approx(
        (terms[allowed].sum() / allowed.sum()).item(), rel=1e-5)
    # a task the agent may not bid on does not count, whatever its label
    assert planner.plan_loss(actor, obs, allowed, on_path | ~allowed).item() == pytest.approx(
        planner.plan_loss(actor, obs, allowed, on_path).item(), rel=1e-6)


def flat_planner(env: TaskAllocEnv, log_odds: float, threshold: float = 0.5, replan: bool = True
                 ) -> RoundZeroPlanner:
    """A planner whose actor gives every task the same log-odds."""
    layout = env.observation_layout
    actor = PoolingActor(layout.own_size, layout.task_size, 8)
    with th.no_grad():
        actor.task_head[-1].weight.zero_()
        actor.task_head[-1].bias.copy_(th.tensor([log_odds, 0.0]))
    policy = RoundZeroPlanner(actor, layout.own_names, layout.task_names, threshold=threshold, replan=replan)
    policy.start(env, 0)
    return policy


@pytest.mark.parametrize("log_odds, bids", [(1.0, True), (-1.0, False)])
def test_it_bids_in_round_0_while_a_task_is_likely_and_passes_in_every_later_round(log_odds, bids):
    """All tasks equally likely: above the threshold every agent bids on its first allowed task, below it passes;
    after round 0 it always passes."""
    env = TaskAllocEnv("train_small", **OVERRIDES)
    observations, infos = env.reset(seed=7)
    policy = flat_planner(env, log_odds)
    rounds_seen = set()
    while env.agents:
        actions = policy.act(observations, infos)
        for agent, obs in observations.items():
            allowed = np.flatnonzero(obs["action_mask"][1: env.observation_layout.n_tasks + 1])
            first = infos[agent]["round"] == 0 and bids and len(allowed) > 0
            assert actions[agent] == (1 + allowed[0] if first else 0)
        rounds_seen.add(infos[env.agents[0]]["round"])
        observations, _, _, _, infos = env.step(actions)
    assert {0, 1} <= rounds_seen


@pytest.mark.parametrize("replan", [True, False])
def test_replanning_estimates_at_every_step_and_planning_once_keeps_the_first_states_plan(replan):
    """Every task likely (0.8) before the agent's first bid, unlikely (0.2) after it: replanning bids once and then
    passes; planning once bids along every task its first state allows, in order (bid_along), whatever it estimates
    later."""
    env = TaskAllocEnv("train_small", **OVERRIDES)
    observations, infos = env.reset(seed=7)
    m, bundle = env.observation_layout.n_tasks, env.observation_layout.own_names.index("bundle_size")
    policy = flat_planner(env, 1.0, replan=replan)
    policy.probabilities = lambda obs: np.where(obs[:, [bundle]] > 0, 0.2, 0.8) * np.ones((len(obs), m))
    first_plan = {a: tuple(np.flatnonzero(o["action_mask"][1: m + 1])) for a, o in observations.items()}
    bids = dict.fromkeys(env.agents, 0)
    while env.agents and infos[env.agents[0]]["round"] == 0:
        actions = policy.act(observations, infos)
        for agent, obs in observations.items():
            mask = obs["action_mask"]
            if replan:
                allowed = np.flatnonzero(mask[1: m + 1])
                want = 1 + allowed[0] if bids[agent] == 0 and len(allowed) else 0
            else:
                want = next((1 + j for j in first_plan[agent] if mask[1 + j]), 0)
            assert actions[agent] == want
            bids[agent] += actions[agent] > 0
        observations, _, _, _, infos = env.step(actions)
    assert max(bids.values()) == 1 if replan else max(bids.values()) > 1


def test_a_bad_threshold_is_refused_by_name():
    env = TaskAllocEnv("train_small")
    for threshold in (0.0, 1.0, True, "half"):
        with pytest.raises(ValueError, match="threshold must be a number in"):
            flat_planner(env, 1.0, threshold)
    with pytest.raises(ValueError, match="replan must be true or false"):
        flat_planner(env, 1.0, replan="no")


def test_a_short_run_lowers_the_validation_loss_and_saves_a_planner_that_hands_over(trained):
    with open(trained / "planner.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["epoch"]) for r in rows] == [0, 1, 2]
    assert float(rows[-1]["validation_loss"]) < float(rows[0]["validation_loss"])
    policy = make_policy(f"learned:{trained}")
    assert isinstance(policy, Handover) and isinstance(policy.first, RoundZeroPlanner)
    assert policy.then.name == "CBGABI" and policy.rounds == 1 and policy.env_overrides == OVERRIDES
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    for seed in (0, 1):
        allocation = rollout(env, policy, seed=seed)
        assert allocation.converged and not allocation.conflicts


def test_annealing_the_learning_rate_changes_the_epochs_after_the_first(trained, tmp_path):
    """The cosine schedule starts at the configured rate (epoch 0 the same, bit for bit, as the constant rate) and
    lowers it from epoch 1 on, so the later epochs' losses differ."""
    planner.main([*SHORT_RUN, "--anneal-lr", "--out-dir", str(tmp_path / "run")])
    constant, annealed = losses(trained), losses(tmp_path / "run")
    assert annealed[0] == constant[0]
    assert all(a != c for a, c in zip(annealed[1:], constant[1:]))


def test_the_label_cache_gives_the_same_run_without_labelling_again(trained, tmp_path, monkeypatch):
    """A first run keeps its training and validation states (two files), a second reads them back and trains the
    same losses as a run without the cache; another seed adds only its training states; a file whose key is not
    the run's is refused by name."""
    cache = tmp_path / "labels"
    planner.main([*SHORT_RUN, "--label-cache", str(cache), "--out-dir", str(tmp_path / "first")])
    assert len(list(cache.glob("*.npz"))) == 2

    def no_labelling(*args):
        raise AssertionError("labelled again")

    monkeypatch.setattr(planner, "label_all", no_labelling)
    planner.main([*SHORT_RUN, "--label-cache", str(cache), "--out-dir", str(tmp_path / "second")])
    assert losses(tmp_path / "second") == losses(tmp_path / "first") == losses(trained)
    monkeypatch.undo()
    planner.main([*SHORT_RUN, "--seed", "1", "--label-cache", str(cache), "--out-dir", str(tmp_path / "seed1")])
    assert len(list(cache.glob("*.npz"))) == 3
    for kept in cache.glob("*.npz"):
        with np.load(kept) as data:
            np.savez(kept, **{**data, "key": np.array("another run")})
    with pytest.raises(planner.ConfigError, match="holds other states"):
        planner.main([*SHORT_RUN, "--seed", "1", "--label-cache", str(cache), "--out-dir", str(tmp_path / "bad")])


def test_augmenting_fits_each_state_under_one_of_the_eight_symmetries(monkeypatch):
    """``fit_epoch`` with ``augment``'s symmetries feeds the actor each state turned by one of them (all eight
    drawn over an epoch), with its labels as they were; with eight identities it is the run without."""
    from research.policies.symmetry import square_symmetries

    data = planner.label(("train_small", OVERRIDES, "exact", [3, 4, 5]))
    env = TaskAllocEnv("train_small", **OVERRIDES)
    layout = env.observation_layout
    tensors = planner.tensors(data)
    symmetries = planner.symmetry_tensors(layout)
    seen = []
    monkeypatch.setattr(planner, "plan_loss", lambda actor, obs, allowed, on_path: (
        seen.append((obs, allowed, on_path)) or bid_log_odds(actor, obs).sum() * 0))
    th.manual_seed(0)
    actor = PoolingActor(layout.own_size, layout.task_size, 16)
    planner.fit_epoch(actor, th.optim.SGD(actor.parameters(), lr=0.0), tensors, 8, np.random.default_rng(0),
                      symmetries)
    obs = th.cat([o for o, _, _ in seen]).numpy()
    allowed, on_path = (th.cat([t[k] for t in seen]).numpy() for k in (1, 2))
    order = np.random.default_rng(0).permutation(len(data.obs))
    permutations, signs, shifts = square_symmetries(layout.own_names, layout.task_names, layout.n_tasks)
    turns = data.obs[order][:, permutations] * signs + shifts                   # (S, 8, D)
    which = np.abs(turns - obs[:, None, :]).max(axis=2).argmin(axis=1)
    np.testing.assert_allclose(turns[np.arange(len(obs)), which], obs, atol=1e-6)
    assert set(which) == set(range(8))
    np.testing.assert_array_equal(allowed, data.allowed[order])
    np.testing.assert_array_equal(on_path, data.on_path[order])

    monkeypatch.undo()
    identity = tuple(t[:1].repeat(8, *([1] * (t.dim() - 1))) for t in symmetries)
    runs = []
    for given in (None, identity):
        th.manual_seed(0)
        actor = PoolingActor(layout.own_size, layout.task_size, 16)
        runs.append(planner.fit_epoch(actor, th.optim.Adam(actor.parameters()), tensors, 8,
                                      np.random.default_rng(0), given))
    assert runs[0] == runs[1]


def test_augmenting_needs_a_square_floor(tmp_path):
    planner.PlannerConfig(scenario="train_small", augment=True).check()
    narrow = tmp_path / "narrow.yaml"
    narrow.write_text(SMALL.read_text().replace("[5.0, 5.0, 2.0]", "[5.0, 4.0, 2.0]"))
    planner.PlannerConfig(scenario=str(narrow)).check()
    with pytest.raises(planner.ConfigError, match=r"augment.*square floor"):
        planner.PlannerConfig(scenario=str(narrow), augment=True).check()


def test_loading_the_planner_again_reproduces_every_action(trained):
    """Two loads of the checkpoint act identically on every step of whole episodes (the actions also move the env)."""
    env = TaskAllocEnv("train_small", invalid_action="raise", **OVERRIDES)
    assert_same_actions(env, make_policy(f"learned:{trained}"), make_policy(f"learned:{trained}"), (2, 3))


def rewritten(trained, tmp_path, **meta):
    """A copy of the trained checkpoint with its meta changed (None removes a key)."""
    spec = json.loads((trained / "model.json").read_text())
    spec["meta"].update(meta)
    spec["meta"] = {k: v for k, v in spec["meta"].items() if v is not None}
    (tmp_path / "model.json").write_text(json.dumps(spec))
    (tmp_path / "model.safetensors").write_bytes((trained / "model.safetensors").read_bytes())
    return tmp_path


@pytest.mark.parametrize("meta, words", [
    ({"then": None}, ["meta 'then'", "got None"]),
    ({"then": 3}, ["meta 'then'", "got 3"]),
    ({"threshold": 1.5}, ["meta 'threshold'", "1.5"]),
    ({"then": "nosuch"}, ["unknown policy 'nosuch'"]),
    ({"replan": "no"}, ["meta 'replan'", "true or false", "'no'"]),
])
def test_a_planner_checkpoint_with_bad_meta_is_refused_by_name(trained, tmp_path, meta, words):
    with pytest.raises(ValueError) as exc:
        make_policy(f"learned:{rewritten(trained, tmp_path, **meta)}")
    assert all(w in str(exc.value) for w in words), exc.value


def test_the_checkpoint_says_whether_the_planner_replans(trained, tmp_path):
    """A short run saves its ``replan`` (true by default) and a checkpoint without the key replans, as planners did
    before the option; a checkpoint with ``replan: false`` plans once."""
    assert json.loads((trained / "model.json").read_text())["meta"]["replan"] is True
    assert make_policy(f"learned:{trained}").first.replan is True
    (tmp_path / "old").mkdir()
    (tmp_path / "once").mkdir()
    assert make_policy(f"learned:{rewritten(trained, tmp_path / 'old', replan=None)}").first.replan is True
    assert make_policy(f"learned:{rewritten(trained, tmp_path / 'once', replan=False)}").first.replan is False


def test_a_planner_that_hands_over_to_a_planner_is_refused(trained, tmp_path):
    """A 'then' naming a planner (here a copy inside its folder) is refused, and naming itself too, at once."""
    folder, inner = tmp_path / "outer", tmp_path / "outer" / "inner"
    inner.mkdir(parents=True)
    rewritten(trained, inner)
    with pytest.raises(CheckpointError, match="is itself a planner"):
        make_policy(f"learned:{rewritten(trained, folder, then='learned:inner')}")
    for itself in ("learned:.", "learned:model.json", "learned:model"):
        with pytest.raises(CheckpointError, match="names it again"):
            make_policy(f"learned:{rewritten(trained, folder, then=itself)}")
    with pytest.raises(ValueError, match="options \\['deterministic'\\] are not taken"):
        make_policy(f"learned:{trained}", deterministic=False)


@pytest.mark.parametrize("argv, words", [
    (["--solver", "sgama"], ["'solver'", "sgama", "exact | lns"]),
    (["--threshold", "1"], ["'threshold'", "(0, 1)"]),
    (["--then", "nosuch"], ["'then'", "unknown policy 'nosuch'"]),
    (["--episodes", "0"], ["'episodes'", ">= 1"]),
])
def test_a_bad_planner_config_is_one_line_and_exit_2(argv, words, tmp_path, capsys):
    assert run_cli(lambda: planner.main(["--config", "planner_default", "--out-dir", str(tmp_path / "run"),
                                         *argv])) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert all(w in err[0] for w in words), err[0]
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("name, scenario", [("planner_default", "default"), ("planner_small_attention", "train_small")])
def test_the_committed_planners_load_by_name_and_hand_over_to_the_committed_bidder(name, scenario):
    policy = make_policy(f"learned:{name}")
    assert isinstance(policy.first, RoundZeroPlanner) and policy.then.name == "learned:mappo_small_pooling_1m"
    env = TaskAllocEnv(scenario, **policy.env_overrides)
    allocation = rollout(env, policy, seed=10_000)
    assert allocation.converged and not allocation.conflicts and allocation.score > 0
