"""ACBBA in the environment (``consensus="acbba"``, Johnson §4.1): convergence, agreement with synchronous CBBA,
timestamps, the listener/builder split, release of outbid tasks, pop-up tasks, local convergence, multi-agent tasks
asynchronously, faults, and determinism across processes."""

from __future__ import annotations

import itertools
import re
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from helpers import agent, build, episode_digest, examples, task
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from taskalloc.evaluation import acbba_check
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.async_consensus import compose
from taskalloc_env.async_protocol import AsyncProtocol
from taskalloc_env.cbba_table import NONE
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.errors import ConfigError
from taskalloc_env.scenario import scenario_config
from taskalloc_env.stamps import NEVER, stamp, tick_of

DMG = {"distance_cost": "from_start", "marginal_gain": "frozen", "agents_per_task": 1}


# -- ACBBA against synchronous CBBA (Johnson §1.2: "the task space convergence properties of nominal CBBA") -----------
def test_acbba_converges_agrees_and_matches_cbba_on_random_dmg_scenarios():
    """A smaller run of ``taskalloc acbba-check`` (1000 scenarios, docs/results.md): every ACBBA run goes
    quiet conflict-free in agreement, and its allocation equals CBBA's or the difference is stale information."""
    verdicts = acbba_check.run_checks(60, {}, jobs=1)
    text, ok = acbba_check.report(verdicts)
    assert ok, text
    assert sum(v.equal is True for v in verdicts) >= 55, text


@pytest.mark.slow
def test_acbba_check_on_a_thousand_scenarios():
    text, ok = acbba_check.report(acbba_check.run_checks(1000, {}, jobs=2))
    assert ok, text


@pytest.mark.parametrize("faults", [
    {"message_loss": 0.2, "max_delay": 3},                     # both at once: the fast subset's case
    pytest.param({"message_loss": 0.2}, marks=pytest.mark.slow),
    pytest.param({"loss_model": "gilbert_elliott", "message_loss": 0.02, "burst_enter": 0.1, "burst_leave": 0.4},
                 marks=pytest.mark.slow),
    pytest.param({"max_delay": 5}, marks=pytest.mark.slow)], ids=["loss+delay", "loss", "bursts", "delay"])
def test_under_loss_and_delay_acbba_still_converges_conflict_free(faults):
    text, ok = acbba_check.report(acbba_check.run_checks(30, faults, jobs=1))
    assert ok, text


# -- timestamps, buffers, rebroadcasts ---------------------------------------------------------------------------------
def _drive(env: TaskAllocEnv, policy: str, seed: int, watch=None):
    p = make_policy(policy)
    obs, infos = env.reset(seed=seed)
    p.start(env, seed)
    while env.agents:
        actions = p.act({a: obs[a] for a in env.agents}, infos)
        ready = env.protocol.ready.copy()
        tick = env.protocol.round
        if watch:
            watch("before", env, actions, ready, tick)
        obs, _, _, _, infos = env.step(actions)
        if watch:
            watch("after", env, actions, ready, tick)
    return env.evaluate()


def test_bids_carry_the_tick_they_were_made_and_only_completed_builds_broadcast():
    """Johnson §4.1.1: "the current time is sampled and recorded as the bid time" (line 812); outgoing buffers are
    flushed "triggered by the completion of the BundleBuilder thread" (line 763): every broadcast comes from a ready
    agent that passed in that tick, and agents that are not ready may only pass."""
    env = TaskAllocEnv(n_agents=6, n_tasks=12, consensus="acbba", **DMG)
    passed: list[tuple[int, int]] = []
    stamped: list[bool] = []

    def watch(when, env, actions, ready, tick):
        p = env.protocol
        if when == "before":
            for a, action in actions.items():
                assert ready[env.agent_index[a]] or action == 0
            advance = p.advance

            def checked():                 # the decisions are applied, the tick has not moved on yet
                for a, action in actions.items():
                    if action:
                        i = env.agent_index[a]
                        stamped.append(p.times.task[i, action - 1] == stamp(tick, i))
                p.advance = advance
                advance()
            p.advance = checked
            return
        passed.extend((tick, env.agent_index[a]) for a, action in actions.items()
                      if not action and ready[env.agent_index[a]])

    alloc = _drive(env, "acbba", seed=3, watch=watch)
    assert alloc.converged and alloc.agreement and not alloc.conflicts
    assert stamped and all(stamped)
    log = env.protocol.broadcast_log
    assert log and all((tick, sender) in set(passed) for tick, sender, _ in log)
    assert alloc.counters.broadcasts == len(log)


