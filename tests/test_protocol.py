"""The consensus protocol: exchange, timestamps, multi-hop propagation, outbid release, quit timers and quitting,
discovery, message accounting, convergence, and the consensus steps of the thesis's Appendix A.

Sources: thesis §4.2.2 and §4.3 (messages, discovery, data volume), eq. (2.4) and Alg 6 l. 24 (timestamps),
§2.2.4 (release), §3.2.3 (exchange and iteration), §5.2.2 and Alg 9 (quitting), App. A.1–A.2; Johnson §3.4.1
(release (3.11)–(3.12), the CBBA round bound); article eq. (10). Convergence detection is our rule
(docs/decisions.md).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import agent, build, check_tables, run_episode, tables, task

from taskalloc.policies import CBBAPolicy, CBGAPolicy, PassPolicy
from taskalloc_env import TaskAllocConfig, TaskAllocEnv, generate
from taskalloc_env.cbba_table import NONE
from taskalloc_env.consensus import broadcast_round
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.network import CommGraph
from taskalloc_env.protocol import Protocol, ProtocolError
from taskalloc_env.scenario import scenario_config


def protocol(s, **options) -> Protocol:
    return Protocol(s, scenario_config(s, **options))


def line_positions(n: int, spacing: float = 1.0) -> np.ndarray:
    return np.array([[spacing * i, 0.0, 0.0] for i in range(n)])


# -- outbid release (thesis §2.2.4; Johnson (3.11)–(3.12)) ----------------------------------------------------------
def release_scenario(agents_per_task: int):
    """Agent 0 at the origin values T0, T1, T2 at 80 each (γ = 10, 2 away, with the start-distance cost the tests
    set); windows open at 100, 200, 300, so the path order is T0, T1, T2 whatever the bundle order. Agents 1 and 2 sit
    0.5 from T0 and bid 95 on it."""
    agents = [agent(0), agent(2, 0.5), agent(2, -0.5)]
    tasks = [task(2, start=100, agents=agents_per_task), task(0, 2, start=200, agents=agents_per_task),
             task(0, 0, 2, start=300, agents=agents_per_task)]
    return build(agents, tasks)


@pytest.mark.parametrize("order, kept", [("bundle", [2]), ("path", [])])
def test_outbid_release_single_agent_tasks(order, kept):
    p = protocol(release_scenario(1), release_order=order, distance_cost="from_start")
    for j in (2, 0, 1):                             # bundle (T2, T0, T1), path (T0, T1, T2)
        assert p.bid(0, j) == pytest.approx(80.0)
    assert p.knowledge.bundles[0] == [2, 0, 1] and p.knowledge.paths[0] == [0, 1, 2]
    p.bid(1, 0)
    p.end_round()
    kn = p.knowledge
    assert kn.bundles[0] == kept and kn.paths[0] == kept
    # the lost task keeps the new winner's entry (only n > n̄ is reset; Johnson (3.11) prints n ≥ n̄)
    assert kn.winner[0, 0] == 1 and kn.groups.bid(0, 1, 0) == pytest.approx(95.0)
    # released tasks: own bids zeroed in the same iteration, no winner left behind
    for j in {0, 1, 2} - set(kept):
        assert kn.groups.bid(0, 0, j) == 0
    assert kn.winner[0, 1] == NONE
    for j in kept:
        assert kn.groups.bid(0, 0, j) == pytest.approx(80.0) and kn.winner[0, j] == 0
    check_consistency(p)


@pytest.mark.parametrize("order, kept", [("bundle", [2]), ("path", [])])
def test_outbid_release_multi_agent_eviction(order, kept):
    """L = 2: agents 1 and 2 (95 each) push agent 0 (80) out of T0 in Pass B; agent 0 releases T0 and what follows."""
    p = protocol(release_scenario(2), release_order=order, distance_cost="from_start")
    for j in (2, 0, 1):
        p.bid(0, j)
    p.bid(1, 0)
    p.bid(2, 0)
    p.end_round()
    kn = p.knowledge
    assert kn.bundles[0] == kept
    assert kn.groups.bid(0, 0, 0) == 0
    assert kn.groups.bid(0, 1, 0) == pytest.approx(95.0) and kn.groups.bid(0, 2, 0) == pytest.approx(95.0)
    for j in {1, 2} - set(kept):
        assert kn.groups.bid(0, 0, j) == 0
    check_consistency(p)


def check_consistency(p: Protocol) -> None:
    kn = p.knowledge
    for i, b in enumerate(kn.bundles):
        assert set(b) == set(np.flatnonzero(tables(kn)[i, i] > 0).tolist())
        assert sorted(b) == sorted(kn.paths[i])


def test_bid_on_a_full_group_displaces_the_minimum_locally():
    """Our choice (docs/decisions.md): a bid into a full task zeroes the displaced member's entry so n_j ≤ L_j."""
    s = build([agent(0), agent(1), agent(2)], [task(1, agents=2)])
    p = protocol(s)
    p.bid(1, 0)
    p.bid(2, 0)                                       # agent 2 is 1 away: 90; agent 1 is on it: 100
    p.end_round()
    assert p.knowledge.member_counts()[0, 0] == 2
    with pytest.raises(ProtocolError):                # agent 0 (90 = agent 2's 90, lower id) cannot outbid
        p.bid(0, 0)
    s2 = build([agent(1.5), agent(1), agent(3)], [task(1, agents=2)])
    p = protocol(s2)
    p.bid(1, 0)
    p.bid(2, 0)                                       # 80
    p.end_round()
    p.bid(0, 0)                                       # 95 beats the minimum 80 of agent 2
    assert p.knowledge.groups.bid(0, 2, 0) == 0 and p.knowledge.groups.bid(0, 0, 0) > 0
    assert p.knowledge.member_counts()[0, 0] == 2


