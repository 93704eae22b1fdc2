"""Scripted baselines and centralised solvers: the decisions of the thesis's examples, CBBA = SGA, the 50% bound,
exact ≥ SGAMA ≥ ..., CBGABI's effect at L_j = N/1 (Fig 5.7/5.13), determinism, and policy plumbing.

Sources: thesis §5.1–5.3 (Fig 5.1, Fig 5.3, team bidding (5.5), quitting Alg 9), App. A.1–A.2 (Tables A.1–A.10),
§3.3.3 (SGAMA, Alg 7), §3.2.3 (single-agent tasks use the CBBA consensus); Johnson §3.3–3.4 (SGA, CBBA); Choi et
al. 2009 (CBBA = SGA, ≥ 50 % of optimal; restated in thesis §2.2.4, Johnson §1.2).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from helpers import (
    agent,
    build,
    check_converged_allocation,
    reference_team_score,
    replay,
    run_episode,
    tables,
    task,
)

from taskalloc.policies import (
    CBBAPolicy,
    CBGAPolicy,
    PassPolicy,
    RandomPolicy,
    exact,
    make_policy,
    rollout,
    sgama,
)
from taskalloc_env import TaskAllocConfig, TaskAllocEnv, generate
from taskalloc_env.cbba_table import NONE
from taskalloc_env.config import from_mapping

VARIANTS = [CBGAPolicy(), CBGAPolicy(task_quitting=True), CBGAPolicy(team_bidding=True),
            CBGAPolicy(team_bidding=True, task_quitting=True)]


def act_on(env: TaskAllocEnv, actions: dict[str, int]):
    """One env step with explicit actions (agents not named pass)."""
    return env.step({a: actions.get(a, 0) for a in env.agents})


# -- Appendix A bundle phases (thesis App. A.1, A.2) -----------------------------------------------------------------
def appendix_scenario(agents_per_task: int):
    """A1 (0,0), A2 (4,0), A3 (4,4), A4 (8,4): the line A1–A2–A3–A4 at range 4. λ = 0 and γ = 1 with the start
    distance cost, so c_ij = c̄_j − ‖pos_i − pos_j‖ wherever j fits. A1 and A2 are equidistant from T2 and T3, A3
    from T3 too, so their bids tie exactly as in the thesis: A1 = 73.98, 71.56, 72.44 and A2 = 71.98, 71.56, 72.44
    on T1–T3 (Tables A.1/A.2). T4 (window [0, 5]) is out of A1's reach; A3 bids 73.6 on it. T5 (A1: 67) overlaps
    T2's 60-minute duration, so A1 can fit it only once it has lost T2."""
    agents = [agent(0), agent(4), agent(4, 4), agent(8, 4)]
    tasks = [task(1, reward=74.98, start=100, agents=agents_per_task),
             task(2, 3, reward=71.56 + math.sqrt(13), start=200, end=205, duration=60, agents=agents_per_task),
             task(2, 2, reward=72.44 + math.sqrt(8), start=300, agents=agents_per_task),
             task(5, 4, reward=74.6, start=0, end=5, agents=agents_per_task),
             task(0, 1, reward=68.0, start=240, end=250, agents=agents_per_task)]
    return build(agents, tasks, time_discount=0.0, distance_discount=1.0, arena=(20.0, 20.0, 20.0))


def appendix_env(agents_per_task: int) -> TaskAllocEnv:
    """The appendix's agents share their raw bids (A2 bids 71.98 on T1, then 72.44 on T3): no ``bid_warping``."""
    env = TaskAllocEnv(scenario=appendix_scenario(agents_per_task), comm_range=4.0, distance_cost="from_start",
                       bid_warping=False)
    env.reset(seed=0)
    assert env.protocol.graph.adjacency.astype(int).tolist() == [[0, 1, 0, 0], [1, 0, 1, 0], [0, 1, 0, 1],
                                                                [0, 0, 1, 0]]
    return env