def test_quiet_means_every_agent_holds_the_same_record_and_time():
    """With unique (tick, bump, stamper) stamps, a quiet network holds identical (z, y, t) everywhere (note §8.3)."""
    for seed in range(8):
        env = TaskAllocEnv(n_agents=5, n_tasks=10, consensus="acbba", **DMG)
        alloc = rollout(env, make_policy("acbba"), seed=seed)
        p = env.protocol
        assert alloc.globally_converged and p.counters.quiet_tick == p.round
        assert (p.times.task == p.times.task[0]).all() and (p.knowledge.winner == p.knowledge.winner[0]).all()
        for i, bundle in enumerate(p.knowledge.bundles):
            assert all(p.knowledge.winner[0, j] == i for j in bundle)


def test_an_outbid_task_is_released_with_the_tasks_after_it_as_empty_bids_with_the_current_time():
    """Module 1 (line 773): an outbid agent releases the task and every later one; the later ones it held go out as
    Table 4.1's rebroadcast* form, an empty bid with the current time; the lost task keeps the new winner's record."""
    s = build([agent(0), agent(5)], [task(1), task(2), task(9)])
    cfg = scenario_config(s, consensus="acbba", build_ticks=(0, 0), message_ticks=(0.0, 0.0), **DMG)
    p = AsyncProtocol(s, cfg)
    assert p.ready.all()
    p.bid(0, 0)
    p.bid(0, 1)
    p.finish(0)
    p.finish(1)
    p.advance()                                        # tick 1: agent 1 hears agent 0's two bids
    assert p.knowledge.winner[1, 0] == 0
    rival = AsyncProtocol(s, cfg)                      # agent 1's higher bid on task 0, made at tick 1
    rival.round = 1
    rival.knowledge.set_bid(1, 1, 0, 1000.0)
    rival.times.task[1, 0] = stamp(1, 1)
    message = compose(rival.knowledge, rival.times, 1, 1, np.array([True, False, False]))
    p.payloads[(1, 1)] = message
    p.network.send(1, np.array([1]), np.array([0, message.data_items]))
    p.advance()                                        # tick 2: agent 0 is outbid on task 0, builds, releases
    kn = p.knowledge
    assert p.ready[0] and kn.bundles[0] == []
    assert (kn.winner[0, 0], p.times.task[0, 0]) == (1, stamp(1, 1))
    assert (kn.winner[0, 1], p.times.task[0, 1]) == (NONE, stamp(2, 0))
    assert p.outgoing[0, :2].all()
    p.finish(0)
    sent = p.payloads[(0, 2)]
    assert (sent.winner[1], sent.bid[1], tick_of(sent.time[1])) == (NONE, 0.0, 2)


# -- convergence: global and local (Johnson §4.1.3) --------------------------------------------------------------------
def test_evaluate_reports_global_and_local_convergence_and_their_times():
    env = TaskAllocEnv(n_agents=5, n_tasks=10, consensus="acbba", separation_time=10, **DMG)
    alloc = rollout(env, make_policy("acbba"), seed=2)
    c = alloc.counters
    assert alloc.converged and alloc.globally_converged and alloc.locally_converged
    assert 0 < c.quiet_tick == c.rounds and c.local_tick > c.quiet_tick - 1
    assert c.separation_ticks <= c.quiet_tick and c.broadcasts > 0
    summary = alloc.summary()
    assert {"quiet_tick", "local_tick", "separation_ticks", "globally_converged", "locally_converged"} <= set(summary)
    local = rollout(TaskAllocEnv(n_agents=5, n_tasks=10, consensus="acbba", separation_time=10,
                                 termination="local", **DMG), make_policy("acbba"), seed=2)
    assert local.converged and local.locally_converged and local.counters.local_tick == local.counters.rounds


