"""The communication layer: who receives which message when (``network.Network``), and what the consensus makes of
lost and delayed messages and failing agents."""

from __future__ import annotations

import re
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from helpers import agent, build, episode_digest, task

from taskalloc.policies import make_policy, rollout
from taskalloc_env import ConfigError, TaskAllocConfig, TaskAllocEnv
from taskalloc_env.network import CommGraph, Deliveries, GilbertElliott, IndependentLoss, Network

RNG = np.random.default_rng


def graph(n: int = 5, comm_range: float | None = None) -> CommGraph:
    return CommGraph(np.array([[float(i), 0.0, 0.0] for i in range(n)]), comm_range)


# -- delivery -----------------------------------------------------------------------------------------------------
def test_perfect_links_deliver_every_neighbour_message_at_once_in_sender_order():
    g = graph(5, comm_range=1.0)                                       # a line: 0-1-2-3-4
    net = Network(g)
    net.send(1, np.arange(5), np.ones(5, dtype=int))
    got = net.deliver(1, np.ones(5, dtype=bool))
    pairs = list(zip(got.receiver.tolist(), got.sender.tolist()))
    assert pairs == [(0, 1), (1, 0), (1, 2), (2, 1), (2, 3), (3, 2), (3, 4), (4, 3)]
    assert (got.sent == 1).all() and len(net.deliver(2, np.ones(5, dtype=bool))) == 0
    assert [p.tolist() for p in got.positions()] == [[0, 1, 3, 5, 7], [2, 4, 6]]


def test_perfect_links_deliver_what_the_general_path_delivers():
    """Perfect links skip the loss and delay draws; a lossy network that loses nothing (p = 0) takes the general
    path. Round after round, with senders dropping out and a receiver dead, both deliver the same messages."""
    g = graph(6, comm_range=2.0)
    perfect, general = Network(g), Network(g, IndependentLoss(0.0), rng=RNG(4))
    assert perfect.perfect and not general.perfect
    alive = np.ones(6, dtype=bool)
    for now, senders in enumerate([np.arange(6), np.arange(6), np.array([0, 2, 5]), np.arange(1, 6)], start=1):
        alive[4] = now < 3
        items = np.arange(6) + now
        a, b = perfect.send(now, senders, items), general.send(now, senders, items)
        assert a == b
        got, want = perfect.deliver(now, alive), general.deliver(now, alive)
        for field in ("receiver", "sender", "sent"):
            assert np.array_equal(getattr(got, field), getattr(want, field))
        assert len(got) and len(perfect.in_flight()) == len(general.in_flight()) == 0


def test_independent_loss_drops_the_requested_share():
    g = graph(20)
    net = Network(g, IndependentLoss(0.2), rng=RNG(1))
    sent = lost = 0
    for r in range(1, 51):
        out = net.send(r, np.arange(20), np.ones(20, dtype=int))
        sent, lost = sent + out.sent, lost + out.lost
        assert len(net.deliver(r, np.ones(20, dtype=bool))) == out.sent - out.lost
    share, sd = lost / sent, np.sqrt(0.2 * 0.8 / sent)
    assert sent == 50 * 20 * 19 and abs(share - 0.2) < 4 * sd


def test_gilbert_elliott_loses_messages_in_bursts():
    """After a loss on a link the next message on that link is lost far more often than on average."""
    model = GilbertElliott(2, loss_good=0.0, loss_bad=1.0, enter_bad=0.05, leave_bad=0.3)
    rng = RNG(2)
    lost = np.array([model.lost(np.array([0]), np.array([1]), rng)[0] for _ in range(20000)])
    after_loss = lost[1:][lost[:-1]].mean()
    assert 0.05 < lost.mean() < 0.25 and after_loss > 0.6 > 2 * lost.mean()


def test_delays_are_bounded_and_dead_receivers_get_nothing():
    g = graph(4)
    net = Network(g, max_delay=3, rng=RNG(3))
    alive = np.array([True, True, True, False])
    net.send(1, np.arange(3), np.ones(4, dtype=int))
    arrived = [net.deliver(r, alive) for r in range(1, 5)]
    total = sum(len(d) for d in arrived)
    assert total == 3 * 3 - 3                    # 3 senders × 3 neighbours, minus the 3 messages to the dead agent 3
    for d in arrived:
        assert (d.sent == 1).all() and (d.receiver != 3).all()
    assert len(net.in_flight()) == 0


def test_deliveries_sort_old_messages_first():
    d = Deliveries.of(np.array([1, 1, 0, 1]), np.array([2, 0, 1, 3]), np.array([5, 5, 5, 4]))
    assert list(zip(d.receiver.tolist(), d.sent.tolist(), d.sender.tolist())) == [(0, 5, 1), (1, 4, 3), (1, 5, 0),
                                                                                  (1, 5, 2)]


