"""Johnson's asynchronous replan (§4.2) with our pop-up trigger (``policies/replan.py``): it fires on a hand-built
instance where a reachable pop-up would precede a bundle task and on none where a condition fails; every decision
over random pop-up scenarios against a reference written from the conditions with the brute-force gains of
``helpers``; agreement at the end, and every released task re-bid, taken by another agent, or biddable by nobody."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import agent, build, examples, reference_gain, scoring_options, task
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_cbaa import single_agent_config

from taskalloc.policies import AsyncReplanPolicy, make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.actions import ActionKind, decode
from taskalloc_env.cbba_table import NONE
from taskalloc_env.suite import task as suite_task

T0, T1, T2, POPUP = range(4)


def line(popup_x: float = 2.0, popup_equipment: tuple[str, ...] = (), rival_x: float | None = None):
    """Agent 0 at x = 0 builds T0 (x = 1, bid 90), T1 (x = 3, 80), T2 (x = 6, 70) with bundles of 3 (γ = 10 per km,
    no time discount, every window open on arrival); agent 1 at x = 12 can do T2 (40) but loses it to agent 0. The
    pop-up at ``popup_x`` (needing ``popup_equipment``) comes at tick 40. With ``rival_x``, agent 2 (equipment B, so
    it bids on the pop-up only) sits at (rival_x, 0.1)."""
    agents = [agent(0, equipment=("A",)), agent(12, equipment=("A",))]
    if rival_x is not None:
        agents.append(agent(rival_x, 0.1, equipment=("B",)))
    tasks = [task(1, equipment=("A",)), task(3, equipment=("A",)), task(6, equipment=("A",)),
             task(popup_x, equipment=popup_equipment)]
    return build(agents, tasks, time_discount=0.0, arena=(50.0, 50.0, 50.0), equipment_names=["A", "B"])


def play(policy, scenario, slow_agent_0: bool = False):
    """One episode on ``scenario`` with the pop-up at tick 40; returns the allocation and each agent's actions
    other than pass from tick 40 on. ``slow_agent_0``: agent 0's builds take 5 ticks, the others' 1."""
    env = TaskAllocEnv(scenario=scenario, consensus="acbba", release_actions=True, max_bundle=3, popup_tasks=1,
                       popup_times=[40], message_ticks=[0.0, 0.0])
    observations, infos = env.reset(seed=0)
    policy.start(env, 0)
    if slow_agent_0:
        env.protocol.build_ticks[:] = [5, 1, 1]
    late: dict[int, list[tuple[ActionKind, int]]] = {}
    while env.agents:
        actions = policy.act(observations, infos)
        for name, action in actions.items():
            if action and env.protocol.round >= 40:
                late.setdefault(env.agent_index[name], []).append(decode(action, 4))
        observations, _, _, _, infos = env.step(actions)
    return env.evaluate(), late


@pytest.mark.parametrize("scope", ["bundle", "suffix"])
def test_a_reachable_popup_that_would_precede_a_bundle_task_triggers_the_replan(scope):
    """On the kept path [T0] the pop-up (x = 2) gains 90 against the 80 of T1 and the 50 of T2, the first tasks it
    would displace; on the empty path 80 against T0's 90. So it would precede T1: ``suffix`` releases T1 (and T2)
    and bids the pop-up first, ``bundle`` releases all, re-bids T0, then the pop-up. T2 no longer fits and agent 1
    takes it. Without the replan agent 0's bundle is full and nobody can do the pop-up."""
    scenario = line()
    policy = AsyncReplanPolicy(scope)
    allocation, late = play(policy, scenario)
    [replan] = policy.replans
    assert (replan.agent, replan.popup, replan.precedes) == (0, POPUP, T1)
    assert replan.released == (T0 if scope == "bundle" else T1)
    assert replan.gain == pytest.approx(reference_gain(scenario, 0, [T0], POPUP)[0]) == pytest.approx(90.0)
    assert replan.rival == pytest.approx(reference_gain(scenario, 0, [T0], T1)[0]) == pytest.approx(80.0)
    rebuilt = [T0, POPUP, T1] if scope == "bundle" else [POPUP, T1]
    assert late[0] == [(ActionKind.RELEASE, replan.released), *((ActionKind.BID, j) for j in rebuilt)]
    assert allocation.paths == ((T0, POPUP, T1), (T2,)) and allocation.score == pytest.approx(310.0)
    assert allocation.converged and allocation.agreement and not allocation.conflicts
    plain = rollout(TaskAllocEnv(scenario=scenario, consensus="acbba", release_actions=True, max_bundle=3,
                                 popup_tasks=1, popup_times=[40], message_ticks=[0.0, 0.0]), make_policy("acbba"), 0)
    assert plain.paths == ((T0, T1, T2), ()) and plain.score == pytest.approx(240.0)


CASES = {"out of reach": {"popup_x": -40.0}, "not its equipment": {"popup_equipment": ("B",), "rival_x": -40.0},
         "would not precede": {"popup_x": 6.5}, "outbid": {"rival_x": 2.0}}