def _declarations(env: TaskAllocEnv, policy: str, seed: int) -> list[tuple[int, dict[str, dict]]]:
    """(tick, infos) after reset and after every step of an episode."""
    p = make_policy(policy)
    obs, infos = env.reset(seed=seed)
    p.start(env, seed)
    seen = [(env.protocol.round, infos)]
    while env.agents:
        obs, _, _, _, infos = env.step(p.act({a: obs[a] for a in env.agents}, infos))
        seen.append((env.protocol.round, infos))
    return seen


@pytest.mark.parametrize("clock", ["bundle", "table"])
def test_each_agent_declares_its_own_local_convergence_in_infos(clock):
    """Johnson §4.1.3 (separation time, l. 941–943): an agent declares itself converged after more than
    ``separation_time`` ticks without relevant news; the run is locally converged at the tick the last one does.
    Slow listeners (0.5–2 ticks per message) spread the agents' last news, so they declare at different ticks."""
    env = TaskAllocEnv(n_agents=5, n_tasks=10, consensus="acbba", separation_time=10, termination="local",
                       message_ticks=(0.5, 2.0), local_convergence=clock, **DMG)
    seen = _declarations(env, "acbba", seed=2)
    declared_first: dict[str, int] = {}
    for tick, infos in seen:
        for a, info in infos.items():
            at = info["locally_converged_at"]
            assert info["locally_converged"] == (at >= 0) and at <= tick
            if info["locally_converged"]:
                declared_first.setdefault(a, tick)
                assert tick - at >= 0 and at > env.config.separation_time
    last_tick, last = seen[-1]
    assert all(info["locally_converged"] for info in last.values())
    assert max(info["locally_converged_at"] for info in last.values()) == env.protocol.counters.local_tick == last_tick
    assert len(set(declared_first.values())) > 1                               # agents declare at their own ticks
    before_last = seen[-2][1]
    assert not all(info["locally_converged"] for info in before_last.values())


@pytest.mark.parametrize("clock", ["bundle", "table"])
def test_a_popup_task_withdraws_every_declaration_and_sync_infos_have_none(clock):
    """An agent does not know the future: it may declare before a pop-up, and the release is news to every agent
    (under ``bundle`` its builder wakes, so it declares again only once the build has run)."""
    env = TaskAllocEnv(n_agents=4, n_tasks=8, consensus="acbba", separation_time=10, popup_tasks=1,
                       popup_times=[150], local_convergence=clock, **DMG)
    seen = _declarations(env, "acbba", seed=0)
    at = {tick: infos for tick, infos in seen}
    assert all(info["locally_converged"] for info in at[149].values())
    assert not any(info["locally_converged"] for info in at[150].values())
    assert all(info["locally_converged"] for info in seen[-1][1].values()) and seen[-1][0] > 150
    _, infos = TaskAllocEnv(n_agents=3, n_tasks=4, **DMG).reset(seed=0)
    assert all("locally_converged" not in info for info in infos.values())


# -- local convergence while others negotiate (Johnson §4.1.3, l. 939; ``local_convergence``) -----------------------
RELEASE = 60


def _popup_scene(clock: str) -> TaskAllocEnv:
    """Five agents on a line, bundles of one task: agents 2 and 3 hold the tasks next to them, agent 4 (out of range
    of everybody, comm_range 7) holds one only it can reach; agents 0 and 1 hold nothing. At tick 60 a task pops
    up next to agent 0: agents 0 and 1 bid and settle who wins, the others cannot bid (full bundles)."""
    s = build([agent(0), agent(1), agent(3), agent(5), agent(9.5, 9)],
              [task(3.1, start=0, end=50), task(5.1, start=0, end=50), task(9.5, 9.1, start=0, end=1),
               task(0.4, start=0, end=50)])
    return TaskAllocEnv(scenario=s, consensus="acbba", max_bundle=1, comm_range=7.0, popup_tasks=1,
                        popup_times=[RELEASE], build_ticks=(1, 1), message_ticks=(0.0, 0.0), separation_time=10,
                        local_convergence=clock, termination="global", distance_cost="from_start",
                        marginal_gain="frozen", invalid_action="raise")