# -- timestamps (2.4) and multi-hop propagation ----------------------------------------------------------------------
def line_protocol(n: int, tasks, **options) -> Protocol:
    agents = [agent(float(i)) for i in range(n)]
    return protocol(build(agents, tasks), comm_range=1.0, **options)


@pytest.mark.parametrize("agents_per_task", [1, 2])
def test_bid_reaches_the_far_end_after_d_rounds(agents_per_task):
    """A bid travels one hop per round (messages are snapshots, our choice; thesis §4.3: a bid needs up to D rounds):
    on a line of 5 (D = 4) agent 4 learns agent 0's bid in round 4, not earlier; the table rules rely on relayed
    stamps for this (thesis eq. (2.4))."""
    p = line_protocol(5, [task(2, agents=agents_per_task)])
    assert p.graph.diameter == 4
    p.bid(0, 0)
    bid = p.knowledge.groups.bid(0, 0, 0)
    for r in range(1, 6):
        p.end_round()
        knows = tables(p.knowledge)[:, 0, 0] == bid
        assert knows.tolist() == [a <= r for a in range(5)], f"after round {r}"


def test_agreement_holds_only_once_every_table_in_the_component_is_the_same():
    """``Protocol.agreement`` (thesis §3.2.3): on a line of 5 a bid is known up to agent r after round r, so the
    tables differ until round 4 and agree from then on."""
    p = line_protocol(5, [task(2)])
    p.bid(0, 0)
    seen = []
    for _ in range(5):
        p.end_round()
        seen.append(p.agreement())
    assert seen == [False, False, False, True, True]


def test_timestamps_follow_2_4():
    """s_ik = τ for neighbours; otherwise the freshest neighbour value (relayed one hop per round); s_ii = τ."""
    p = line_protocol(5, [task(2)])
    for r in range(1, 5):
        p.end_round()
        s = p.knowledge.timestamps
        for i in range(5):
            for k in range(5):
                hops = abs(i - k)
                expected = r if hops <= 1 else max(r - hops + 1, 0)
                assert s[i, k] == expected, f"round {r}: s_{i}[{k}]"