def first_bundle_phase(env: TaskAllocEnv, with_a3: bool) -> dict:
    """Round 0 as in Tables A.1/A.2 (A.5/A.6): A1 and A2 bid T1, T3, T2; A3 bids T4, T2, T3 (Table A.8's row).
    Returns the observations after the first exchange."""
    for a1, a2, a3 in ((1, 1, 4), (3, 3, 2), (2, 2, 3)):
        act_on(env, {"uav_0": a1, "uav_1": a2, **({"uav_2": a3} if with_a3 else {})})
    obs = act_on(env, {})[0]
    assert env.protocol.round == 1
    return obs


def test_appendix_a1_cbba_bundle_phase():
    """A.1: after hearing A2, A1 keeps T1, loses T2 and T3 on the tie-break, releases them, and re-bids only where it
    can beat the winning bids: not T2/T3 (equal bids, A2 > A1), not T4 (unreachable) — it bids T5 = 67 (Table A.3)."""
    env = appendix_env(1)
    gains = env.protocol.view().gain
    np.testing.assert_allclose(gains[0, :3], [73.98, 71.56, 72.44])
    np.testing.assert_allclose(gains[1, :3], [71.98, 71.56, 72.44])
    assert gains[0, 1] == gains[1, 1] and gains[0, 2] == gains[1, 2]
    obs = first_bundle_phase(env, with_a3=False)
    kn = env.protocol.knowledge
    assert kn.bundles[0] == [0]
    assert kn.winner[0].tolist() == [0, 1, 1, NONE, NONE]
    mask = obs["uav_0"]["action_mask"][1:6].astype(bool).tolist()
    assert mask == [False, False, False, False, True]
    policy = CBBAPolicy()
    policy.start(env)
    assert policy.act(obs)["uav_0"] == 1 + 4
    act_on(env, {"uav_0": 1 + 4})
    assert kn.groups.bid(0, 0, 4) == pytest.approx(67.0)


def test_appendix_a2_cbga_bundle_phases():
    """A.2 (L = 2): after the first exchange A1 sees room everywhere and changes nothing (Fig A.7, Table A.7);
    after the second it has been evicted from T2 and T3 (Table A.9), cannot re-enter them (tied with A2, the
    lower id loses), cannot reach T4, and bids T5 = 67 (Table A.9)."""
    env = appendix_env(2)
    obs = first_bundle_phase(env, with_a3=True)
    kn = env.protocol.knowledge
    policy = CBGAPolicy()
    policy.start(env)
    np.testing.assert_allclose(tables(kn)[0, :2], [[73.98, 71.56, 72.44, 0, 0], [71.98, 71.56, 72.44, 0, 0]])
    assert not tables(kn)[0, 2:].any()
    assert policy.act(obs)["uav_0"] == 0, "A1 has nothing to add in the second bundle phase"
    assert kn.bundles[1] == [0, 2, 1], "A2 kept itself on all three tasks (Table A.8)"
    obs = act_on(env, {})[0]
    assert env.protocol.round == 2
    members = [np.flatnonzero(tables(kn)[0, :, j] > 0).tolist() for j in range(5)]
    assert members == [[0, 1], [1, 2], [1, 2], [2], []]                      # Table A.9 without A1's new T5 bid
    assert kn.bundles[0] == [0]
    assert obs["uav_0"]["action_mask"][1:6].astype(bool).tolist() == [False, False, False, False, True]
    assert policy.act(obs)["uav_0"] == 1 + 4
    act_on(env, {"uav_0": 1 + 4})
    assert kn.groups.bid(0, 0, 4) == pytest.approx(67.0)


# -- Fig 5.3: team-focused choice (thesis §5.2.1, (5.5), Fig 5.3) ---------------------------------------------------
def fig_5_3_env() -> TaskAllocEnv:
    """Agent 0: c = 60 on T2 (free, L = 1), c = 50 on T3 (L = 3, holding bids 90 and 80), c = 70 on T1 (L = 1, held
    at 95, so not valid). γ = 10 with the start distance: c = 100 − 10·d."""
    agents = [agent(3, 4), agent(1), agent(0, 2), agent(6, 4.5)]
    tasks = [task(6, 4), task(3), task(0, agents=3)]
    env = TaskAllocEnv(scenario=build(agents, tasks), distance_cost="from_start")
    env.reset(seed=0)
    gains = env.protocol.view().gain
    np.testing.assert_allclose(gains[0], [70.0, 60.0, 50.0])                  # d = 3, 4, 5
    np.testing.assert_allclose([gains[1, 2], gains[2, 2], gains[3, 0]], [90.0, 80.0, 95.0])
    act_on(env, {"uav_1": 3, "uav_2": 3, "uav_3": 1})
    return env, act_on(env, {})[0]