def _ticks(env: TaskAllocEnv) -> dict[int, dict]:
    """Per tick: the agents declared, the broadcasters and each agent's record of the pop-up task (task 3)."""
    seen: dict[int, dict] = {}

    def watch(when, env, actions, ready, tick):
        p = env.protocol
        if when == "before":
            seen[tick] = {"declared": p.agents_locally_converged.copy(), "tables": p.knowledge.winner.copy(),
                          "times": p.times.task.copy()}
        else:
            seen[tick]["broadcast"] = {a for t, a, _ in p.broadcast_log if t == tick}

    alloc = _drive(env, "acbba", seed=0, watch=watch)
    assert alloc.converged and alloc.agreement and alloc.paths == ((3,), (), (0,), (1,), (2,))
    return seen


@pytest.mark.parametrize("clock", ["bundle", "table"])
def test_a_popup_announcement_sends_nothing_and_only_agents_whose_tables_change_rebroadcast(clock):
    """After a pop-up near agent 0 the first broadcasts are the bids of the two agents that can take it (Johnson
    l. 763: a build's changes go out when it completes); the full agents broadcast only once their table holds a bid
    on the pop-up (Table 4.1's update & rebroadcast, rows 12 and 7); agent 4, out of range, learns of the task but
    hears no bid: its table never changes and it never broadcasts. The announcement itself sends nothing."""
    seen = _ticks(_popup_scene(clock))
    after = [t for t in sorted(seen) if t >= RELEASE]
    first = next(t for t in after if seen[t]["broadcast"])
    assert seen[first]["broadcast"] == {0, 1} and first > RELEASE
    for t in after:
        assert 4 not in seen[t]["broadcast"]
        assert (seen[t]["tables"][4] == seen[RELEASE]["tables"][4]).all()
        assert (seen[t]["times"][4] == seen[RELEASE]["times"][4]).all()
        for a in seen[t]["broadcast"] & {2, 3}:
            assert seen[t]["tables"][a, 3] in (0, 1)          # its record of the pop-up: a bidder's bid


@pytest.mark.parametrize("clock", ["bundle", "table"])
def test_agents_that_keep_their_bundles_declare_while_the_bidders_negotiate(clock):
    """Johnson l. 939: agents that "will not change their bundles based on the presence of this task ... can decide
    that they have reached self convergence ... even though others are still actively engaging in a consensus
    phase". Under ``bundle`` the full agents are declared when the bidders broadcast their bids, and agent 4 stays
    declared throughout except while its builder checks the new task; under ``table`` (any relevant news restarts
    the clock, l. 941 read literally) nobody is declared while the pop-up is negotiated."""
    seen = _ticks(_popup_scene(clock))
    assert seen[RELEASE - 1]["declared"].all() and max(seen) < RELEASE + 10
    first = next(t for t in sorted(seen) if t >= RELEASE and seen[t]["broadcast"])
    talks = [t for t in sorted(seen) if t >= RELEASE and seen[t]["broadcast"] & {0, 1}]
    if clock == "bundle":
        assert seen[first]["declared"].tolist() == [False, False, True, True, True]
        assert all(seen[t]["declared"][4] for t in range(RELEASE + 2, max(seen) + 1))
        assert not any(seen[t]["declared"][:2].any() for t in talks)
    else:
        assert not any(seen[t]["declared"].any() for t in seen if t >= RELEASE)     # the run is quiet before


@settings(max_examples=examples(200), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n_agents=st.integers(2, 5), n_tasks=st.integers(2, 7), popups=st.integers(0, 3),
       period=st.sampled_from([3, 15, 40]), faults=st.sampled_from([{}, {"max_delay": 2}, {"message_loss": 0.2},
                                                                   {"comm_range": 2.0}]),
       sep=st.sampled_from([5, 12]), seed=st.integers(0, 10_000))