def test_timestamp_is_stamped_after_conflict_resolution():
    """Ecosystem bug #3 (SPACE PR #46): stamping before processing makes s_k[m] > s_i[m] always false. On the line
    0–1–2, agent 2's bid reaches agent 0 only through the rule 'sender believes m, receiver none: update if
    s_k[m] > s_i[m]', which needs s_1[2] = 1 > s_0[2] = 0 when agent 0 processes round 2."""
    p = line_protocol(3, [task(2)])
    p.bid(2, 0)
    p.end_round()
    kn = p.knowledge
    assert kn.winner[1, 0] == 2 and kn.winner[0, 0] == NONE
    assert kn.timestamps[1, 2] > kn.timestamps[0, 2]
    p.end_round()
    assert kn.winner[0, 0] == 2


def test_relayed_release_propagates():
    """A dropped bid spreads (Johnson (3.11)–(3.12) and Table 3.1): on the line 0–1–2, agent 2 bids T0 then T1;
    agent 1 outbids it on T0, so agent 2 releases T1 (added after T0). Agent 0 first learns agent 2 holds T1
    (relayed), then — through the rule 'sender believes none, receiver believes m: update if s_k[m] > s_i[m]' —
    that nobody does."""
    agents = [agent(0), agent(1), agent(2)]
    tasks = [task(1, 0.1, start=100), task(2, 0, 1, start=200)]
    p = protocol(build(agents, tasks), comm_range=1.0)
    p.bid(2, 0)
    p.bid(2, 1)
    p.bid(1, 0)                                      # 99 against agent 2's ≈ 89.9
    p.end_round()                                    # round 1
    kn = p.knowledge
    assert kn.bundles[2] == [], "agent 2 lost T0 and released T1 that was added after it"
    assert tables(kn)[2, 2].tolist() == [0.0, 0.0]
    p.end_round()                                    # round 2: agent 0 hears agent 1's round-1 view
    assert kn.winner[0].tolist() == [1, 2]
    p.end_round()                                    # round 3: the release reaches agent 0
    assert kn.winner[:, 0].tolist() == [1, 1, 1]
    assert kn.winner[:, 1].tolist() == [NONE, NONE, NONE]


# -- discovery (thesis §4.2.2, Table 4.5) and isolation (thesis §4.3) ------------------------------------------------
def test_agents_discover_their_component_through_bids():
    """Each agent bids its own task: after D rounds every agent knows every agent of the line (discovery by triples)."""
    n = 4
    p = line_protocol(n, [task(float(i), 0.3) for i in range(n)], require_known_capacity=True)
    assert p.knowledge.known.tolist() == np.eye(n, dtype=bool).tolist()
    for i in range(n):
        p.bid(i, i)
    for _ in range(p.graph.diameter):
        p.end_round()
    assert p.knowledge.known.all()


def test_agents_discover_their_component_without_bids():
    """Thesis §4.2.2: agents starting with only themselves know every agent in their component within D
    iterations. Messages carry the timestamp vector as (agentID, time) pairs (our choice), so IDs spread even when
    nobody has bid yet."""
    n = 4
    p = line_protocol(n, [task(1, agents=2)], require_known_capacity=True)
    for _ in range(p.graph.diameter):
        p.end_round()
    known = p.knowledge.known.astype(int).tolist()
    assert known == [[1] * n] * n, f"known after D rounds: {known}"


