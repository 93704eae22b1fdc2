"""The compiled kernels give exactly what their numpy references give, on random inputs."""

from __future__ import annotations

import contextlib
import os

import numpy as np
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from taskalloc_env import kernels
from taskalloc_env.bidding import bid_view, refresh_rows
from taskalloc_env.config import PrerequisiteChains, TaskAllocConfig
from taskalloc_env.consensus import Snapshot, exchange, exchange_reference
from taskalloc_env.group_table import GroupOverflow, GroupTable
from taskalloc_env.groups import Equipment
from taskalloc_env.knowledge import LocalKnowledge
from taskalloc_env.network import Deliveries
from taskalloc_env.protocol import NO_TIMER
from taskalloc_env.scenario import Agent, Scenario, Task, generate
from taskalloc_env.scoring import PathTable, ScoringModel, paid_groups_reference, team_score

pytestmark = pytest.mark.skipif(not kernels.COMPILED, reason="numba is not installed")


@st.composite
def rounds(draw):
    """Random tables, a random snapshot (or two, for delayed messages) and random deliveries."""
    n, m = draw(st.integers(2, 6)), draw(st.integers(1, 6))
    single = np.array([draw(st.booleans()) for _ in range(m)])
    need = np.where(single, 1, [draw(st.integers(2, 3)) for _ in range(m)])
    typed = draw(st.booleans())
    agent_eq = np.zeros((n, 2), dtype=bool)
    task_eq = np.zeros((m, 2), dtype=np.int64)
    if typed:
        agent_eq[np.arange(n), [draw(st.integers(0, 1)) for _ in range(n)]] = True
        for j in np.flatnonzero(~single):
            if draw(st.booleans()):
                for _ in range(need[j]):
                    task_eq[j, draw(st.integers(0, 1))] += 1
    values = st.sampled_from([0.0, 0.0, 10.0, 20.0, 20.0, 35.0])

    def table() -> LocalKnowledge:
        kn = LocalKnowledge.empty(n, m, need, know_everyone=draw(st.booleans()))
        for i in range(n):
            for j in range(m):
                holders = [k for k in range(n) if draw(values) > 0][: need[j]]
                for k in holders:
                    kn.set_bid(i, k, j, draw(values) or 5.0)
            kn.timestamps[i] = [draw(st.integers(0, 4)) for _ in range(n)]
            kn.known[i, i] = True
        return kn

    receiver_kn = table()
    senders = [table() for _ in range(draw(st.integers(1, 2)))]
    snaps = {}
    for r, kn in enumerate(senders, start=1):
        snaps[r] = Snapshot(r, kn.groups.copy(), kn.timestamps.copy(), kn.known.copy(),
                            3 * kn.groups.count.sum(axis=1) + n)
    pairs = [(i, k) for i in range(n) for k in range(n) if i != k and draw(st.booleans())]
    sent = np.array([draw(st.integers(1, len(senders))) for _ in pairs], dtype=np.int64)
    rec = np.array([i for i, _ in pairs], dtype=np.int64)
    snd = np.array([k for _, k in pairs], dtype=np.int64)
    deliveries = Deliveries.of(rec, snd, sent)
    return receiver_kn, snaps, deliveries, need, Equipment(agent_eq, task_eq), draw(st.sampled_from(["canonical",
                                                                                                       "thesis"]))


def clone(kn: LocalKnowledge) -> LocalKnowledge:
    return LocalKnowledge(kn.groups.copy(), kn.timestamps.copy(), kn.known.copy(),
                          [list(b) for b in kn.bundles], [list(p) for p in kn.paths], kn.assigned_at.copy(),
                          kn.quit.copy(), kn.quit_blocked.copy(), kn.single.copy())


@settings(max_examples=examples(300), deadline=None)
@given(rounds())
def test_compiled_exchange_equals_the_reference(case):
    kn, snaps, deliveries, need, equipment, table = case
    compiled, reference = clone(kn), clone(kn)
    got = exchange(compiled, deliveries, snaps, 9, need, equipment, table)
    want = exchange_reference(reference, deliveries, snaps, 9, need, equipment, table)
    assert got == want
    for name in ("count", "members", "bids", "own"):
        np.testing.assert_array_equal(getattr(compiled.groups, name), getattr(reference.groups, name), err_msg=name)
    for name in ("winner", "timestamps", "known"):
        np.testing.assert_array_equal(getattr(compiled, name), getattr(reference, name), err_msg=name)