def test_the_clock_changes_who_is_declared_never_what_is_sent_or_allocated(n_agents, n_tasks, popups, period,
                                                                           faults, sep, seed):
    """``local_convergence`` moves only the declarations: with the episode run to quiet (``termination=global``)
    both settings send the same broadcasts and end with the same tables. Under ``bundle`` a declared agent's
    bundle and the records of the tasks it holds (bid, time) have not changed for more than ``separation_time``
    ticks and its builder is idle."""
    config = {"n_agents": n_agents, "n_tasks": min(n_tasks + popups, 9), "popup_tasks": popups,
              "popup_period": period, "consensus": "acbba", "termination": "global", "separation_time": sep,
              **faults, **DMG}
    runs = {}
    for clock in ("table", "bundle"):
        history: list[tuple[list[list[int]], np.ndarray, np.ndarray]] = []

        def watch(when, env, actions, ready, tick, history=history, clock=clock):
            p = env.protocol
            if when != "after":
                return
            own = p.knowledge.own_bids()                  # the agent's own records: bids and their times
            history.append(([list(b) for b in p.knowledge.bundles], own.copy(), np.where(own > 0, p.times.task, NEVER)))
            if clock != "bundle":
                return
            for i in np.flatnonzero(p.agents_locally_converged):
                assert p.ready_at[i] == -1 and not p.inbox[i]
                window = history[-(sep + 1):]
                last = window[-1]
                assert all(b[i] == last[0][i] and (y[i] == last[1][i]).all() and (t[i] == last[2][i]).all()
                           for b, y, t in window)

        env = TaskAllocEnv(**config, local_convergence=clock)
        alloc = _drive(env, "acbba", seed, watch=watch)
        runs[clock] = (env.protocol.broadcast_log, alloc.paths, env.protocol.knowledge.winner.copy(), alloc.converged)
    assert runs["table"][0] == runs["bundle"][0] and runs["table"][1:2] == runs["bundle"][1:2]
    assert (runs["table"][2] == runs["bundle"][2]).all() and runs["table"][3] == runs["bundle"][3]


@pytest.mark.slow
def test_in_johnsons_popup_setting_agents_declare_while_others_broadcast():
    """Johnson's 8 agents × 35 tasks, 10 at the start and a pop-up every 50 ticks (``taskalloc acbba-experiments
    profiles`` measures it on 20 seeds): under ``bundle`` some agent is declared at a share of the ticks with
    broadcasts, under ``table`` at none; both end quiet and in agreement."""
    from taskalloc.evaluation.acbba_experiments import JOHNSON, episode

    shares = {}
    for clock in ("bundle", "table"):
        rows = [episode(("acbba", {**JOHNSON, "popup_tasks": 25, "popup_period": 50, "local_convergence": clock}, s))
                for s in range(2)]
        assert all(r["converged"] and r["agreement"] for r in rows)
        shares[clock] = sum(r["declared_traffic"] for r in rows) / sum(r["traffic"] for r in rows)
    assert shares["table"] == 0 and shares["bundle"] > 0.1


# -- error messages ----------------------------------------------------------------------------------------------------
def test_acbba_on_multi_agent_tasks_names_acbba_and_the_asynchronous_cbga():
    env = TaskAllocEnv(n_agents=4, n_tasks=6, consensus="acbba", agents_per_task=2)
    env.reset(seed=0)
    with pytest.raises(ValueError) as err:
        make_policy("acbba").start(env, 0)
    text = str(err.value)
    assert text.startswith("ACBBA assigns single-agent tasks only")
    assert 'consensus="acbba"' in text and 'make_policy("cbgabi")' in text and "CBGA" in text
    with pytest.raises(ValueError, match=r"^CBBA assigns single-agent tasks only .* use CBGAPolicy"):
        make_policy("cbba").start(env, 0)


@pytest.mark.parametrize("field, pair", [("message_ticks", (0.5, 0.1)), ("build_ticks", (3, 1))])
def test_a_reversed_processing_time_range_says_the_upper_bound_must_not_be_below_the_lower(field, pair):
    with pytest.raises(ConfigError, match=rf"'{field}': got {re.escape(repr(pair))}; allowed: .*upper bound >= "
                                          r"the lower bound"):
        TaskAllocConfig(consensus="acbba", **{field: pair})