def test_require_known_capacity_gates_multi_agent_bids():
    """``require_known_capacity`` (after thesis §4.3): knowing only itself, an agent places no bid on an L_j > 1
    task; after first contact with a neighbour it may. An isolated agent never may, though it may bid on
    single-agent tasks."""
    agents = [agent(0), agent(1), agent(5)]
    tasks = [task(0.5, agents=2), task(4.5)]
    p = protocol(build(agents, tasks), comm_range=1.0, require_known_capacity=True)
    v = p.view()
    assert not v.can_bid[:, 0].any()
    assert v.can_bid[:, 1].all()
    p.end_round()
    v = p.view()
    assert v.can_bid[:, 0].tolist() == [True, True, False]
    for _ in range(3):
        p.end_round()
        assert not p.view().can_bid[2, 0]


@pytest.mark.parametrize("edge_rule, linked", [("dist", False), ("circles_overlap", True)])
def test_edge_rule(edge_rule, linked):
    """``edge_rule`` (our choice, thesis §4.3): ``dist`` links agents within r, ``circles_overlap`` within 2r."""
    graph = CommGraph(np.array([[0.0, 0, 0], [3.0, 0, 0]]), comm_range=2.0, edge_rule=edge_rule)
    assert bool(graph.adjacency[0, 1]) is linked and bool(graph.adjacency[1, 0]) is linked
    assert bool(np.isfinite(graph.hops).all()) is linked and graph.diameter == (1 if linked else 0)


def test_agents_with_several_equipment_items_are_refused():
    """One equipment type per agent (|ae_i| = 1 in every experiment, thesis §3.3.4). With an agent carrying B and C
    on a task needing {B, C}, coverage counted as a multiset union depends on the order members join, and two agents
    can converge on different tables; such scenarios are refused with the reason."""
    with pytest.raises(ValueError, match="several equipment items"):
        build([agent(0, equipment=("B",)), agent(3, equipment=("B", "C"))],
              [task(2, agents=2, equipment=("B", "C"))])


# -- message accounting (thesis §4.2.2, §4.3) -----------------------------------------------------------------------
def test_message_and_data_item_accounting():
    """One message per (sender, receiver) pair; a message holds 3·u + N_n items, u = positive entries of the sender's
    table."""
    n = 4
    tasks = [task(0.5, agents=2), task(2.5), task(1.5, agents=2)]
    p = line_protocol(n, tasks)
    p.bid(0, 0)
    p.bid(1, 0)
    p.bid(3, 1)
    positive = (tables(p.knowledge) > 0).sum(axis=(1, 2))          # before the round: 1, 1, 0, 1
    degree = np.array([1, 2, 2, 1])
    traffic = p.end_round()
    assert traffic.messages == degree.sum() == 6
    assert traffic.data_items == int(np.sum(degree * (3 * positive + n)))
    assert p.counters.messages == 6


def test_converged_message_size_formula():
    """Thesis §4.3: at convergence (full comms) each message holds 3·Σ_j |members(j)| + N_n ≤ 3·Σ_j L_j + N_n items."""
    s = generate(TaskAllocConfig(n_agents=4, n_tasks=5, agents_per_task=2, start_time_range=(0.0, 20.0)),
                 np.random.default_rng(3))
    env = TaskAllocEnv(scenario=s, agents_per_task=2)
    run_episode(env, CBGAPolicy(), seed=0)
    p = env.protocol
    members = (p.knowledge.groups.dense(0) > 0).sum()
    traffic = p.end_round()
    per_message = 3 * members + s.n_agents
    assert traffic.data_items == traffic.messages * per_message
    assert per_message <= 3 * s.task_agents.sum() + s.n_agents


# -- quitting (thesis §5.2.2, Alg 9, (5.6); article eq. (10)) ---------------------------------------------------------
def quit_scenario():
    """Three agents, T0 needs all three (L = 3), T1 is a single-agent task after it."""
    return build([agent(0), agent(1), agent(2)], [task(1, agents=3, start=100), task(1, 1, start=200)])