@settings(max_examples=examples(300), deadline=None)
@given(st.integers(1, 5), st.lists(st.integers(1, 4), min_size=1, max_size=5), st.integers(0, 2**32 - 1))
def test_compiled_group_writes_equal_the_reference(n, capacity, seed):
    """Random joins, re-bids and withdrawals (some of them beyond L_j) on two tables, one written by
    ``kernels.table.set_member`` and one by ``GroupTable.set_reference``: the same arrays and the same refusals."""
    rng = np.random.default_rng(seed)
    compiled, reference = (GroupTable.empty(n, n, np.array(capacity)) for _ in range(2))
    for _ in range(60):
        i, k, j = int(rng.integers(n)), int(rng.integers(n)), int(rng.integers(len(capacity)))
        value = float(rng.choice([0.0, -1.0, rng.uniform(1, 9)]))
        outcomes = []
        for write in (compiled.set, reference.set_reference):
            try:
                write(i, k, j, value)
                outcomes.append(None)
            except GroupOverflow as error:
                outcomes.append(str(error))
        assert outcomes[0] == outcomes[1]
        for name in ("count", "members", "bids", "own"):
            np.testing.assert_array_equal(getattr(compiled, name), getattr(reference, name), err_msg=name)


@settings(max_examples=examples(200), deadline=None)
@given(st.integers(1, 5), st.lists(st.integers(1, 4), min_size=1, max_size=5), st.integers(0, 2**32 - 1))
def test_compiled_joined_equals_the_reference(n, capacity, seed):
    """A table before and after random joins, re-bids and withdrawals: ``kernels.table.joined_members`` and
    ``GroupTable.joined_reference`` name the same columns (and some column is named in most examples)."""
    rng = np.random.default_rng(seed)
    table = GroupTable.empty(n, n, np.array(capacity))
    for _ in range(4):
        before = table.copy()
        for _ in range(int(rng.integers(0, 12))):
            i, k, j = int(rng.integers(n)), int(rng.integers(n)), int(rng.integers(len(capacity)))
            with contextlib.suppress(GroupOverflow):        # a write past L_j changes nothing
                table.set(i, k, j, float(rng.choice([0.0, rng.uniform(1, 9)])))
        np.testing.assert_array_equal(table.joined(before), table.joined_reference(before))
        np.testing.assert_array_equal(before.joined(table), before.joined_reference(table))