# -- pop-up tasks (Johnson §4.1.3, Figs 4-3 and 4-4) -------------------------------------------------------------------
@pytest.mark.parametrize("consensus", ["sync", "every_step", "acbba"])
def test_popup_tasks_are_invisible_until_released(consensus):
    env = TaskAllocEnv(n_agents=3, n_tasks=6, popup_tasks=2, popup_times=[3, 6], consensus=consensus, **DMG)
    obs, infos = env.reset(seed=1)
    layout = env.observation_layout
    p = make_policy("acbba" if consensus == "acbba" else "cbba")
    p.start(env, 1)
    seen = set()
    while env.agents:
        released = env.protocol.released.copy()
        for o in obs.values():
            _, tasks = layout.split(o["observation"])
            assert not tasks[~released].any() and (tasks[released, layout.task_column("released")] == 1).all()
            assert not o["action_mask"][1:][np.r_[~released, ~released]].any()
        assert (env.protocol.release_tick[released] <= env.protocol.round).all()
        seen |= set(np.flatnonzero(released).tolist())
        obs, _, _, _, infos = env.step(p.act({a: obs[a] for a in env.agents}, infos))
    assert seen == set(range(6)) and env.evaluate().converged


def test_release_times_bound_the_schedule_when_ticks_map_to_mission_time():
    """``mission_time_per_tick``: a pop-up released at tick r cannot start before r × that (scoring counts only what is
    feasible after release)."""
    env = TaskAllocEnv(n_agents=3, n_tasks=6, popup_tasks=3, popup_period=20, mission_time_per_tick=1.0,
                       consensus="acbba", **DMG)
    alloc = rollout(env, make_policy("acbba"), seed=4)
    release = env.protocol.release_tick
    for path, starts in zip(alloc.paths, alloc.start_times):
        for j, start in zip(path, starts):
            assert start >= release[j] * 1.0 - 1e-9


def test_poisson_arrivals_are_seeded_and_within_the_horizon():
    ticks = []
    for seed in (0, 0, 1):
        env = TaskAllocEnv(n_agents=3, n_tasks=8, popup_tasks=5, popup_period=30, popup_arrivals="poisson",
                           consensus="acbba", **DMG)
        env.reset(seed=seed)
        ticks.append(env.protocol.release_tick.tolist())
    assert ticks[0] == ticks[1] != ticks[2]
    assert all(0 < t <= 150 for t in ticks[0][3:]) and ticks[0][:3] == [0, 0, 0]


def test_slow_popups_are_assigned_within_a_bounded_time_and_the_profile_is_burst_then_quiet():
    """Arrivals slower than convergence (the 0.2 s analogue): each released task that some agent can do holds a
    winner in every table within BOUND ticks, and every burst of broadcasts ends before the next release."""
    period, bound = 150, 60
    for seed in range(4):
        env = TaskAllocEnv(n_agents=6, n_tasks=14, popup_tasks=6, popup_period=period, consensus="acbba",
                           termination="global", **DMG)
        checks = {}

        def watch(when, env, actions, ready, tick, checks=checks):
            p = env.protocol
            if when != "after":
                return
            for j in np.flatnonzero((p.release_tick > 0) & (p.round - p.release_tick == bound)):
                held = (p.knowledge.winner[:, j] != NONE).all()
                nobody_can = not (p.view().gain[:, j] > 0).any()
                checks[int(j)] = held or nobody_can

        alloc = _drive(env, "acbba", seed=seed, watch=watch)
        assert alloc.converged and not alloc.conflicts
        p = env.protocol
        for j in np.flatnonzero(p.release_tick > 0):       # released less than BOUND ticks before the end
            checks.setdefault(int(j), bool((p.knowledge.winner[:, j] != NONE).all()
                                           or not (p.view().gain[:, j] > 0).any()))
        assert len(checks) == 6 and all(checks.values()), checks
        releases = sorted(set(env.protocol.release_tick.tolist()))
        ticks = np.array([t for t, _, _ in env.protocol.broadcast_log])
        for start, nxt in itertools.pairwise(releases):
            burst = ticks[(ticks >= start) & (ticks < nxt)]
            assert burst.size and burst.max() < nxt - 1 and burst.max() - start < bound


# -- multi-agent tasks asynchronously (CBGA's merge per message; our extension) ----------------------------------------
FAULTS = {
    "perfect": {},
    "loss+delay": {"message_loss": 0.2, "max_delay": 3},
    "bursts": {"loss_model": "gilbert_elliott", "message_loss": 0.02, "burst_enter": 0.1, "burst_leave": 0.4},
    "range": {"comm_range": 2.5},
    "dropouts": {"dropouts": 2, "dropout_rounds": [1, 20]},
    "popups": {"popup_tasks": 3, "popup_period": 40},
}