@pytest.mark.parametrize("joiner", [True, False])
def test_quit_timer_sync(joiner):
    """Group timer (thesis §5.2.2; Alg 9 l. 4–5): agent 0 joins T0 at T = 3 (H = 3); with δ = 1 its quit is due at
    T = 5. A member that appears in its column at T = 5 resets H to 5 and stops the quit; without the joiner the quit
    is allowed at T = 5."""
    p = protocol(quit_scenario(), task_quitting=True, delta=1)
    for _ in range(3):
        p.end_round()
    assert p.round == 3
    p.bid(0, 0)
    assert p.knowledge.assigned_at[0, 0] == 3
    p.end_round()                                    # T = 4
    assert not p.quit_options()[0, 0]                # 4 − 3 = 1, not > δ
    if joiner:
        p.bid(1, 0)
    p.end_round()                                    # T = 5: agent 0 sees agent 1 (or nobody)
    assert p.round == 5
    assert bool(p.quit_options()[0, 0]) is (not joiner)
    assert p.knowledge.assigned_at[0, 0] == (5 if joiner else 3)


def test_quit_releases_later_tasks_and_happens_once():
    """Alg 9 l. 6–8 and thesis §5.2.2: quitting zeroes i's bid, sets Q_i[j] = 1 and releases the tasks after j; the
    agent may bid on j again (quit_block = none) but can never quit it a second time."""
    p = protocol(quit_scenario(), task_quitting=True, delta=1, quit_block="none")
    p.bid(0, 0)
    p.bid(0, 1)
    for _ in range(2):
        p.end_round()
    assert p.quit_options()[0, 0] and not p.quit_options()[0, 1]       # T1 is a single-agent task
    released = p.quit(0, 0)
    kn = p.knowledge
    assert released == [1]
    assert kn.bundles[0] == [] and kn.groups.bid(0, 0, 0) == 0 and kn.groups.bid(0, 0, 1) == 0 and kn.quit[0, 0]
    assert p.view().can_bid[0, 0]
    p.bid(0, 0)
    for _ in range(4):
        p.end_round()
        assert not p.quit_options()[0, 0]
    with pytest.raises(ProtocolError):
        p.quit(0, 0)
    # the quit propagated: the other agents no longer list agent 0 from before (they list the new bid)
    assert kn.groups.bid(1, 0, 0) == kn.groups.bid(0, 0, 0)


def test_quit_preconditions():
    """Only with task_quitting on, only members, only incomplete groups, only after the timer (Alg 9 l. 2–6)."""
    s = quit_scenario()
    off = protocol(s, task_quitting=False)
    off.bid(0, 0)
    for _ in range(3):
        off.end_round()
    assert not off.quit_options().any()
    on = protocol(s, task_quitting=True, delta=1)
    on.bid(0, 0)
    on.bid(1, 0)
    on.bid(2, 0)                                     # complete group
    for _ in range(4):
        on.end_round()
    assert not on.quit_options().any()
    on = protocol(s, task_quitting=True, delta=2)
    on.bid(0, 0)
    for t in range(1, 5):
        on.end_round()
        assert bool(on.quit_options()[0, 0]) is (t > 2)
        assert not on.quit_options()[1:].any()      # not members


def test_quit_block_until_joined():
    """The article's rule (after its eq. (10)), 'unfeasible until other agents assign themselves': no re-bid on j
    until another agent joins j; a member leaving does not lift the block."""
    p = protocol(quit_scenario(), task_quitting=True, delta=1, quit_block="until_joined")
    p.bid(0, 0)
    p.bid(2, 0)
    for _ in range(3):                                # both joined in round 0, heard of each other in round 1: H = 1
        p.end_round()
    p.quit(0, 0)
    assert not p.view().can_bid[0, 0]
    p.end_round()
    assert not p.view().can_bid[0, 0]
    p.quit(2, 0)                                      # a departure: still blocked
    p.end_round()
    assert not p.view().can_bid[0, 0] and p.view().members[0, 0] == 0
    p.bid(1, 0)                                       # another agent assigns itself: the block lifts
    p.end_round()
    assert p.view().can_bid[0, 0]


