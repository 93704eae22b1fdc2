"""The peers' channel models (``faults.StationaryGilbertElliott``, ``faults.RayleighFading``) and the benchmarks'
per-episode measures (``Allocation``: ``max_travel``, ``counters.max_agent_messages``, ``workload_gini``,
``completion``, ``score_per_task``)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from helpers import agent, build, episode_digest, examples, task
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc.evaluation.episodes import Episode, run_episode
from taskalloc.policies import make_policy, rollout
from taskalloc_env import ConfigError, TaskAllocConfig, TaskAllocEnv
from taskalloc_env.allocation import Allocation, gini
from taskalloc_env.faults import NoLoss, RayleighFading, StationaryGilbertElliott
from taskalloc_env.network import CommGraph, Network
from taskalloc_env.scoring import ScoringModel

RNG = np.random.default_rng


# -- Gilbert–Elliott set by its stationary loss rate and lag-1 correlation ------------------------------------------
def loss_sequences(loss: float, rho: float, n_agents: int = 40, messages: int = 300, seed: int = 0) -> np.ndarray:
    """(links, messages) whether each message on each directed link of a complete graph was lost."""
    model = StationaryGilbertElliott(n_agents, loss, rho)
    sender, receiver = np.nonzero(~np.eye(n_agents, dtype=bool))
    rng = RNG(seed)
    return np.stack([model.lost(sender, receiver, rng) for _ in range(messages)], axis=1)


@pytest.mark.parametrize("loss, rho", [(0.1, 0.8), (0.25, 0.8), (0.5, 0.0), (0.7, 0.5), (0.3, 0.95)])
def test_the_chain_has_the_stationary_loss_rate_and_lag_one_correlation_it_was_given(loss, rho):
    """Over 1560 links × 300 messages: the share lost is ℓ, the lag-1 autocorrelation of a link's losses is ρ, and
    the first message on every link already sees the stationary distribution (links start from it)."""
    lost = loss_sequences(loss, rho).astype(float)
    mean = lost.mean()
    lag1 = ((lost[:, :-1] - mean) * (lost[:, 1:] - mean)).mean() / lost.var()
    assert abs(mean - loss) < 0.02
    assert abs(lag1 - rho) < 0.02
    first, sd = lost[:, 0].mean(), math.sqrt(loss * (1 - loss) / lost.shape[0])
    assert abs(first - loss) < 4 * sd


def test_the_transition_probabilities_are_the_benchmarks_persistences():
    """p_GG = q + ρ(1 − q) and p_BB = (1 − q) + ρq with q = 1 − ℓ; their sum minus one is ρ."""
    for loss, rho in [(0.1, 0.8), (0.6, 0.3), (0.0, 0.5), (1.0, 0.0)]:
        model, q = StationaryGilbertElliott(2, loss, rho), 1 - loss
        p_gg, p_bb = 1 - model.enter_bad, 1 - model.leave_bad
        assert p_gg == pytest.approx(q + rho * (1 - q)) and p_bb == pytest.approx((1 - q) + rho * q)
        assert p_gg + p_bb - 1 == pytest.approx(rho)


def test_no_stationary_loss_is_the_perfect_network_and_full_loss_loses_everything():
    env = TaskAllocEnv("train_small", loss_model="gilbert_elliott_rho")
    env.reset(seed=0)
    assert isinstance(env.protocol.network.loss, NoLoss) and env.protocol.network.perfect
    assert loss_sequences(1.0, 0.8, n_agents=3, messages=20).all()
    assert not TaskAllocConfig(loss_model="gilbert_elliott_rho").faulty
    assert TaskAllocConfig(loss_model="gilbert_elliott_rho", message_loss=0.2).faulty


# -- Rayleigh fading --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("reference, exponent", [(5.0, 2.0), (3.0, 3.0)])
def test_rayleigh_delivery_matches_its_formula_at_two_distances_and_falls_with_distance(reference, exponent):
    positions = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 6.0, 0.0]])
    model = RayleighFading(positions, reference, exponent)
    rng, k = RNG(5), 100_000
    delivered = []
    for receiver, d in ((1, 2.0), (2, 6.0)):
        share = 1 - model.lost(np.zeros(k, dtype=np.int64), np.full(k, receiver), rng).mean()
        want = math.exp(-((d / reference) ** exponent))
        assert abs(share - want) < 4 * math.sqrt(want * (1 - want) / k) + 1e-9
        delivered.append(share)
    assert delivered[0] > delivered[1]


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(st.floats(0.0, 50.0), min_size=2, max_size=8), st.floats(0.1, 20.0), st.floats(0.5, 10.0))
def test_rayleigh_delivery_never_rises_with_distance(xs, reference, exponent):
    positions = np.array([[x, 0.0, 0.0] for x in sorted(xs)])
    delivery = RayleighFading(positions - positions[0], reference, exponent).delivery[0]
    assert np.all(np.diff(delivery) <= 0) and delivery[0] == 1.0
    assert np.allclose(delivery, np.exp(-((positions[:, 0] - positions[0, 0]) / reference) ** exponent))


def test_the_environment_hands_the_agents_start_positions_to_the_loss_model():
    """The delivery matrix is the formula over the instance's agent distances: agents together always hear each
    other, agents far apart (d ≫ d0) almost never."""
    env = TaskAllocEnv("train_small", loss_model="rayleigh", fading_distance=2.0, fading_exponent=3.0)
    env.reset(seed=3)
    pos = env.scenario.agent_pos
    distance = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    assert np.allclose(env.protocol.network.loss.delivery, np.exp(-((distance / 2.0) ** 3)))
    together = build([agent(0), agent(0, 0.01), agent(0.01)], [task(1), task(2)])
    far = build([agent(0), agent(100), agent(200)], [task(1), task(2)], arena=(300.0, 300.0, 10.0))
    lost = {}
    for name, scenario in (("together", together), ("far", far)):
        env = TaskAllocEnv(scenario=scenario, loss_model="rayleigh", fading_distance=5.0, max_rounds=30)
        allocation = rollout(env, make_policy("cbga"), seed=0)
        lost[name] = allocation.counters.messages_lost / allocation.counters.messages_sent
    assert lost["together"] == 0.0 and lost["far"] == 1.0


# -- bad input and determinism ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("field, value, allowed", [
    ("burst_correlation", 1.0, "a number >= 0 and < 1"),
    ("burst_correlation", -0.1, "a number >= 0 and < 1"),
    ("burst_correlation", 1.5, "a number >= 0 and < 1"),
    ("fading_distance", 0.0, "a number > 0"),
    ("fading_distance", -3.0, "a number > 0"),
    ("fading_exponent", 0.0, "a number > 0 and within ±10"),
    ("fading_exponent", 11.0, "a number > 0 and within ±10"),
    ("message_loss", 1.2, "a probability in [0, 1]"),
    ("loss_model", "rician", "independent | gilbert_elliott | gilbert_elliott_rho | rayleigh"),
])
def test_bad_channel_settings_are_one_line_errors_naming_the_field_and_the_range(field, value, allowed):
    with pytest.raises(ConfigError, match=f"'{field}'.*{re.escape(allowed)}") as info:
        TaskAllocEnv("train_small", **{"loss_model": "gilbert_elliott_rho", field: value})
    assert "\n" not in str(info.value)


CHANNELS = {"rho": {"loss_model": "gilbert_elliott_rho", "message_loss": 0.2, "burst_correlation": 0.8},
            "rayleigh": {"loss_model": "rayleigh"}}


@pytest.mark.parametrize("channel", sorted(CHANNELS))
def test_a_channel_replays_from_its_seed(channel):
    runs = [episode_digest(("cbga", CHANNELS[channel], seed)) for seed in (2, 2, 3)]
    assert runs[0] == runs[1] != runs[2]


@pytest.mark.parametrize("channel", sorted(CHANNELS))
@pytest.mark.parametrize("policy", ["cbga", "cbgabi", "acbba"])
def test_episodes_on_the_peers_channels_lose_messages_and_still_agree(channel, policy):
    p = make_policy(policy)
    overrides = {"agents_per_task": 1} if policy == "acbba" else {}
    env = TaskAllocEnv("train_small", **CHANNELS[channel], **overrides, **p.env_overrides)
    lost = 0
    for seed in range(4):
        allocation = rollout(env, p, seed=seed)
        assert allocation.converged and allocation.agreement, f"seed {seed}"
        lost += allocation.counters.messages_lost
    assert lost > 0


# -- the per-episode measures -----------------------------------------------------------------------------------------
def hand_built() -> tuple[ScoringModel, Allocation]:
    """Agent 0 flies (0,0) → (3,0) → (3,4): 7 km, two valid tasks (both reached before their windows open); agent 1
    (10,0) → (10,5): 5 km, one; agent 2 (20,0) → (20,1): 1 km to a task needing two agents, which it holds alone (not
    valid). γ = 10 per km, rewards 100."""
    s = build([agent(0), agent(10), agent(20)],
              [task(3), task(3, 4, start=110), task(10, 5), task(20, 1, agents=2)], arena=(30.0, 30.0, 10.0))
    model = ScoringModel(s)
    return model, Allocation.from_paths(model, [[0, 1], [2], [3]])


def test_every_measure_on_a_hand_built_allocation():
    _, a = hand_built()
    assert a.travel == pytest.approx((7.0, 5.0, 1.0)) and a.max_travel == pytest.approx(7.0)
    assert a.valid_tasks == (0, 1, 2) and a.completion == pytest.approx(3 / 4)
    assert a.score == pytest.approx(300 - 10 * 13) and a.score_per_task == pytest.approx(170 / 3)
    assert a.tasks_serviced == (2, 1, 0) and a.workload_gini == pytest.approx(4 / 9)
    summary = a.summary()
    assert summary["max_travel"] == a.max_travel and summary["workload_gini"] == a.workload_gini
    assert summary["completion"] == 0.75 and summary["max_agent_messages"] == 0     # no protocol ran


def test_an_allocation_that_completes_nothing_has_no_efficiency():
    model, _ = hand_built()
    nothing = Allocation.from_paths(model, [[], [], [3]])
    assert nothing.completion == 0.0 and nothing.score_per_task is None
    assert nothing.workload_gini == 0.0 and nothing.max_travel == pytest.approx(1.0)


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(st.integers(0, 20), min_size=1, max_size=12))
def test_gini_is_the_mean_absolute_difference_over_twice_the_mean(xs):
    x = np.array(xs, dtype=float)
    want = 0.0 if x.sum() == 0 else np.abs(x[:, None] - x[None]).sum() / (2 * len(x) ** 2 * x.mean())
    assert gini(xs) == pytest.approx(want, abs=1e-12)
    assert 0.0 <= gini(xs) <= 1 - 1 / len(xs) + 1e-12


def test_gini_cells():
    assert gini([]) == 0.0 and gini([0, 0]) == 0.0 and gini([3, 3, 3]) == 0.0
    assert gini([0, 0, 3]) == pytest.approx(2 / 3) and gini([1, 3]) == pytest.approx(0.25)


def test_the_network_counts_the_messages_each_agent_sends():
    net = Network(CommGraph(np.array([[float(i), 0.0, 0.0] for i in range(4)]), 1.0))     # a line 0-1-2-3
    for now in (1, 2):
        net.send(now, np.arange(4), np.ones(4, dtype=int))
    net.send(3, np.array([0]), np.ones(4, dtype=int))
    assert net.sent_by.tolist() == [3, 4, 4, 2]


@pytest.mark.parametrize("policy, overrides", [("cbga", {"comm_range": 2.5}), ("cbga", {"message_loss": 0.3}),
                                               ("acbba", {"agents_per_task": 1})])
def test_the_busiest_agents_messages_reach_the_counters(policy, overrides):
    """Synchronous agents all broadcast every round, so the busiest sends its degree × rounds; under ACBBA the
    busiest sender's count is the network's."""
    p = make_policy(policy)
    env = TaskAllocEnv("train_small", **overrides, **p.env_overrides)
    allocation = rollout(env, p, seed=1)
    c, net = allocation.counters, env.protocol.network
    assert c.max_agent_messages == net.sent_by.max() and net.sent_by.sum() == c.messages_sent
    if policy == "cbga":
        assert c.max_agent_messages == env.protocol.graph.degree.max() * c.rounds


def test_the_measures_reach_the_episode_rows():
    cfg = TaskAllocConfig(n_agents=4, n_tasks=6, agents_per_task=1)
    rows = {solver: run_episode(Episode(solver, cfg, 0)) for solver in ("cbga", "sgama")}
    for row in rows.values():
        assert row["completion"] == row["valid_tasks"] / 6 and row["max_travel"] > 0
        assert row["score_per_task"] == pytest.approx(row["score"] / row["valid_tasks"])
        assert 0 <= row["workload_gini"] < 1
    assert rows["cbga"]["max_agent_messages"] == 3 * rows["cbga"]["rounds"]
    assert rows["sgama"]["max_agent_messages"] is None          # a centralised solver sends nothing