# -- episodes under faults --------------------------------------------------------------------------------------------
FAULTS = {
    "loss": {"message_loss": 0.2},
    "bursts": {"loss_model": "gilbert_elliott", "message_loss": 0.02, "burst_enter": 0.1, "burst_leave": 0.4},
    "bursts-rho": {"loss_model": "gilbert_elliott_rho", "message_loss": 0.2, "burst_correlation": 0.8},
    "rayleigh": {"loss_model": "rayleigh"},
    "delay": {"max_delay": 2},
    "loss+delay": {"message_loss": 0.2, "max_delay": 2},
    "range+loss": {"comm_range": 2.5, "message_loss": 0.2},
    "dropouts": {"dropouts": 2, "dropout_rounds": [1, 4]},
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("policy", ["cbga", "cbgabi"])
def test_faulty_episodes_converge_agree_and_are_conflict_free(fault, policy):
    p = make_policy(policy)
    env = TaskAllocEnv("train_small", **FAULTS[fault], **p.env_overrides)
    for seed in range(6):
        allocation = rollout(env, p, seed=seed)
        assert allocation.converged, f"seed {seed}: hit the round bound"
        assert allocation.agreement and (not allocation.conflicts or "comm_range" in FAULTS[fault])
        counters = allocation.counters
        assert counters.messages_sent >= counters.messages + counters.messages_lost - 1e-9


def test_a_failed_agent_leaves_and_its_tasks_are_reassigned():
    """Agent 1 holds the task next to it; it fails in round 2. Agent 0 hears nothing from it for silence_timeout
    rounds, clears its bid, and takes the task; agent 1 leaves env.agents as terminated."""
    s = build([agent(0), agent(1)], [task(1, start=10, end=100), task(0, 1, start=10, end=100)])
    env = TaskAllocEnv(scenario=s, dropout_schedule=[[1, 2]], silence_timeout=3, invalid_action="raise")
    policy = make_policy("cbga")
    obs, infos = env.reset(seed=0)
    policy.start(env, 0)
    seen_exit = False
    while env.agents:
        obs, _, terminations, _, infos = env.step(policy.act({a: obs[a] for a in env.agents}, infos))
        if "uav_1" in terminations and terminations["uav_1"] and env.agents:
            assert env.agents == ["uav_0"]
            seen_exit = True
    allocation = env.evaluate()
    assert seen_exit and allocation.converged
    assert allocation.paths[1] == () and set(allocation.paths[0]) == {0, 1}
    assert allocation.counters.dropped_agents == 1 and allocation.counters.silent_releases >= 1


@pytest.mark.slow
def test_every_strategy_replays_byte_identically_across_processes():
    cases = [(policy, FAULTS[fault], seed) for fault in sorted(FAULTS) for policy in ("cbga", "random")
             for seed in (3, 4)]
    here = [episode_digest(c) for c in cases]
    with ProcessPoolExecutor(2) as pool:
        there = list(pool.map(episode_digest, cases))
    assert here == there
    assert len(set(here)) == len(here)


def test_faults_show_in_the_observation_and_the_counters():
    env = TaskAllocEnv("train_small", message_loss=0.3)
    assert "member_silence" in env.observation_layout.task_names
    assert "member_silence" not in TaskAllocEnv("train_small").observation_layout.task_names
    allocation = rollout(env, make_policy("cbga"), seed=1)
    assert allocation.counters.messages_lost > 0 and allocation.summary()["messages_lost"] > 0


@pytest.mark.parametrize("field, value, allowed", [
    ("message_loss", 1.5, "a probability in [0, 1]"),
    ("message_loss", -0.1, "a probability in [0, 1]"),
    ("burst_leave", 2, "a probability in [0, 1]"),
    ("max_delay", -1, "an integer >= 0"),
    ("loss_model", "carrier_pigeon", "independent | gilbert_elliott"),
    ("dropouts", 4, "fewer than n_agents"),
    ("dropout_schedule", [[7, 2]], "an agent id below n_agents"),
])
def test_bad_network_settings_name_the_field(field, value, allowed):
    with pytest.raises(ConfigError, match=f"'{field}'.*{re.escape(allowed)}"):
        TaskAllocEnv("train_small", **{field: value})


def test_a_failure_past_the_round_bound_is_refused():
    with pytest.raises(ConfigError, match="past the round bound"):
        TaskAllocEnv("train_small", dropout_schedule=[[1, 10_000]]).reset(seed=0)


def test_config_round_trip_keeps_the_network_fields():
    cfg = TaskAllocConfig(n_agents=4, n_tasks=3, agents_per_task=1, dropout_schedule=((1, 2),), message_loss=0.1)
    assert cfg.replace() == cfg and cfg.faulty and not TaskAllocConfig().faulty