def test_quit_block_none_lets_the_quitter_bid_again_at_once():
    p = protocol(quit_scenario(), task_quitting=True, delta=1, quit_block="none")
    p.bid(0, 0)
    for _ in range(2):
        p.end_round()
    p.quit(0, 0)
    assert p.view().can_bid[0, 0]


def test_a_quit_the_others_list_is_seen():
    """``quits_seen``: agents 0 and 2 hold T0 (L = 3) and every table lists both after round 1; agent 0
    quits at T = 3 and, blocked by ``until_joined``, does not re-bid. The merge of round 4 drops agent 0 from T0 in
    the tables of agents 1 and 2: one quit, seen once (not once per agent, not again in later rounds)."""
    p = protocol(quit_scenario(), task_quitting=True, delta=1, quit_block="until_joined")
    p.bid(0, 0)
    p.bid(2, 0)
    for _ in range(3):
        p.end_round()
    assert (tables(p.knowledge)[:, 0, 0] > 0).all()
    p.quit(0, 0)
    assert (p.counters.quits, p.counters.quits_seen) == (1, 0)
    p.end_round()
    assert (tables(p.knowledge)[:, 0, 0] == 0).all()
    assert (p.counters.quits, p.counters.quits_seen) == (1, 1)
    for _ in range(3):
        p.end_round()
    assert p.counters.quits_seen == 1


def test_a_quit_re_bid_in_the_same_bundle_phase_is_not_seen():
    """The common case (985 of 989 quits at L_j = 4 were re-bid unseen): with ``quit_block=none`` the quitter bids on
    the task again before the round ends, the others' tables never drop it, and the quit goes unseen."""
    p = protocol(quit_scenario(), task_quitting=True, delta=1, quit_block="none")
    p.bid(0, 0)
    p.bid(2, 0)
    for _ in range(3):
        p.end_round()
    p.quit(0, 0)
    p.bid(0, 0)
    for _ in range(3):
        p.end_round()
        assert (tables(p.knowledge)[:, 0, 0] > 0).all()
    assert (p.counters.quits, p.counters.quits_seen) == (1, 0)


def test_a_quit_nobody_listed_is_not_seen():
    """A quit whose holder no other table lists yet (the quitter alone on a line out of range) is not seen, even
    when it is not re-bid: nothing reached another table."""
    s = build([agent(0), agent(5), agent(9)], [task(0, agents=3, start=100)])
    p = protocol(s, task_quitting=True, delta=1, quit_block="until_joined", comm_range=1.0)
    p.bid(0, 0)
    for _ in range(3):
        p.end_round()
    p.quit(0, 0)
    for _ in range(2):
        p.end_round()
    assert (p.counters.quits, p.counters.quits_seen) == (1, 0)


@pytest.mark.parametrize("reset_on, allowed", [("additions", True), ("any_change", False)])
def test_reset_on_a_member_leaving(reset_on, allowed):
    """A member leaving changes the column without adding anyone: only ``any_change`` resets the timer."""
    p = protocol(quit_scenario(), task_quitting=True, delta=0, reset_on=reset_on)
    p.bid(0, 0)
    p.bid(1, 0)
    p.end_round()                                    # T = 1: both see each other → H = 1
    assert p.knowledge.assigned_at[:2, 0].tolist() == [1, 1]
    p.end_round()                                    # T = 2
    p.quit(1, 0)
    p.end_round()                                    # T = 3: agent 0 sees agent 1 leave
    assert p.knowledge.member_counts()[0, 0] == 1
    assert bool(p.quit_options()[0, 0]) is allowed