@pytest.mark.parametrize("policy, choice", [(CBGAPolicy(), 2), (CBGAPolicy(team_bidding=True), 3),
                                            (CBGAPolicy(team_bidding=True, team_value="literal"), 3)])
def test_fig_5_3_team_bidding_picks_the_nearly_full_group(policy, choice):
    env, obs = fig_5_3_env()
    kn = env.protocol.knowledge
    assert sorted(tables(kn)[0, :, 2][tables(kn)[0, :, 2] > 0].tolist()) == [80.0, 90.0]
    assert obs["uav_0"]["action_mask"][1:4].tolist() == [0, 1, 1]
    policy.start(env)
    assert policy.act(obs)["uav_0"] == choice
    act_on(env, {"uav_0": choice})
    assert kn.groups.bid(0, 0, choice - 1) == pytest.approx({2: 60.0, 3: 50.0}[choice]), "the stored bid is c_ij"


def test_team_value_net_does_not_reward_outbidding_a_single_agent_task():
    """``team_value`` (thesis §5.2.1, (5.5)): agent 0 can take T0 (L = 1, c = 60) from agent 1 (50), or join T1 (L = 2,
    c = 50) next to agent 2 (40). ``net``: T0 is worth 60 − 50 + 50 = 60, T1 40 + 50 = 90 → T1. ``literal`` (5.5)
    as printed: T0 is worth 50 + 60 = 110 → T0. Individually T0 (60 > 50)."""
    agents = [agent(0), agent(4, 5), agent(0, 5, 6)]
    env = TaskAllocEnv(scenario=build(agents, [task(4), task(0, 5, agents=2)]), distance_cost="from_start")
    env.reset(seed=0)
    gains = env.protocol.view().gain
    np.testing.assert_allclose([gains[0, 0], gains[0, 1], gains[1, 0], gains[2, 1]], [60.0, 50.0, 50.0, 40.0])
    act_on(env, {"uav_1": 1, "uav_2": 2})
    obs = act_on(env, {})[0]
    assert obs["uav_0"]["action_mask"][1:3].tolist() == [1, 1]
    for policy, choice in ((CBGAPolicy(), 1), (CBGAPolicy(team_bidding=True), 2),
                           (CBGAPolicy(team_bidding=True, team_value="literal"), 1)):
        policy.start(env)
        assert policy.act(obs)["uav_0"] == choice, policy


# -- Fig 5.1: the team would score more with both agents on the 2-agent task ---------------------------------------
def fig_5_1_scenario():
    """Tc (L = 2) at the origin, Tb (L = 1) and Ta (L = 1) near A0; all windows [100, 101] with 10 minutes of work,
    so each agent does one task. A2 sits on Ta (99) and takes it from A0 (94.2). Then A0 chooses between Tb (90,
    free) and Tc (60 for A0, with A1 already there at 80): individually Tb, as a team Tc (140 > 90)."""
    agents = [agent(4), agent(2), agent(4.3, 0.6)]
    tasks = [task(4.3, 0.5, start=100, end=101, duration=10), task(5, start=100, end=101, duration=10),
             task(0, start=100, end=101, duration=10, agents=2)]
    return build(agents, tasks)


@pytest.mark.parametrize("policy, team", [(CBGAPolicy(), False), (CBGAPolicy(task_quitting=True), False),
                                          (CBGAPolicy(team_bidding=True), True),
                                          (CBGAPolicy(team_bidding=True, task_quitting=True), True)])