@pytest.mark.parametrize("fault", sorted(FAULTS))
@pytest.mark.parametrize("policy", ["cbga", "cbgabi", "acbba"])
def test_asynchronous_episodes_converge_agree_and_are_conflict_free(fault, policy):
    p = make_policy(policy)
    extra = {"agents_per_task": 1} if policy == "acbba" else {}
    env = TaskAllocEnv("train_small", **{"consensus": "acbba", **FAULTS[fault], **extra, **p.env_overrides})
    for seed in range(6):
        allocation = rollout(env, p, seed=seed)
        live = env.protocol.alive
        connected = len(set(env.protocol.live_graph.component[live].tolist())) == 1
        assert allocation.converged, f"seed {seed}: hit the tick bound"
        assert allocation.agreement, f"seed {seed}"
        assert not allocation.conflicts or not connected, f"seed {seed}: {allocation.conflicts}"


def test_a_failed_agent_is_announced_and_its_tasks_are_reassigned():
    s = build([agent(0), agent(1)], [task(1, start=10, end=100), task(0, 1, start=10, end=100)])
    env = TaskAllocEnv(scenario=s, consensus="acbba", dropout_schedule=[[1, 12]], silence_timeout=5,
                       build_ticks=(0, 0), invalid_action="raise")
    alloc = rollout(env, make_policy("acbba"), seed=0)
    assert alloc.converged and alloc.paths[1] == () and set(alloc.paths[0]) == {0, 1}
    assert alloc.counters.dropped_agents == 1 and alloc.counters.silent_releases >= 1


def test_listener_processing_time_delays_messages():
    """Per-agent processing times: a listener slower than a tick per message takes several ticks for a burst."""
    env = TaskAllocEnv(n_agents=4, n_tasks=8, consensus="acbba", message_ticks=(1.0, 1.0), **DMG)
    env.reset(seed=0)
    assert (env.protocol.message_ticks == 1.0).all()
    fast = rollout(TaskAllocEnv(n_agents=4, n_tasks=8, consensus="acbba", message_ticks=(0.0, 0.0), **DMG),
                   make_policy("acbba"), seed=0)
    slow = rollout(env, make_policy("acbba"), seed=0)
    assert slow.converged and slow.counters.quiet_tick > fast.counters.quiet_tick


# -- determinism -------------------------------------------------------------------------------------------------------
ASYNC_CASES = [
    ("acbba", {"agents_per_task": 1, "popup_tasks": 3, "popup_period": 20, "popup_arrivals": "poisson"}),
    ("cbgabi", {"message_loss": 0.2, "max_delay": 2}),
    ("random", {"popup_tasks": 2, "popup_period": 10, "build_ticks": [0, 4], "message_ticks": [0.0, 0.7]}),
]


def test_asynchronous_episodes_replay_byte_identically_across_processes():
    cases = [(name, {"consensus": "acbba", **extra}, seed) for name, extra in ASYNC_CASES for seed in (3, 4)]
    here = [episode_digest(c) for c in cases]
    with ProcessPoolExecutor(2) as pool:
        there = list(pool.map(episode_digest, cases))
    assert here == there and len(set(here)) == len(here)


def test_never_is_before_every_stamp_and_fresh_tables_hold_no_time():
    p = AsyncProtocol(build([agent(0)], [task(1)]), scenario_config(build([agent(0)], [task(1)]), consensus="acbba"))
    assert (p.times.task == NEVER).all() and (p.times.entry == NEVER).all() and stamp(0, 0) > NEVER


# -- fuzz regressions (evaluation.fuzz.cases(1500, 2026)) --------------------------------------------------------------
FUZZ_1262656425 = {
    "n_agents": 2, "n_tasks": 3, "start_time_range": [0.0, 60.0], "window": 10.0, "duration": 0.0,
    "agents_per_task": [1, 2], "prerequisites": {"chains": 1, "length": 3, "followup_window": True},
    "prereq_mode": "all_have_bid", "prereq_timing": "earliest", "marginal_gain": "rescore", "reward_split": "per_agent",
    "release_order": "path", "cbba_table": "canonical", "consensus": "acbba", "reset_on": "additions",
    "quit_block": "none", "conflict_policy": "first_L_paid", "distance_cost": "from_start", "message_ticks": [0.1, 0.4],
    "build_ticks": [1, 3], "separation_time": 5, "termination": "local", "acbba_row11": "update",
    "acbba_row15": "leave_bump", "acbba_time_refresh": "epsilon", "acbba_ties": "lowest_id",
    "acbba_equal_bids": "leave", "acbba_outbid_time": "bump", "acbba_row20_guard": True, "acbba_row28_guard": True,
    "message_loss": 0.0, "max_delay": 0, "loss_model": "gilbert_elliott"}