# -- convergence (our stopping rule; Johnson §3.4.1's round bound for CBBA) -----------------------------------------
def test_convergence_needs_d_plus_one_stable_rounds():
    """Nobody bids on a line with D = 3: nothing changes, and the run converges after exactly D + 1 = 4 rounds with
    score 0 (empty bundles contribute 0)."""
    s = build([agent(float(i)) for i in range(4)], [task(1.5, agents=2)])
    env = TaskAllocEnv(scenario=s, comm_range=1.0)
    ep = run_episode(env, PassPolicy(), seed=0)
    assert env.protocol.graph.diameter == 3
    assert ep.allocation.counters.rounds == 4 and ep.steps == 4 and ep.allocation.converged
    assert ep.allocation.score == 0 and ep.episode_return == 0


def _graph_scenario(kind: str, seed: int):
    n = {"line": 5, "star": 5, "ring": 6, "full": 5}[kind]
    cfg = TaskAllocConfig(n_agents=n, n_tasks=6, agents_per_task=1, start_time_range=(0.0, 30.0))
    s = generate(cfg, np.random.default_rng(seed))
    if kind == "line":
        pos, comm = line_positions(n), 1.0
    elif kind == "star":
        angles = np.arange(n - 1) * 2 * np.pi / (n - 1)
        pos = np.vstack([[2.5, 2.5, 0.0], np.column_stack([2.5 + np.cos(angles), 2.5 + np.sin(angles), 0 * angles])])
        comm = 1.01
    elif kind == "ring":
        angles = np.arange(n) * 2 * np.pi / n
        pos, comm = np.column_stack([2.5 + np.cos(angles), 2.5 + np.sin(angles), 0 * angles]), 1.01
    else:
        pos, comm = s.agent_pos, None
    return dataclasses.replace(s, agent_pos=pos), comm


@pytest.mark.parametrize("kind, diameter", [("full", 1), ("star", 2), ("ring", 3), ("line", 4)])
@pytest.mark.parametrize("seed", range(4))
def test_cbba_converges_within_the_round_bound(kind, diameter, seed):
    """With DMG scores (frozen times, start-distance cost) CBBA agrees within min{N_t, L_t·N_a}·D rounds (Johnson
    §3.4.1 prints max{·}; SGA's count is min(·)·D, Johnson §3.3.2); the run then needs D + 1 quiet rounds to detect
    it. Tables agree at the end."""
    s, comm = _graph_scenario(kind, seed)
    env = TaskAllocEnv(scenario=s, comm_range=comm, agents_per_task=1, distance_cost="from_start",
                       marginal_gain="frozen")
    ep = run_episode(env, CBBAPolicy(), seed=seed, check=check_tables)
    p = env.protocol
    assert p.graph.diameter == diameter
    assert ep.allocation.converged
    bound = min(s.n_tasks, s.n_tasks * s.n_agents) * diameter
    assert ep.allocation.counters.rounds - (diameter + 1) <= bound
    for i in range(1, s.n_agents):
        assert np.array_equal(p.knowledge.groups.dense(i), p.knowledge.groups.dense(0))


# -- Appendix A (thesis App. A.1–A.2, Tables A.1–A.10; ties to the higher id, §3.2.3) ----------------------------------
A1, A2, A3, A4 = 0, 1, 2, 3
T1, T2, T3, T4, T5 = 0, 1, 2, 3, 4


def appendix_knowledge(single: bool) -> tuple[LocalKnowledge, CommGraph, Equipment, np.ndarray]:
    """4 agents on the line A1–A2–A3–A4, 5 tasks (L = 1 for A.1, L = 2 for A.2)."""
    kn = LocalKnowledge.empty(4, 5, np.full(5, 1 if single else 2), know_everyone=True)
    graph = CommGraph(line_positions(4), comm_range=1.0)
    eq = Equipment(np.zeros((4, 0), dtype=bool), np.zeros((5, 0), dtype=np.int64))
    return kn, graph, eq, np.full(5, 1 if single else 2)


def place(kn: LocalKnowledge, holder: int, bids: dict[int, float], bidder: int | None = None) -> None:
    for j, value in bids.items():
        kn.set_bid(holder, holder if bidder is None else bidder, j, value)