def test_fig_5_1_team_bidding_sends_both_agents_to_the_group_task(policy, team):
    s = fig_5_1_scenario()
    env = TaskAllocEnv(scenario=s, distance_cost="from_start", **policy.env_overrides)
    env.reset(seed=0)
    gains = env.protocol.view().gain
    assert gains[0].argmax() == 0 and gains[1].argmax() == 2 and gains[2].argmax() == 0
    assert gains[2, 0] > gains[0, 0] > gains[0, 1] > gains[0, 2] and gains[1, 2] + gains[0, 2] > gains[0, 1]
    ep = run_episode(env, policy, seed=0)
    check_converged_allocation(env, ep)
    alloc = ep.allocation
    if team:
        assert alloc.members[2] == (0, 1) and 2 in alloc.valid_tasks
        assert alloc.score == pytest.approx(99 + 60 + 80)
    elif policy.task_quitting:       # A1 quits the group nobody joins and, blocked until someone does, stays out
        assert alloc.members[1] == (0,) and alloc.members[2] == () and alloc.counters.quits == 1
        assert alloc.score == pytest.approx(99 + 90)
    else:                            # A1 waits at Tc alone and pays its travel for nothing
        assert alloc.members[1] == (0,) and alloc.members[2] == (1,) and 2 not in alloc.valid_tasks
        assert alloc.score == pytest.approx(99 + 90 - 20)


# -- CBBA = SGA (Choi et al. 2009; thesis §3.3.3; Johnson §3.4) -------------------------------------------------------
def cbba_env(seed: int, **extra) -> TaskAllocEnv:
    rng = np.random.default_rng(seed)
    return TaskAllocEnv(n_agents=int(rng.integers(2, 6)), n_tasks=int(rng.integers(3, 10)), agents_per_task=1,
                        distance_cost="from_start", marginal_gain="frozen", start_time_range=(0.0, 30.0), **extra)


def cbba_with_stale_check(env: TaskAllocEnv, seed: int) -> tuple[object, bool]:
    """Run CBBA; also report whether some agent bid while a task it valued more was blocked only by a bid its
    holder had already released (stale information, which CBBA cannot undo later)."""
    obs, infos = env.reset(seed=seed)
    policy = CBBAPolicy()
    policy.start(env, seed)
    stale = False
    while env.agents:
        p = env.protocol
        view, kn = p.view(), p.knowledge
        own = kn.own_bids()
        for a in env.agents:
            i = env.agent_index[a]
            best = np.max(np.where(view.can_bid[i], view.gain[i], 0.0))
            holders = kn.winner[i]
            for j in np.flatnonzero(view.eligible[i] & (view.gain[i] > best) & (holders != NONE) & (holders != i)):
                if own[holders[j], j] <= 0:
                    stale = True
        obs, _, _, _, infos = env.step(policy.act(obs, infos))
    return env.evaluate(), stale


@pytest.mark.slow
def test_cbba_matches_sga_on_random_scenarios():
    """With DMG scores (frozen times, start-distance cost), no ties and full communication, CBBA ends in SGA's
    allocation. The one exception the test tolerates is stale information: an agent bids while a better task is
    blocked by a bid its holder already released in the same round, then never revisits it (a gap in the
    'CBBA = SGA' claim, reported separately); those runs must still be conflict-free and converged."""
    stale_free = 0
    for seed in range(200):
        env = cbba_env(seed)
        alloc, stale = cbba_with_stale_check(env, seed)
        assert alloc.converged and not alloc.conflicts
        sga = sgama(env.scenario, env.config)
        if not stale:
            stale_free += 1
            assert alloc.members == sga.members, f"seed {seed}: CBBA {alloc.members} vs SGA {sga.members}"
            assert alloc.paths == sga.paths
            assert alloc.score == pytest.approx(sga.score)
    assert stale_free >= 120


@pytest.mark.slow
def test_cbba_scores_at_least_half_the_optimum():
    """The 50 % bound (Choi et al. 2009; thesis §2.2.4, Johnson §1.2): on tiny instances CBBA ≥ 0.5 × the optimum."""
    for seed in range(100):
        rng = np.random.default_rng(seed)
        env = TaskAllocEnv(n_agents=int(rng.integers(2, 4)), n_tasks=int(rng.integers(2, 6)), agents_per_task=1,
                           distance_cost="from_start", marginal_gain="frozen", start_time_range=(0.0, 20.0))
        alloc = rollout(env, CBBAPolicy(), seed=seed)
        best = exact(env.scenario, env.config)
        assert alloc.score <= best.score + 1e-9
        assert alloc.score >= 0.5 * best.score - 1e-9, f"seed {seed}: {alloc.score} < half of {best.score}"