def test_a_disagreement_at_rest_comes_only_from_a_link_that_lost_every_message():
    """Fuzz seed 1262656425 (cbga+tb): message_loss 0, but the Gilbert–Elliott link 0 → 1 enters its bad state
    (burst_loss 1) and loses all five of agent 0's broadcasts, its bid on task 1, its answer and both confirmations;
    agent 1 keeps its own older, lower bid. ACBBA never resends (docs/decisions.md "lost messages"), so the fuzz
    excuses a disagreement only when the last message between the two agents was lost; without the bad state the
    same run agrees."""
    from taskalloc.evaluation import fuzz

    case = (FUZZ_1262656425, "cbga+tb", 1262656425)
    verdict = fuzz.run_case(case)
    assert verdict["agreement"] is None and verdict["conflict-free"] is None
    assert all(verdict[c] for c in ("spaces", "return", "valid groups", "determinism"))
    # the network goes quiet with the two tables disagreeing: not converged, counted apart with the reason
    assert verdict["converged"] is None and "quiet" in verdict["why"] and "disagreeing" in verdict["why"]
    for burst_loss in (1.0, 0.0):
        policy = make_policy("cbga+tb")
        env = TaskAllocEnv(**{**FUZZ_1262656425, "burst_loss": burst_loss, **policy.env_overrides})
        obs, infos = env.reset(seed=1262656425)
        last_lost = fuzz._record_losses(env)
        policy.start(env, 1262656425)
        while env.agents:
            obs, _, _, _, infos = env.step(policy.act({a: obs[a] for a in env.agents}, infos))
        alloc = env.evaluate()
        assert alloc.globally_converged is (burst_loss == 0.0)          # quiet with disagreeing tables: not converged
        assert alloc.agreement is (burst_loss == 0.0)
        assert bool(last_lost[0, 1]) is (burst_loss == 1.0)
        assert fuzz._lost_disagreement(env.protocol, last_lost) is (burst_loss == 1.0)


LIVELOCK_1832714987 = {"n_agents": 4, "n_tasks": 9, "start_time_range": [0.0, 60.0], "agents_per_task": 1,
                       "consensus": "acbba", "acbba_row11": "trust_later", "acbba_outbid_time": "bump",
                       "max_rounds": 150}


def test_the_outbid_bump_can_livelock_a_complete_graph_and_the_detector_sees_the_cycle():
    """Fuzz seed 1832714987, minimised (single-agent tasks, complete graph, every option at its default but two):
    agent 2's withdrawn bid 97.16 on task 7 outbids the fresh bids of agents 0 and 3 (row 17), whose `bump` (†,
    acbba_outbid_time) re-times it past agent 2's own later record (79.94); row 11's trust_later keeps that lower,
    later record alive, so 0 and 3 bid again. The tables cycle with period 5 ticks while the bundles move through
    the same few states: the documented phantom of the bump (docs/decisions.md), recognised by ``livelocked`` (no
    new bundle state for the later half) and accepted by the fuzz. Either option at its default converges."""
    from taskalloc.evaluation import fuzz

    seed = 1832714987
    env = TaskAllocEnv(**LIVELOCK_1832714987)
    alloc = _drive(env, "acbba", seed)
    p = env.protocol
    assert p.graph.adjacency.sum() == 4 * 3
    assert not alloc.converged and p.round == 150 and p.livelocked
    verdict = fuzz.run_case((LIVELOCK_1832714987, "acbba", seed))
    assert verdict["converged"] is None and "livelock" in verdict["why"]
    for option in ({"acbba_row11": "update"}, {"acbba_outbid_time": "sender"}):
        env = TaskAllocEnv(**{**LIVELOCK_1832714987, **option})
        assert _drive(env, "acbba", seed).converged and not env.protocol.livelocked
