"""Path timing, path score, marginal gains and the team score (thesis §3.2.2, (3.7)–(3.11); §5.3.1; Johnson
§3.3.1 and §3.4.1: frozen service times (3.2)/(3.6), DMG (3.13)).

Expected values are computed by hand in each test from thesis (3.7)–(3.10):
arr = t + leg / v (feasible iff arr < end), st = max(arr, start, ready), reward = c̄ e^{−λ(st − start)},
cost = γ·leg (``leg``) or γ·‖pos_i^0 − pos_j‖ (``from_start``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import agent, build, examples, reference_gain, reference_team_score, replay, task
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc_env import TaskAllocEnv, generate, resolve_config
from taskalloc_env.scoring import ScoringModel, distances, team_score

LAM, GAMMA = 0.1, 0.5
SQRT109 = math.sqrt(109.0)


def two_tasks(b_start: float = 20.0):
    """Agent at the origin (speed 1); A at (3,4,0) (5 away), window [0,10], dur 2; B at (3,10,0) (6 from A)."""
    return build([agent(0)], [task(3, 4, reward=100, start=0, end=10, duration=2),
                              task(3, 10, reward=100, start=b_start, end=30, duration=1)],
                 time_discount=LAM, distance_discount=GAMMA)


def model(s, **kw) -> ScoringModel:
    kw.setdefault("distance_cost", "leg")
    return ScoringModel(s, **kw)


# -- one path (3.7)–(3.10) -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("distance_cost, cost", [("leg", GAMMA * (5 + 6)), ("from_start", GAMMA * (5 + SQRT109))])
def test_two_task_path_by_hand(distance_cost, cost):
    """A then B: arr_A = 5 (no wait), B reached at 13 but starts at 20 (waits for its window)."""
    sch = model(two_tasks(), distance_cost=distance_cost).schedule(0, [0, 1])
    assert sch.feasible
    np.testing.assert_allclose(sch.arrival, [5.0, 13.0])
    np.testing.assert_allclose(sch.start, [5.0, 20.0])
    np.testing.assert_allclose(sch.finish, [7.0, 21.0])
    np.testing.assert_allclose(sch.reward, [100 * math.exp(-LAM * 5), 100.0])
    assert sch.cost.sum() == pytest.approx(cost)
    assert sch.score == pytest.approx(100 * math.exp(-0.5) + 100 - cost)


def test_path_order_matters_for_windows():
    """B first: A is reached at 21 + 6 = 27, after its window closed (10) → infeasible (3.7)."""
    sch = model(two_tasks()).schedule(0, [1, 0])
    assert not sch.feasible


@pytest.mark.parametrize("end, feasible", [(5.0, False), (5.001, True)])
def test_arrival_must_be_strictly_before_the_window_end(end, feasible):
    s = build([agent(0)], [task(5, reward=100, start=0, end=end)], time_discount=LAM, distance_discount=GAMMA)
    m = model(s)
    assert m.schedule(0, [0]).feasible is feasible
    gain, slot = m.insertion_gains(0, [])
    if feasible:
        assert gain[0] == pytest.approx(100 * math.exp(-LAM * 5) - GAMMA * 5)
        assert slot[0] == 0
    else:
        assert gain[0] == 0 and slot[0] == -1


def test_late_arrival_is_discounted_from_the_task_start():
    """(3.8): the discount counts from start_j, not from time 0; arriving early never pays more than c̄."""
    s = build([agent(0)], [task(5, reward=80, start=2, end=10), task(0, 1, reward=80, start=3, end=10)],
              time_discount=LAM, distance_discount=0.0)
    sch = model(s).schedule(0, [0])
    assert sch.reward[0] == pytest.approx(80 * math.exp(-LAM * (5 - 2)))
    early = model(s).schedule(0, [1])                  # arrives at 1, waits until 3
    assert early.start[0] == pytest.approx(3.0) and early.reward[0] == pytest.approx(80.0)


@pytest.mark.parametrize("reward_time", ["arrival", "start"])
@pytest.mark.parametrize("timing, start", [("conservative", 13.0), ("earliest", 5.0), ("none", 5.0)])
def test_prerequisite_timing(timing, start, reward_time):
    """P window [0, 10], dur 3; follow-up F (P ∈ P_F) reached at 5: conservative waits until end_P + dur_P = 13,
    earliest needs start_P + dur_P = 3 (already passed), none ignores P (``prereq_timing``, our choice). (3.8)
    discounts from the arrival τ = 5 (``reward_time="arrival"``, the thesis's words) or from the start."""
    s = build([agent(0)], [task(0, 9, reward=100, start=0, end=10, duration=3),
                           task(5, reward=100, start=0, end=20, prerequisites=(0,))],
              time_discount=LAM, distance_discount=0.0)
    sch = model(s, prereq_timing=timing, reward_time=reward_time).schedule(0, [1])
    assert sch.feasible
    assert sch.start[0] == pytest.approx(start)
    late = 5.0 if reward_time == "arrival" else start
    assert sch.reward[0] == pytest.approx(100 * math.exp(-LAM * late))


def test_prerequisite_that_ends_too_late_makes_the_follow_up_impossible():
    """end_P + dur_P = 13 ≥ end_F = 12: F can never start under ``conservative`` (E3.15 Exp2)."""
    s = build([agent(0)], [task(0, 9, reward=100, start=0, end=10, duration=3),
                           task(5, reward=100, start=0, end=12, prerequisites=(0,))])
    assert not model(s, prereq_timing="conservative").schedule(0, [1]).feasible
    assert model(s, prereq_timing="conservative").insertion_gains(0, [])[0][1] == 0
    assert model(s, prereq_timing="earliest").schedule(0, [1]).feasible


def test_reward_split_total_pays_each_member_its_share():
    """``total`` pays c̄_j / L_j per member (E3.7, thesis §3.3.3: 150 in total, 75 per member)."""
    s = build([agent(0), agent(1)], [task(0, reward=150, start=10, agents=2)], distance_discount=0.0)
    per_agent = model(s).schedule(0, [0])
    total = model(s, reward_split="total").schedule(0, [0])
    assert per_agent.reward[0] == pytest.approx(150.0)
    assert total.reward[0] == pytest.approx(75.0)


# -- marginal gain (3.11) --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("distance_cost", ["leg", "from_start"])
def test_marginal_gain_of_appending(distance_cost):
    """c_B given [A] = S([A, B]) − S([A]) = 100 − γ·d, at slot 1 (B before A would make A infeasible)."""
    gain, slot = model(two_tasks(), distance_cost=distance_cost).insertion_gains(0, [0])
    d = 6.0 if distance_cost == "leg" else SQRT109
    assert gain[1] == pytest.approx(100 - GAMMA * d)
    assert slot[1] == 1
    assert gain[0] == 0 and slot[0] == -1               # already on the path


@pytest.mark.parametrize("distance_cost", ["leg", "from_start"])
def test_marginal_gain_rescore_charges_the_delay_of_later_tasks(distance_cost):
    """B opens at 8. Path [B]: B starts at √109 ≈ 10.44. Inserting A first makes B start at 13, so the gain of A
    is its own reward minus B's lost reward minus the extra cost (thesis (3.11): later tasks are re-timed)."""
    s = two_tasks(b_start=8.0)
    gain, slot = model(s, distance_cost=distance_cost).insertion_gains(0, [1])
    lost = 100 * math.exp(-LAM * (SQRT109 - 8)) - 100 * math.exp(-LAM * (13 - 8))
    extra = GAMMA * (5 + 6 - SQRT109) if distance_cost == "leg" else GAMMA * 5
    assert slot[0] == 0
    assert gain[0] == pytest.approx(100 * math.exp(-LAM * 5) - lost - extra)


def test_marginal_gain_frozen_forbids_moving_existing_start_times():
    """Johnson (3.2)/(3.6): with frozen times, inserting A before B would delay B → not allowed; no slot fits."""
    s = two_tasks(b_start=8.0)
    gain, slot = model(s, marginal_gain="frozen").insertion_gains(0, [1])
    assert gain[0] == 0 and slot[0] == -1
    # when B waits long enough (opens at 20), the insertion absorbs into the wait and is allowed
    gain, slot = model(two_tasks(), marginal_gain="frozen", distance_cost="from_start").insertion_gains(0, [1])
    assert slot[0] == 0 and gain[0] == pytest.approx(100 * math.exp(-LAM * 5) - GAMMA * 5)


def test_only_positive_gains_are_bids():
    """A task whose reward cannot pay for the travel has c_ij = 0 (only c_ij > 0 can become a bid; our choice)."""
    s = build([agent(0)], [task(5, reward=2, start=10)], distance_discount=1.0)
    gain, slot = model(s).insertion_gains(0, [])
    assert gain[0] == 0 and slot[0] == -1


def test_leg_cost_is_not_dmg_counterexample():
    """DMG (Johnson (3.13)) fails for the detour penalty: it can *raise* a later bid. j at x = 10, m at x = 5 on the
    way: c_j([]) = 100 − γ·10 but c_j([m]) = 100 − γ·5. ``from_start`` keeps c_j constant here (DMG holds)."""
    s = build([agent(0)], [task(5, start=100), task(10, start=200)], distance_discount=1.0)
    leg = model(s, distance_cost="leg")
    assert leg.insertion_gains(0, [])[0][1] == pytest.approx(90.0)
    assert leg.insertion_gains(0, [0])[0][1] == pytest.approx(95.0)     # rose: not DMG
    fs = model(s, distance_cost="from_start")
    assert fs.insertion_gains(0, [0])[0][1] == pytest.approx(fs.insertion_gains(0, [])[0][1]) == pytest.approx(90.0)


def test_rescore_is_not_dmg_counterexample():
    """Re-timed gains (``rescore``, (3.11)) are not DMG either, even with the start-distance cost. On the path (0),
    task 1 fits only before 0 and would push 0 from its window start (4.21) to 9.77, so c_1 = 0.65. Inserting task 2
    first makes 0 late already (17.05) and leaves a wait before 2's window (8.92) that absorbs task 1's detour:
    c_1 rises to 99.48. ``frozen`` forbids the insertion that moved 0 (docs/configuration.md, "Which scores are
    DMG")."""
    env = TaskAllocEnv(n_agents=1, n_tasks=3, agents_per_task=1, start_time_range=(0.0, 10.0), window=20.0,
                       distance_cost="from_start")
    env.reset(seed=1052)
    s, cfg = env.scenario, env.config
    rescore = ScoringModel.from_config(s, cfg)
    assert rescore.insertion_gains(0, [0])[0][1] == pytest.approx(0.65, abs=0.01)
    assert rescore.insertion_gains(0, [2, 0])[0][1] == pytest.approx(99.48, abs=0.01)       # rose: not DMG
    frozen = ScoringModel.from_config(s, cfg.replace(marginal_gain="frozen"))
    assert frozen.insertion_gains(0, [0])[1][2] == 1           # frozen: 2 may not go before 0, which it would delay
    assert frozen.insertion_gains(0, [2, 0])[0][1] <= frozen.insertion_gains(0, [2])[0][1] + 1e-9   # [2] ⊕ 0: DMG


@st.composite
def random_paths(draw):
    seed = draw(st.integers(0, 10_000))
    n_tasks = draw(st.integers(2, 7))
    prereqs = draw(st.booleans()) and n_tasks >= 4
    cfg = resolve_config({"n_agents": 2, "n_tasks": n_tasks, "agents_per_task": 1, "start_time_range": (0.0, 25.0),
                          "window": draw(st.sampled_from([5.0, 15.0])),
                          "duration": draw(st.sampled_from([0.0, 2.0, 5.0])),
                          "prerequisites": {"chains": 1, "length": 2} if prereqs else None})
    s = generate(cfg, np.random.default_rng(seed))
    options = {"distance_cost": draw(st.sampled_from(["leg", "from_start"])),
               "prereq_timing": draw(st.sampled_from(["conservative", "earliest", "none"])),
               "reward_split": "per_agent", "reward_time": draw(st.sampled_from(["arrival", "start"]))}
    marginal = draw(st.sampled_from(["rescore", "frozen"]))
    # a feasible path built by the reference itself: random tasks at their best positive insertion
    path: list[int] = []
    for j in draw(st.permutations(range(n_tasks)))[: draw(st.integers(0, n_tasks - 1))]:
        g, n = reference_gain(s, 0, path, j, marginal_gain=marginal, **options)
        if g > 0:
            path.insert(n, j)
    return s, path, options, marginal


@settings(max_examples=examples(120), deadline=None)
@given(random_paths())
def test_insertion_gains_match_brute_force(case):
    """The vectorised (3.11) equals the best feasible insertion found by replaying every slot."""
    s, path, options, marginal = case
    m = ScoringModel(s, marginal_gain=marginal, **options)
    sch = m.schedule(0, path)
    ref = replay(s, 0, path, **options)
    assert sch.feasible == ref.feasible
    np.testing.assert_allclose(sch.start, ref.start, atol=1e-9)
    assert sch.score == pytest.approx(ref.score, abs=1e-9)
    gain, slot = m.insertion_gains(0, path)
    for j in range(s.n_tasks):
        if j in path:
            assert gain[j] == 0 and slot[j] == -1
            continue
        want, _ = reference_gain(s, 0, path, j, marginal_gain=marginal, **options)
        assert gain[j] == pytest.approx(want, abs=1e-7), f"task {j} on path {path}"
        if want > 0:
            at_slot = replay(s, 0, [*path[: slot[j]], j, *path[slot[j]:]], **options)
            assert at_slot.feasible
            assert at_slot.score - ref.score == pytest.approx(want, abs=1e-7)
        else:
            assert slot[j] == -1


@settings(max_examples=examples(80), deadline=None)
@given(random_paths(), st.data())
def test_frozen_from_start_gains_are_dmg(case, data):
    """DMG (Johnson (3.13)): with frozen times and the start-distance cost, inserting another task m never
    raises the gain of j, and never moves an existing start time."""
    s, path, options, _ = case
    options = dict(options, distance_cost="from_start")
    m = ScoringModel(s, marginal_gain="frozen", **options)
    gain, slot = m.insertion_gains(0, path)
    candidates = [j for j in range(s.n_tasks) if gain[j] > 0]
    if not candidates:
        return
    extra = data.draw(st.sampled_from(candidates))
    longer = [*path[: slot[extra]], extra, *path[slot[extra]:]]
    before = m.schedule(0, path).start
    after = m.schedule(0, longer).start
    np.testing.assert_allclose(np.delete(after, slot[extra]), before, atol=1e-9)
    gain_after, _ = m.insertion_gains(0, longer)
    for j in range(s.n_tasks):
        if j not in longer:
            assert gain_after[j] <= gain[j] + 1e-9, f"gain of {j} rose after inserting {extra}"


# -- team score (thesis §5.3.1, (3.4)) --------------------------------------------------------------------------------
def _score(s, paths, **kw):
    policy = kw.pop("conflict_policy", "first_L_paid")
    m = ScoringModel(s, **kw)
    return team_score(m, [m.schedule(i, p) for i, p in enumerate(paths)], policy)


def test_incomplete_group_earns_nothing_but_pays_travel():
    """L_j = 2 with one member: no reward, travel still costs; an empty path contributes 0 (thesis §3.1.2)."""
    s = build([agent(0), agent(0, 3)], [task(4, reward=100, start=10, agents=2)], distance_discount=1.0)
    ts = _score(s, [[0], []], distance_cost="from_start")
    assert not ts.valid[0]
    assert ts.agent_scores.tolist() == pytest.approx([-4.0, 0.0])
    assert ts.score == pytest.approx(-4.0)


def test_complete_group_pays_every_member():
    """Every member of a valid L-agent task gets the full c̄_j (thesis §3.2.2, §5.3.2: a 4-agent task scores 400)."""
    s = build([agent(0), agent(0, 3)], [task(4, reward=100, start=10, agents=2)], distance_discount=1.0)
    ts = _score(s, [[0], [0]], distance_cost="from_start")
    assert ts.valid[0]
    assert ts.agent_scores.tolist() == pytest.approx([100 - 4.0, 100 - 5.0])


def test_reward_split_total_in_the_team_score():
    s = build([agent(0), agent(0, 3)], [task(4, reward=150, start=10, agents=2)], distance_discount=1.0)
    ts = _score(s, [[0], [0]], distance_cost="from_start", reward_split="total")
    assert ts.score == pytest.approx(150 - 4.0 - 5.0)


def _conflict_scenario():
    """Three agents on one L = 1 task; agent 2 arrives first (1 away), agents 0 and 1 tie (both 2 away)."""
    return build([agent(-2), agent(2), agent(0, 1)], [task(0, reward=100, start=0, end=50)],
                 time_discount=LAM, distance_discount=1.0)


def test_conflict_first_l_paid_pays_the_earliest_starter():
    s = _conflict_scenario()
    ts = _score(s, [[0], [0], [0]], distance_cost="from_start")
    assert ts.conflicts[0]
    expected = [-2.0, -2.0, 100 * math.exp(-LAM * 1) - 1.0]
    assert ts.agent_scores.tolist() == pytest.approx(expected)


def test_conflict_first_l_paid_ties_go_to_the_higher_id():
    s = _conflict_scenario()
    ts = _score(s, [[0], [0], []], distance_cost="from_start")
    assert ts.agent_scores.tolist() == pytest.approx([-2.0, 100 * math.exp(-LAM * 2) - 2.0, 0.0])


def test_conflict_none_paid():
    s = _conflict_scenario()
    ts = _score(s, [[0], [0], [0]], distance_cost="from_start", conflict_policy="none_paid")
    assert ts.conflicts[0] and not ts.valid[0]
    assert ts.score == pytest.approx(-5.0)


def test_equipment_must_cover_the_requirement():
    """te = {A, B}: two A agents form a full but invalid group (3.5)."""
    agents = [agent(0, equipment=("A",)), agent(0, 1, equipment=("A",)), agent(0, 2, equipment=("B",))]
    s = build(agents, [task(1, reward=100, start=10, agents=2, equipment=("A", "B"))], distance_discount=0.0)
    assert not _score(s, [[0], [0], []]).valid[0]
    assert _score(s, [[0], [], [0]]).valid[0]


def test_prerequisites_must_be_valid_transitively():
    """C needs B needs A: with A invalid (incomplete), B and C score nothing even though they are complete."""
    s = build([agent(0), agent(1)],
              [task(2, reward=100, start=10, end=20, agents=2),
               task(3, reward=100, start=30, end=40, prerequisites=(0,)),
               task(4, reward=100, start=60, end=70, prerequisites=(1,))], distance_discount=0.0)
    ts = _score(s, [[0, 1, 2], []], prereq_timing="none")
    assert ts.valid.tolist() == [False, False, False]
    assert ts.score == pytest.approx(0.0)
    ts = _score(s, [[0, 1, 2], [0]], prereq_timing="none")
    assert ts.valid.tolist() == [True, True, True]


def test_team_score_matches_reference_on_generated_scenarios():
    """The vectorised team score equals the loop reference (``helpers.reference_team_score``) with conflicts."""
    rng = np.random.default_rng(7)
    for seed in range(30):
        cfg = resolve_config({"n_agents": 4, "n_tasks": 6, "start_time_range": (0.0, 30.0), "agent_types": ["A", "B"],
                              "task_mix": [{"count": 3, "agents": 1}, {"count": 3, "equipment": ["A", "B"]}],
                              "prerequisites": {"chains": 1, "length": 2}})
        s = generate(cfg, np.random.default_rng(seed))
        paths = []
        for i in range(s.n_agents):
            path: list[int] = []
            for j in rng.permutation(s.n_tasks):
                g, n = reference_gain(s, i, path, int(j), distance_cost="leg")
                if g > 0 and rng.random() < 0.6:
                    path.insert(n, int(j))
            paths.append(path)
        for policy in ("first_L_paid", "none_paid"):
            ts = _score(s, paths, conflict_policy=policy, distance_cost="leg")
            ref, valid = reference_team_score(s, paths, conflict_policy=policy, distance_cost="leg")
            assert ts.score == pytest.approx(ref, abs=1e-9)
            assert set(np.flatnonzero(ts.valid).tolist()) == valid


@settings(max_examples=examples(60), deadline=None)
@given(st.integers(1, 12), st.integers(1, 12), st.integers(0, 2**32 - 1), st.sampled_from([1e-3, 1.0, 1e3]))
def test_distances_are_numpys_norm_bit_for_bit(n, m, seed, scale):
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(-5, 5, (n, 3)) * scale, rng.uniform(-5, 5, (m, 3))
    assert np.array_equal(distances(a, b), np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2))