@st.composite
def planning_cases(draw):
    """A generated scenario (windows, durations, prerequisites, discounts drawn), scoring options and random paths."""
    n, m = draw(st.integers(1, 4)), draw(st.integers(1, 9))
    chains = draw(st.integers(0, m // 3))
    kw = dict(n_agents=n, n_tasks=m, agents_per_task=1, window=draw(st.sampled_from([0.5, 5.0, 40.0])),
              duration=draw(st.sampled_from([0.0, 2.0, 5.0])),
              time_discount=draw(st.sampled_from([0.0, 0.1, 0.8])),
              distance_discount=draw(st.sampled_from([0.0, 0.8, 5.0])),
              start_time_range=(0.0, draw(st.sampled_from([0.0, 10.0, 100.0]))),
              prerequisites=PrerequisiteChains(chains) if chains else None)
    scenario = generate(TaskAllocConfig(**kw), np.random.default_rng(draw(st.integers(0, 10_000))))
    options = dict(marginal_gain=draw(st.sampled_from(["rescore", "frozen"])),
                   reward_time=draw(st.sampled_from(["arrival", "start"])),
                   distance_cost=draw(st.sampled_from(["leg", "total"])),
                   prereq_timing=draw(st.sampled_from(["conservative", "earliest", "none"])))
    paths = [draw(st.permutations(range(m)))[: draw(st.integers(0, m))] for _ in range(n)]
    return ScoringModel(scenario, **options), paths


@settings(max_examples=examples(400), deadline=None)
@given(planning_cases())
def test_compiled_plan_equals_the_reference(case):
    """Timing, feasibility and best slots agree exactly; values to the last bits of exp (see kernels/plan.py)."""
    model, paths = case
    agents = range(len(paths))
    got, want = model.plan(agents, paths), model.plan_reference(agents, paths)
    present = np.arange(want.timing.path.shape[1])[None, :] < want.timing.length[:, None]
    np.testing.assert_array_equal(got.timing.feasible, want.timing.feasible)
    for name in ("arrival", "start", "finish", "reward", "cost"):
        np.testing.assert_allclose(getattr(got.timing, name)[present], getattr(want.timing, name)[present],
                                   rtol=1e-12, atol=0, err_msg=name)
    np.testing.assert_allclose(got.gain, want.gain, rtol=1e-12, atol=1e-12)
    ties = np.isclose(got.gain, want.gain, rtol=1e-12) & (got.slot != want.slot)
    np.testing.assert_array_equal(got.slot[~ties], want.slot[~ties])


@pytest.mark.parametrize("seed", range(100))
def test_the_plan_kernels_shortcuts_never_change_a_gain(seed):
    """Insertions worth nearly the full reward (little discount, little travel cost, long paths) and deadlines close
    behind the finish times of path tasks (short windows, many tasks in a short span): where the plan kernel's
    shortcuts could matter (``kernels/plan.py``: the bound pay_j − charge, the stop at the first slot that leaves
    after the deadline), the gains and slots equal the reference's."""
    rng = np.random.default_rng(seed)
    n, m = 3, 14
    cfg = TaskAllocConfig(n_agents=n, n_tasks=m, agents_per_task=1, window=float(rng.choice([0.5, 2.0, 5.0, 40.0])),
                          duration=float(rng.choice([0.0, 1.0])), time_discount=float(rng.choice([0.01, 0.1])),
                          distance_discount=float(rng.choice([0.0, 0.01, 0.5])),
                          start_time_range=(0.0, float(rng.choice([5.0, 30.0]))))
    scenario = generate(cfg, rng)
    model = ScoringModel(scenario, marginal_gain=str(rng.choice(["rescore", "frozen"])),
                         distance_cost=str(rng.choice(["leg", "total"])))
    paths = [list(rng.permutation(m)[: rng.integers(0, 8)]) for _ in range(n)]
    got, want = model.plan(range(n), paths), model.plan_reference(range(n), paths)
    np.testing.assert_allclose(got.gain, want.gain, rtol=1e-12, atol=1e-12)
    ties = np.isclose(got.gain, want.gain, rtol=1e-12) & (got.slot != want.slot)
    np.testing.assert_array_equal(got.slot[~ties], want.slot[~ties])


@st.composite
def typed_scenarios(draw, min_agents: int = 1) -> Scenario:
    """Up to 6 agents carrying equipment A or B (or none of any), up to 7 tasks needing 1–3 agents, some with
    equipment and prerequisites (ties in positions and windows are frequent)."""
    n, m = draw(st.integers(min_agents, 6)), draw(st.integers(1, 7))
    typed = draw(st.booleans())
    agents = [Agent((float(k), 0.0, 0.0), 1.0, (draw(st.sampled_from("AB")),) if typed else ()) for k in range(n)]
    tasks = []
    for j in range(m):
        need = draw(st.integers(1, 3))
        equipment = tuple(draw(st.sampled_from("AB")) for _ in range(need)) if typed and draw(st.booleans()) else ()
        prereqs = tuple(p for p in range(j) if draw(st.integers(0, 4)) == 0)
        tasks.append(Task((1.0, 1.0, 0.0), 100.0, 0.0, 50.0, 1.0, agents=need, equipment=equipment,
                          prerequisites=prereqs))
    return Scenario.from_entities(agents, tasks, equipment_names=("A", "B") if typed else ())


@st.composite
def score_tables(draw):
    """Path tables with conflicts (more than L_j members), equal start times, equipment and prerequisites."""
    scenario = draw(typed_scenarios())
    n, m = scenario.n_agents, scenario.n_tasks
    table = PathTable.empty(n, m)
    table.members[:] = np.array([[draw(st.integers(0, 2)) > 0 for _ in range(m)] for _ in range(n)])
    table.start[table.members] = [draw(st.sampled_from([1.0, 2.0, 2.0, 3.5])) for _ in range(table.members.sum())]
    table.reward[table.members] = [draw(st.sampled_from([10.0, 20.5, 0.1])) for _ in range(table.members.sum())]
    table.cost[:] = [draw(st.sampled_from([0.0, 1.5])) for _ in range(n)]
    return ScoringModel(scenario), table, draw(st.sampled_from(["first_L_paid", "none_paid"]))


@pytest.mark.filterwarnings("ignore:tasks .* are identical")
@settings(max_examples=examples(400), deadline=None)
@given(score_tables())
def test_compiled_team_score_equals_the_reference(case):
    """Paid members, valid tasks, conflicts and the score agree exactly with the numpy lines (``kernels/score.py``)."""
    model, table, conflict_policy = case
    got = team_score(model, table, conflict_policy)
    paid, valid, conflicts = paid_groups_reference(model, table, conflict_policy)
    for name, want in (("paid", paid), ("valid", valid), ("conflicts", conflicts)):
        np.testing.assert_array_equal(getattr(got, name), want, err_msg=name)
    assert got.score == float((np.where(paid, table.reward, 0.0).sum(axis=1) - table.cost).sum())


@st.composite
def views(draw):
    """A scenario with single- and multi-agent tasks (equipment, prerequisites), random tables in every agent's
    row (ties frequent), gains, quit blocks and bundles, and the view options."""
    scenario = draw(typed_scenarios(min_agents=2))
    n, m = scenario.n_agents, scenario.n_tasks
    kn = LocalKnowledge.empty(n, m, scenario.task_agents, know_everyone=draw(st.booleans()))
    values = st.sampled_from([0.0, 0.0, 10.0, 20.0, 20.0, 35.0])
    for i in range(n):
        for j in range(m):
            holders = [k for k in range(n) if draw(values) > 0][: scenario.task_agents[j]]
            for k in holders:
                kn.set_bid(i, k, j, draw(values) or 5.0)
        kn.bundles[i] = [int(j) for j in np.flatnonzero(kn.own_bids()[i] > 0)]
        kn.known[i] = [draw(st.booleans()) for _ in range(n)]
        kn.known[i, i] = True
    kn.quit_blocked[:] = np.array([[draw(st.integers(0, 4)) == 0 for _ in range(m)] for _ in range(n)])
    gain = np.array([[draw(st.sampled_from([0.0, 5.0, 20.0, 35.0])) for _ in range(m)] for _ in range(n)])
    options = dict(prereq_mode=draw(st.sampled_from(["all_have_bid", "all_complete", "any_has_bid"])),
                   require_known_capacity=draw(st.booleans()), max_bundle=draw(st.integers(1, m + 1)),
                   fillable=np.array([draw(st.integers(0, 5)) > 0 for _ in range(m)]),
                   bid_warping=draw(st.booleans()), outbid_ties=draw(st.sampled_from(["strict", "higher_id"])))
    return scenario, kn, gain, options, draw(st.integers(0, n - 1))


@pytest.mark.filterwarnings("ignore:tasks .* are identical")
@settings(max_examples=examples(400), deadline=None)
@given(views())
def test_compiled_view_rows_equal_the_reference(case):
    """All rows from scratch, and one row refreshed after only that row's table changed, equal ``bid_view``."""
    scenario, kn, gain, options, row = case
    equipment = Equipment(scenario.agent_equipment, scenario.task_equipment)
    slot = np.zeros(gain.shape, dtype=np.int64)
    args = (scenario, equipment, scenario.eligible(), gain, slot)

    def same(got, want):
        for name in ("bid", "outbid", "eligible", "prereqs_met", "members", "group_total", "lowest_bid", "displaced",
                     "displaced_bid", "in_bundle", "can_bid"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)

    first = refresh_rows(None, [], kn, *args, **options)
    same(first, bid_view(kn, *args, **options))
    if kn.groups.bid(row, row, 0) > 0:                                                # only this row changes
        kn.set_bid(row, row, 0, 0.0)
    else:                                       # row joins task 0, displacing its lowest member if the group is full
        column = kn.groups.dense(row)[:, 0]
        members = np.flatnonzero(column > 0)
        if len(members) >= scenario.task_agents[0]:
            kn.set_bid(row, int(members[np.argmin(column[members])]), 0, 0.0)
        kn.set_bid(row, row, 0, 25.0)
    kn.bundles[row] = [int(j) for j in np.flatnonzero(kn.own_bids()[row] > 0)]
    kn.quit_blocked[row] = ~kn.quit_blocked[row]
    same(refresh_rows(first, [row], kn, *args, **options), bid_view(kn, *args, **options))


@settings(max_examples=examples(300), deadline=None)
@given(st.integers(1, 5), st.integers(1, 7), st.sampled_from(["cbga", "cbga+tb", "cbga+tq", "cbgabi", "cbba"]),
       st.sampled_from(["net", "literal"]), st.sampled_from([np.float32, np.float64]), st.integers(0, 2**32 - 1))
def test_compiled_rule_equals_the_reference(n, m, name, team_value, dtype, seed):
    """``taskalloc.policies.greedy.greedy_actions`` and ``CBGAPolicy.choose_reference`` on random masks and columns,
    with
    ties, sums that tie only in ``dtype``, NaN and infinities: the same actions."""
    from taskalloc.policies import make_policy

    policy = make_policy(name)
    policy.team_value = team_value
    rng = np.random.default_rng(seed)
    mask = rng.random((n, 1 + 2 * m)) < rng.choice([0.0, 0.2, 0.7, 1.0])
    mask[:, 0] = True
    # 1 + 1e-8 ties with 1 in float32, not in float64; 0.1 + 0.2 - 0.3 likewise with 0
    values = np.array([0.0, 0.1, 0.2, 0.3, 1e-8, 1.0, -1.0, np.nan, np.inf, -np.inf])
    weights = np.r_[1.0, 0.5, 0.5, 0.5, 1.0, 1.0, 0.3, rng.choice([0.0, 0.05], size=3)]
    columns = [rng.choice(values, size=(n, m), p=weights / weights.sum()).astype(dtype)
               for _ in policy.columns]
    np.testing.assert_array_equal(policy.choose(mask, *columns), policy.choose_reference(mask, *columns))


@pytest.mark.parametrize("team_value", ["net", "literal"])
def test_the_compiled_rule_adds_in_the_columns_dtype(team_value):
    """1 + 1e-8 is 1 in float32: the two bids tie and the lower task id wins, as in numpy; in float64 the second
    would win."""
    from taskalloc.policies import make_policy

    policy = make_policy("cbgabi")
    policy.team_value = team_value
    mask = np.array([[True, True, True, False, False]])
    for dtype, expected in ((np.float32, 1), (np.float64, 2)):
        gain, total, displaced = (np.array(row, dtype=dtype) for row in ([[1.0, 1.0]], [[0.0, 1e-8]], [[0.0, 0.0]]))
        assert policy.choose(mask, gain, total, displaced)[0] == expected
        assert policy.choose_reference(mask, gain, total, displaced)[0] == expected


def test_the_references_can_be_chosen_and_a_typo_is_refused():
    import subprocess
    import sys

    def compiled(value: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", "import taskalloc_env.kernels as k; print(k.COMPILED)"],
                              capture_output=True, text=True, env={**os.environ, "TASKALLOC_KERNELS": value})

    assert compiled("reference").stdout.strip() == "False"
    bad = compiled("fast")
    assert bad.returncode != 0 and "TASKALLOC_KERNELS='fast' is not one of" in bad.stderr


@pytest.mark.parametrize("sample", range(2))
def test_compiled_observations_equal_the_reference(sample):
    """Every step of random-policy episodes on fuzzed configs (faults, pop-ups, ACBBA, task quitting included):
    ``observe`` with the compiled step features gives the same observation bytes as ``observe_reference``; the
    kernel writes the own columns the layout names."""
    from taskalloc.evaluation.fuzz import draw_config
    from taskalloc.policies import make_policy
    from taskalloc_env import TaskAllocEnv
    from taskalloc_env.kernels.observe import BUNDLE_SIZE, PASSED, ROUND
    from taskalloc_env.observation import OWN_FEATURES

    assert [OWN_FEATURES[c] for c in (BUNDLE_SIZE, ROUND, PASSED)] == ["bundle_size", "round", "passed"]

    rng, extra = np.random.default_rng(300 + sample), np.random.default_rng([300 + sample, 2])
    steps = 0
    for episode in range(12):
        env = TaskAllocEnv(**draw_config(rng, extra), max_cycles=60)
        policy = make_policy("random")
        obs, _ = env.reset(seed=episode)
        policy.start(env, episode)
        while env.agents:
            protocol, builder, passed = env.protocol, env._builder, env._engine.passed
            for dtype in (np.float32, np.float64):
                compiled = builder.observe(protocol, passed, dtype)
                reference = builder.observe_reference(protocol, passed, dtype)
                assert compiled.tobytes() == reference.tobytes()
            steps += 1
            obs, *_ = env.step(policy.act(obs))
    assert steps > 100


@pytest.mark.parametrize("sample", range(2))
def test_compiled_quit_conditions_equal_the_reference(sample):
    """Every step of random-policy episodes on fuzzed configs with task quitting: ``kernels.quits.quittable`` and
    ``Protocol.quittable_reference`` agree, without the timer and with timers around the round, and quits happen."""
    from taskalloc.evaluation.fuzz import draw_config
    from taskalloc.policies import make_policy
    from taskalloc_env import TaskAllocEnv

    rng, extra = np.random.default_rng(500 + sample), np.random.default_rng([500 + sample, 2])
    allowed = 0
    for episode in range(12):
        env = TaskAllocEnv(**draw_config(rng, extra) | {"task_quitting": True, "delta": int(rng.integers(0, 3))},
                           max_cycles=60)
        policy = make_policy("random")
        obs, _ = env.reset(seed=episode)
        policy.start(env, episode)
        while env.agents:
            protocol = env.protocol
            counts = protocol.knowledge.member_counts()
            for before in (NO_TIMER, protocol.round - 2, protocol.round, protocol.round + 1):
                compiled = protocol._quittable(counts, before)
                np.testing.assert_array_equal(compiled, protocol.quittable_reference(counts, before))
                allowed += int(compiled.sum())
            obs, *_ = env.step(policy.act(obs))
    assert allowed > 0


@pytest.mark.parametrize("sample", range(2))
def test_allocations_with_the_kernels_equal_those_with_the_references(sample, monkeypatch):
    """End to end on fuzzed configs: the same paths, groups and counters; scores to the last bit of exp."""
    from taskalloc.evaluation.fuzz import draw_config
    from taskalloc.policies.fast import solvable, solve
    from taskalloc_env import TaskAllocEnv, resolve_config

    rng, extra, checked = np.random.default_rng(100 + sample), np.random.default_rng([100 + sample, 2]), 0
    while checked < 30:
        kw = draw_config(rng, extra)
        cfg = resolve_config("default", **kw)
        if not solvable(cfg):                       # the direct solver's domain (tests/test_fast.py)
            continue
        name = ("cbga", "cbga+tb", "cbga+tq", "cbgabi", "cbba")[checked % 5]
        env = TaskAllocEnv(**kw | ({"agents_per_task": 1} if name == "cbba" else {}), max_cycles=300)
        env.reset(seed=checked)
        compiled = solve(env.scenario, env.config, name, max_cycles=300)
        with monkeypatch.context() as patch:
            patch.setattr(kernels, "COMPILED", False)
            reference = solve(env.scenario, env.config, name, max_cycles=300)
        assert (compiled.paths, compiled.members, compiled.counters) == \
            (reference.paths, reference.members, reference.counters), kw
        assert np.isclose(compiled.score, reference.score, rtol=1e-12, atol=0)
        checked += 1