def single_view(kn: LocalKnowledge, i: int) -> list[tuple[int, float]]:
    """(winner, bid) per task as in the thesis's z/y tables (NONE, 0 for no winner)."""
    return [(int(kn.winner[i, j]), round(float(kn.winning_bid()[i, j]), 2)) for j in range(5)]


def test_appendix_a1_cbba_consensus_steps():
    """A.1: A1 keeps T1 (73.98 > 71.98) and loses T2, T3 on the tie (A2 > A1): Table A.3's z/y. A2, hearing A1 and
    A3, ends with Table A.4 (A3's bids as A.4 shows them). One round later A1 holds A2's Table A.4."""
    kn, graph, eq, need = appendix_knowledge(single=True)
    place(kn, A1, {T1: 73.98, T2: 71.56, T3: 72.44})            # Table A.1
    place(kn, A2, {T1: 71.98, T2: 71.56, T3: 72.44})            # Table A.2
    place(kn, A3, {T2: 72.44, T3: 72.44, T4: 73.6})             # A3's bids as they reach A2 (Table A.4)
    broadcast_round(kn, graph, 1, need, eq)
    assert single_view(kn, A1)[:4] == [(A1, 73.98), (A2, 71.56), (A2, 72.44), (NONE, 0.0)]    # Table A.3
    assert single_view(kn, A2)[:4] == [(A1, 73.98), (A3, 72.44), (A3, 72.44), (A3, 73.6)]     # Table A.4
    # second bundle phase: A1 releases T2, T3 and bids T5 = 67 (Table A.3); A2 bids T5 = 68.47 (Table A.4)
    place(kn, A1, {T5: 67.0})
    place(kn, A2, {T5: 68.47})
    assert single_view(kn, A1) == [(A1, 73.98), (A2, 71.56), (A2, 72.44), (NONE, 0.0), (A1, 67.0)]
    broadcast_round(kn, graph, 2, need, eq)
    assert single_view(kn, A1) == [(A1, 73.98), (A3, 72.44), (A3, 72.44), (A3, 73.6), (A2, 68.47)]


def multi_view(kn: LocalKnowledge, i: int) -> list[list[float]]:
    return np.round(kn.groups.dense(i), 2).tolist()


def test_appendix_a2_cbga_consensus_steps():
    """A.2 (L = 2): after the first exchange A1 holds Table A.7 and A2 holds Table A.8 — A2 evicted A1 from T2 by
    bid and from T3 by the tie-break (A3 > A2 > A1 at 72.4). After the second exchange A1 holds Table A.9 (except
    its new T5 bid, placed later in that bundle phase): A1 learned it lost T2 and T3."""
    kn, graph, eq, need = appendix_knowledge(single=False)
    place(kn, A1, {T1: 73.9, T2: 71.6, T3: 72.4})               # Table A.5
    place(kn, A2, {T1: 71.9, T2: 71.6, T3: 72.4})               # Table A.6
    place(kn, A3, {T2: 72.4, T3: 72.4, T4: 73.6})               # A3's row of Table A.8
    broadcast_round(kn, graph, 1, need, eq)
    table_a7 = [[73.9, 71.6, 72.4, 0, 0], [71.9, 71.6, 72.4, 0, 0], [0] * 5, [0] * 5]
    table_a8 = [[73.9, 0, 0, 0, 0], [71.9, 71.6, 72.4, 0, 0], [0, 72.4, 72.4, 73.6, 0], [0] * 5]
    assert multi_view(kn, A1) == table_a7
    assert multi_view(kn, A2) == table_a8
    broadcast_round(kn, graph, 2, need, eq)
    table_a9_without_t5 = [[73.9, 0, 0, 0, 0], [71.9, 71.6, 72.4, 0, 0], [0, 72.4, 72.4, 73.6, 0], [0] * 5]
    assert multi_view(kn, A1) == table_a9_without_t5