@pytest.mark.parametrize("case", list(CASES))
def test_the_replan_does_not_fire_when_a_condition_fails(case):
    """Out of reach: 40 km away the pop-up gains nothing on any kept path. Not its equipment: the pop-up at x = 2
    needs B, which agent 0 lacks (its gains are those of the firing case; agent 2, far away, has B). Would not
    precede: at x = 6.5 it gains 65 on [T0, T1] against T2's 70, 45 on [T0] against 80, 35 on [] against 90.
    Outbid: agent 2 bid 99 on it before agent 0's build was ready, so h_ij fails. In each case the episode is plain
    ACBBA's."""
    scenario, slow = line(**CASES[case]), case == "outbid"
    policy = AsyncReplanPolicy("suffix")
    allocation, _ = play(policy, scenario, slow_agent_0=slow)
    plain, _ = play(make_policy("acbba"), scenario, slow_agent_0=slow)
    assert policy.replans == [] and allocation.counters.releases == 0
    assert allocation.paths == plain.paths and allocation.counters.broadcasts == plain.counters.broadcasts
    assert allocation.paths[0] == (T0, T1, T2)


def reference_trigger(env: TaskAllocEnv, i: int, popups: np.ndarray, margin: float = 1e-7):
    """The trigger's conditions read straight from the module docstring, with the brute-force gains of (3.11)
    (``helpers.reference_gain``): (pop-up, first task it would precede) or None; "ambiguous" when a comparison is
    within ``margin`` (float rounding may decide it either way)."""
    p, s, cfg = env.protocol, env.scenario, env.config
    kn = p.knowledge
    sequence = kn.bundles[i] if cfg.release_order == "bundle" else kn.paths[i]
    own = kn.own_bids()[i]
    eligible = s.eligible()[i]
    view = p.view()
    for k, cut in enumerate(sequence):
        kept = [t for t in kn.paths[i] if t in sequence[:k]]

        def gain(j, kept=kept):
            return reference_gain(s, i, kept, j, marginal_gain=cfg.marginal_gain, **scoring_options(env))[0]

        rival = max(gain(t) for t in sequence[k:])
        passing = []
        for j in popups:
            if not (p.released[j] and eligible[j] and view.prereqs_met[i, j] and p.fillable[j]
                    and j not in kn.bundles[i] and not kn.quit_blocked[i, j]):
                continue
            c = gain(j)
            bid = min(c, min(own[t] for t in kept)) if cfg.bid_warping and kept else c
            y, z = kn.winning_bid()[i, j], kn.winner[i, j]
            if min(abs(c - rival), abs(bid - y) if z != NONE else 1.0, abs(c) if c else 1.0) < margin:
                return "ambiguous"
            wins = z == NONE or bid > y or (cfg.outbid_ties != "strict" and bid == y and i > z)
            if c > 0 and wins and c > rival:
                passing.append((c, -j))
        if passing:
            return -max(passing)[1], cut
    return None


@settings(max_examples=examples(100), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kw=single_agent_config(), scope=st.sampled_from(["bundle", "suffix"]), popups=st.integers(1, 4),
       period=st.sampled_from([1, 7, 30]), seed=st.integers(0, 2**16))
def test_every_trigger_decision_matches_the_reference_and_the_team_agrees(kw, scope, popups, period, seed):
    """Random single-agent scenarios under ``acbba`` with pop-up tasks: each evaluation of the trigger (fire or not,
    which pop-up, which task) equals ``reference_trigger``'s; the run converges conflict-free in agreement, and every
    task a replan released ends on some path or is a valid bid of nobody."""
    kw = {**kw, "popup_tasks": min(popups, kw["n_tasks"] - 1) or 1, "popup_period": period}
    policy = AsyncReplanPolicy(scope)
    env = TaskAllocEnv(**{**kw, **policy.env_overrides}, dtype="float64")
    checked = []
    real = policy.trigger

    def trigger(agent, new):
        expected = reference_trigger(env, agent, new)
        replan = real(agent, new)
        if expected != "ambiguous":
            assert (None if replan is None else (replan.popup, replan.precedes)) == expected
            checked.append(replan is not None)
        return replan

    policy.trigger = trigger
    allocation = rollout(env, policy, seed=seed)
    assert allocation.converged and allocation.agreement and not allocation.conflicts
    held = {j for path in allocation.paths for j in path}
    can_bid = env.protocol.view().can_bid
    for replan in policy.replans:
        assert all(j in held or not can_bid[:, j].any() for j in replan.dropped)
    assert allocation.counters.releases == len(policy.replans)


def test_on_johnsons_popup_setting_many_replans_fire_each_as_the_reference_says():
    """One episode of the suite's Async (8 agents, bundles of 5, 25 pop-ups): every trigger evaluation equals
    ``reference_trigger``'s, and replans do fire."""
    policy = AsyncReplanPolicy("suffix")
    env = TaskAllocEnv(suite_task("taskalloc/Async-v0").config(), dtype="float64", **policy.env_overrides)
    decisions = []
    real = policy.trigger

    def trigger(agent, new):
        expected, replan = reference_trigger(env, agent, new), real(agent, new)
        assert expected == "ambiguous" or (None if replan is None else (replan.popup, replan.precedes)) == expected
        decisions.append(replan is not None)
        return replan

    policy.trigger = trigger
    allocation = rollout(env, policy, seed=0)
    assert allocation.converged and allocation.agreement and not allocation.conflicts
    assert len(decisions) > 100 and sum(decisions) >= 10


def test_the_policy_names_its_scope_and_needs_single_agent_tasks():
    with pytest.raises(ValueError, match="scope 'all' is not one of"):
        AsyncReplanPolicy("all")
    policy = make_policy("acbba+replan")
    assert isinstance(policy, AsyncReplanPolicy) and policy.scope == "bundle"
    assert policy.env_overrides == {"consensus": "acbba", "release_actions": True}
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="single-agent tasks only"):
        policy.start(env, 0)