def test_sgama_with_single_agent_tasks_is_sga():
    """Johnson §3.3.1: each SGA iteration assigns the single highest remaining marginal gain; winning scores are
    non-increasing under DMG and each task is assigned at most once."""
    for seed in range(20):
        env = cbba_env(seed)
        env.reset(seed=seed)
        s, cfg = env.scenario, env.config
        model = env.protocol.model
        paths = [[] for _ in range(s.n_agents)]
        taken: set[int] = set()
        last = math.inf
        while True:
            best = (0.0, None, None, None)
            for i in range(s.n_agents):
                gain, slot = model.insertion_gains(i, paths[i])
                for j in range(s.n_tasks):
                    if j not in taken and gain[j] > best[0]:
                        best = (gain[j], i, j, slot[j])
            if best[1] is None:
                break
            value, i, j, n = best
            assert value <= last + 1e-9
            last = value
            paths[i].insert(int(n), j)
            taken.add(j)
        assert sgama(s, cfg).paths == tuple(tuple(p) for p in paths)


# -- centralised solvers ----------------------------------------------------------------------------------------
def tiny_env(seed: int, **extra) -> TaskAllocEnv:
    rng = np.random.default_rng(seed)
    kw = {"n_agents": int(rng.integers(2, 5)), "n_tasks": int(rng.integers(2, 6)), "start_time_range": (0.0, 20.0)}
    if seed % 3 == 2:
        kw |= {"agent_types": ["A", "B"], "n_tasks": 4,
               "task_mix": [{"count": 2, "equipment": ["A", "B"]}, {"count": 2, "agents": 1}]}
    else:
        kw["agents_per_task"] = [1, 2, 3]
    return TaskAllocEnv(**kw, **extra)


@pytest.mark.parametrize("seed", range(24))
def test_exact_is_at_least_sgama_and_every_baseline(seed):
    env = tiny_env(seed)
    env.reset(seed=seed)
    s, cfg = env.scenario, env.config
    best = exact(s, cfg)
    greedy = sgama(s, cfg)
    for alloc in (best, greedy):          # feasible, capacity respected, scored by the shared code = reference
        assert not alloc.conflicts
        for j, members in enumerate(alloc.members):
            assert len(members) <= s.task_agents[j]
        ref, valid = reference_team_score(s, alloc.paths, distance_cost=cfg.distance_cost)
        assert alloc.score == pytest.approx(ref) and set(alloc.valid_tasks) == valid
    assert best.score >= greedy.score - 1e-9
    assert best.score >= 0.0
    for policy in VARIANTS:
        e = tiny_env(seed, **policy.env_overrides)
        assert best.score >= rollout(e, policy, seed=seed).score - 1e-9, policy.name


def test_exact_matches_brute_force():
    """Every combination of ordered paths of two agents over three tasks: exact() finds the best valid one."""
    for seed in range(6):
        cfg = TaskAllocConfig(n_agents=2, n_tasks=3, agents_per_task=(1, 2), start_time_range=(0.0, 15.0))
        s = generate(cfg, np.random.default_rng(seed))
        orders = [p for r in range(4) for p in itertools.permutations(range(3), r)]
        best = -math.inf
        for p0, p1 in itertools.product(orders, orders):
            score, _ = reference_team_score(s, [p0, p1])
            if replay(s, 0, p0).feasible and replay(s, 1, p1).feasible:
                best = max(best, score)
        assert exact(s, cfg).score == pytest.approx(best)


@pytest.mark.parametrize("kind", ["equipment", "prerequisites"])
@pytest.mark.parametrize("seed", range(8))
def test_exact_matches_brute_force_with_equipment_and_prerequisites(kind, seed):
    """Three agents over three tasks, every combination of ordered paths: the dynamic programme's states (members
    and equipment items per task) and its final checks (equipment, prerequisites) find the best valid allocation."""
    extra = ({"agent_types": ["A", "B"], "task_mix": [{"count": 2, "equipment": ["A", "B"]}, {"count": 1, "agents": 1}]}
             if kind == "equipment" else
             {"agents_per_task": (1, 2), "prerequisites": {"chains": 1, "length": 3, "followup_window": False}})
    cfg = from_mapping({"n_agents": 3, "n_tasks": 3, "start_time_range": (0.0, 15.0), **extra})
    s = generate(cfg, np.random.default_rng(seed))
    orders = [p for r in range(4) for p in itertools.permutations(range(3), r)]
    feasible = [[p for p in orders if replay(s, i, p).feasible and all(s.eligible()[i, j] for j in p)]
                for i in range(3)]
    best = max(reference_team_score(s, paths)[0] for paths in itertools.product(*feasible))
    assert exact(s, cfg).score == pytest.approx(best)


# -- quitting and team bidding where the thesis says they matter (thesis §5.3.2, Figs 5.7 / 5.13) --------------------
def test_cbgabi_completes_more_tasks_when_every_task_needs_everyone():
    """10 agents, 20 tasks, every L_j = 10 (E5.2 vs E5.7: 7295 → 9391): base CBGA strands agents on groups that never
    fill; CBGABI completes more tasks on most seeds and scores more on average."""
    wins, scores = 0, {"CBGA": [], "CBGABI": []}
    seeds = range(10)
    for seed in seeds:
        valid = {}
        for policy in (CBGAPolicy(), CBGAPolicy(team_bidding=True, task_quitting=True)):
            env = TaskAllocEnv(n_agents=10, n_tasks=20, agents_per_task=10, **policy.env_overrides)
            alloc = rollout(env, policy, seed=seed)
            assert alloc.converged and not alloc.conflicts
            valid[policy.name] = alloc.n_valid
            scores[policy.name].append(alloc.score)
        wins += valid["CBGABI"] > valid["CBGA"]
    assert wins >= 7, f"CBGABI completed more tasks on only {wins} of {len(seeds)} seeds"
    assert np.mean(scores["CBGABI"]) > np.mean(scores["CBGA"])


# -- determinism over long runs and policy plumbing ---------------------------------------------------------------
@pytest.mark.parametrize("name", ["cbga", "cbga+tq", "cbga+tb", "cbgabi", "random"])
def test_policies_are_deterministic_over_long_runs(name):
    """The default scenario (10 agents, 20 tasks, L = 4): the same seed gives the same allocation and traffic."""
    results = []
    for _ in range(2):
        policy = make_policy(name)
        env = TaskAllocEnv(**policy.env_overrides)
        results.append(rollout(env, policy, seed=11))
    assert results[0] == results[1]
    assert results[0].converged


def test_pass_policy_scores_zero():
    env = TaskAllocEnv(n_agents=3, n_tasks=4)
    alloc = rollout(env, PassPolicy(), seed=0)
    assert alloc.score == 0 and alloc.counters.bids == 0 and all(p == () for p in alloc.paths)


def test_random_policy_only_takes_masked_actions():
    env = TaskAllocEnv(n_agents=4, n_tasks=6, agents_per_task=[1, 2], task_quitting=True)
    ep = run_episode(env, RandomPolicy(seed=3), seed=3)      # the env raises on any action outside the mask
    assert ep.allocation.converged


def test_policy_needs_its_env_overrides():
    policy = CBGAPolicy(task_quitting=True, quit_threshold=2)
    assert policy.env_overrides == {"task_quitting": True, "delta": 2}
    env = TaskAllocEnv(n_agents=3, n_tasks=4)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="task_quitting"):
        policy.start(env)


def test_cbba_policy_rejects_multi_agent_tasks():
    env = TaskAllocEnv(n_agents=3, n_tasks=4, agents_per_task=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="L_j"):
        CBBAPolicy().start(env)


def test_cbga_reduces_to_cbba_on_single_agent_tasks():
    """Thesis §3.2.3 (single-agent tasks use the CBBA consensus): with every L_j = 1, CBGA and CBBA agree."""
    for seed in range(10):
        env = TaskAllocEnv(n_agents=4, n_tasks=8, agents_per_task=1)
        a = rollout(env, CBGAPolicy(), seed=seed)
        b = rollout(env, CBBAPolicy(), seed=seed)
        assert a == b
