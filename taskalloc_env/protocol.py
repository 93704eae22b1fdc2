"""CBGA's two phases over all agents' local knowledge, driven one decision at a time (thesis ch. 3–5).

The environment calls ``bid`` and ``quit`` for the agents' decisions in the bundle phase (thesis Alg 5; Alg 9),
and ``end_round`` when the round is over. ``end_round`` is Phase 2 and the clean-up that precedes the next bundle
phase (thesis §3.2.3 and §5.2.2):

    T += 1; exchange (consensus.exchange, Alg 6); outbid release (thesis §2.2.4, Johnson eqs. (3.11)–(3.12));
    quit timers (Alg 9 l. 4–5); convergence: no table or bundle changed for D + 1 consecutive rounds (and no quit
    timer still running) and every live agent agreeing -- our stopping rule: the thesis gives none for detecting
    convergence (docs/decisions.md).

Pop-up tasks (``releases``, any consensus mode): a task is invisible, and cannot be bid on, before its release
round; a release counts as a change, and the run has not converged while a release is still to come.

Late joiners (``join_at``, any consensus mode; ours): an agent that joins at round r is absent before it -- not
``alive``, so it neither sends nor receives, and its empty table is the knowledge it starts with -- and present from
round r's exchange on, where it hears its neighbours. A join counts as a change, and the run has not converged while
a join is still to come. An agent that fails before its join round never joins.

Task quitting is part of the protocol when ``task_quitting`` is on (thesis §5.2.2, Alg 9): agent i may quit j
only if L_j > 1, i is a member, it never quit j (Q_i[j] = 0), the group is incomplete in its view and the
group-synchronised timer has run out (T − H_i[j] > δ, ``delta``). Which bids and quits to make is the policy's
choice.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.allocation import Allocation, Counters
from taskalloc_env.bidding import BidView, refresh_rows
from taskalloc_env.config import TaskAllocConfig, episode_bound
from taskalloc_env.consensus import Snapshot, Traffic, exchange, snapshot
from taskalloc_env.group_table import GroupTable
from taskalloc_env.kernels.quits import RELEASE_GUARDS, quittable, releasable
from taskalloc_env.knowledge import NEVER, LocalKnowledge
from taskalloc_env.network import CommGraph, dropout_schedule, join_schedule, make_network
from taskalloc_env.releases import release_ticks
from taskalloc_env.scenario import Scenario
from taskalloc_env.scoring import PathTable, Schedule, ScoringModel, TeamScore, team_score

NO_TIMER = int(np.iinfo(np.int64).max)     # ``_quittable`` without the timer condition: every H_i[j] is earlier


class ProtocolError(ValueError):
    """A decision the protocol does not allow (a bid that is not valid, a quit that is not allowed)."""


class Protocol:
    """All agents' tables plus the rules that change them."""

    def __init__(self, scenario: Scenario, cfg: TaskAllocConfig, rng: np.random.Generator | None = None) -> None:
        """``rng`` drives Poisson pop-up arrivals, the network's faults and random drop-outs (the env hands in one
        spawned from its seeded generator); when the config draws nothing (``stochastic``) nothing is drawn from it."""
        self.scenario = scenario
        self.cfg = cfg
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.release_tick = release_ticks(cfg, scenario.n_tasks, self.rng)
        self.model = ScoringModel.from_config(scenario, cfg, self.release_tick)
        self.graph = CommGraph(scenario.agent_pos, cfg.comm_range, cfg.edge_rule)
        self.equipment = self.model.equipment
        self.equipment_match = scenario.eligible()
        self.fillable = np.ones(scenario.n_tasks, dtype=bool)
        self.fillable[list(scenario.infeasible_tasks())] = False
        self.max_bundle = cfg.max_bundle or scenario.n_tasks
        self.max_rounds = episode_bound(cfg, scenario.n_tasks, scenario.n_agents, int(scenario.task_agents.max()),
                                        self.graph.diameter)
        self.silence_timeout = cfg.silence_timeout or 2 * (self.graph.diameter + 1)
        self.reset()

    def reset(self) -> None:
        s = self.scenario
        self.knowledge = LocalKnowledge.empty(s.n_agents, s.n_tasks, s.task_agents,
                                              know_everyone=not self.cfg.require_known_capacity)
        self.round = 0
        self.released = self.release_tick <= 0
        self.counters = Counters()
        self.network = make_network(self.graph, self.cfg, self.rng)
        self.joins = join_schedule(self.cfg, self.max_rounds)
        self.to_join = np.zeros(s.n_agents, dtype=bool)           # late joiners not present yet
        self.to_join[[a for agents in self.joins.values() for a in agents]] = True
        self.alive = ~self.to_join                                # present: joined and not failed
        self.live_graph = self.graph if self.alive.all() else self._graph_of_present()
        self.dropouts = dropout_schedule(self.cfg, s.n_agents, self.max_rounds, self.rng)
        self.last_heard = np.zeros((s.n_agents, s.n_agents), dtype=np.int64)   # latest send round i received from k
        self._snapshots: dict[int, Snapshot] = {}
        self.stable_rounds = 0
        self.converged = False
        self.unresolved: str | None = None      # why the stopping test passed without agreement (None: it did not)
        self._paths = PathTable.empty(s.n_agents, s.n_tasks)
        self._gain = np.zeros((s.n_agents, s.n_tasks))
        self._slot = np.full((s.n_agents, s.n_tasks), -1, dtype=np.int64)
        self._dirty = set(range(s.n_agents))
        self._view: BidView | None = None
        self._stale_rows: set[int] = set()
        self._quits: np.ndarray | None = None
        self._no_quits = np.zeros((s.n_agents, s.n_tasks), dtype=bool)
        self._no_quits.setflags(write=False)
        self._score: TeamScore | None = None
        self._last_groups = self.knowledge.groups.copy()
        self._last_bundles: list[list[int]] = [[] for _ in range(s.n_agents)]
        self._pending_quits: dict[tuple[int, int], None] = {}     # (quitter, task): quits no other agent saw yet
        self._bid_round = np.full((s.n_agents, s.n_tasks), NEVER, dtype=np.int64)   # round of i's latest bid on j
        self._released = np.zeros((s.n_agents, s.n_tasks), dtype=bool)             # i released j (release actions)

    # -- cached derived state ------------------------------------------------------------------------------------
    def _touch(self, agent: int | None = None) -> None:
        """Agent ``agent``'s tables changed (only its path and its row of the view need recomputing), or, without
        an agent, anyone's may have (the whole view)."""
        if agent is not None:
            self._dirty.add(agent)
            self._stale_rows.add(agent)
        else:
            self._view = None
            self._stale_rows.clear()
        self._quits = None
        self._score = None

    def _refresh_paths(self) -> None:
        """Re-time the changed paths and recompute their agents' marginal gains, in one batched call."""
        if not self._dirty:
            return
        agents = sorted(self._dirty)
        self.model.refresh(agents, [self.knowledge.paths[i] for i in agents], self._paths, self._gain, self._slot)
        self._dirty.clear()

    @property
    def schedules(self) -> list[Schedule]:
        """Every agent's path timing (computed on demand: the hot path keeps arrays only)."""
        return self.model.plan(range(self.scenario.n_agents), self.flown_paths, gains=False).schedules

    @property
    def flown_paths(self) -> list[list[int]]:
        """The paths that will be flown: a failed agent flies none."""
        return [path if alive else [] for path, alive in zip(self.knowledge.paths, self.alive)]

    def view(self) -> BidView:
        """The bidding situation of every agent (cached until the next change)."""
        if self._view is None or self._stale_rows:
            self._refresh_paths()
            self._view = refresh_rows(self._view, sorted(self._stale_rows), self.knowledge, self.scenario,
                                      self.equipment, self.equipment_match, self._gain, self._slot,
                                      prereq_mode=self.cfg.prereq_mode,
                                      require_known_capacity=self.cfg.require_known_capacity,
                                      max_bundle=self.max_bundle, fillable=self.fillable & self.released,
                                      bid_warping=self.cfg.bid_warping, outbid_ties=self.cfg.outbid_ties)
            self._stale_rows.clear()
        return self._view

    def score(self) -> TeamScore:
        """The team score of the allocation as it stands: each agent's own path (``scoring.team_score``)."""
        if self._score is None:
            self._refresh_paths()
            paths = self._paths
            if not self.alive.all():
                paths = dataclasses.replace(paths, members=paths.members & self.alive[:, None],
                                            reward=paths.reward * self.alive[:, None], cost=paths.cost * self.alive)
            self._score = team_score(self.model, paths, self.cfg.conflict_policy)
        return self._score

    # -- Phase 1 decisions ---------------------------------------------------------------------------------------
    def _quittable(self, counts: np.ndarray | None = None, assigned_before: int = NO_TIMER) -> np.ndarray:
        """(N, M) the timer-free quit conditions (thesis Alg 9 l. 2–3): L_j > 1, i holds j, i never quit j, and
        the group is incomplete in i's table; with ``assigned_before``, also H_i[j] < it. Quitting, the
        pending-quit test and the timer reset share it. Compiled (``kernels.quits.quittable``) when numba is
        there, else ``quittable_reference``.

        ``counts`` are the member counts n_j of every table; without them, the view's (valid in the bundle phase).
        """
        kn = self.knowledge
        counts = self.view().members if counts is None else counts
        if not kernels.COMPILED:
            return self.quittable_reference(counts, assigned_before)
        return quittable(counts, self.scenario.task_agents, kn.groups.own, kn.quit, kn.single, kn.assigned_at,
                         assigned_before)

    def quittable_reference(self, counts: np.ndarray, assigned_before: int = NO_TIMER) -> np.ndarray:
        """``_quittable`` in numpy (the reference of ``kernels.quits.quittable``)."""
        kn = self.knowledge
        allowed = counts < self.scenario.task_agents                 # a new (N, M) array, then narrowed in place
        allowed &= kn.groups.own > 0
        allowed &= ~kn.quit
        allowed &= ~kn.single
        allowed &= kn.assigned_at < assigned_before
        return allowed

    def quit_options(self) -> np.ndarray:
        """(N, M) quits the protocol allows now: quittable and the timer ran out, T − H_i[j] > δ (thesis Alg 9 l. 6,
        H_ij < T − δ; article eq. (10)); cached until the next change."""
        if self._quits is None:
            if not self.cfg.task_quitting:
                self._quits = self._no_quits
            else:
                self._quits = self._quittable(assigned_before=self.round - self.cfg.delta)
        return self._quits

    def bid(self, agent: int, task: int, view: BidView | None = None) -> float:
        """Agent ``agent`` bids c_ij on ``task`` at its best slot (Alg 5 lines 21–26); returns the bid.

        ``view`` may be a view computed earlier in the same step: a bid only changes the bidder's own row, so the
        other agents' rows stay valid.
        """
        view = view if view is not None else self.view()
        if not view.can_bid[agent, task]:
            raise ProtocolError(f"agent {agent} has no valid bid on task {task} ({self.explain_bid(agent, task)})")
        value = float(view.bid[agent, task])
        self.knowledge.add_to_bundle(agent, task, int(view.slot[agent, task]), value, self.round,
                                     displaced=int(view.displaced[agent, task]))
        self.counters.bids += 1
        self._bid_round[agent, task] = self.round
        self._pending_quits.pop((agent, task), None)        # re-bid before anyone saw the quit: it stays unseen
        self._touch(agent)
        return value

    def explain_bid(self, agent: int, task: int) -> str:
        """Why a bid is not valid: the eligibility filters and the outbid test of ``bidding.bid_view``."""
        v = self.view()
        reasons = []
        if v.in_bundle[agent, task]:
            reasons.append("the task is already in its bundle")
        if not v.equipment_match[agent, task]:
            reasons.append("its equipment does not match te_j")
        if not self.released[task]:
            reasons.append("the task has not been released yet (a pop-up task)")
        if not self.fillable[task]:
            reasons.append("no team of this scenario can complete it (too few capable agents)")
        if not v.prereqs_met[agent, task]:
            reasons.append(f"prerequisites are not met ({self.cfg.prereq_mode})")
        if v.gain[agent, task] <= 0:
            reasons.append("no feasible insertion with a positive marginal gain")
        if not v.outbid[agent, task]:
            reasons.append("it cannot outbid the current winners")
        if not reasons and not v.eligible[agent, task]:
            reasons.append("blocked by quit_block, require_known_capacity or max_bundle")
        return "; ".join(reasons)

    def quit(self, agent: int, task: int) -> list[int]:
        """Agent quits ``task`` (Alg 9 lines 6–8) and releases what follows it; returns the released tasks."""
        if not self.quit_options()[agent, task]:
            raise ProtocolError(f"agent {agent} may not quit task {task}: quitting needs task_quitting on, "
                                "L_j > 1, membership, an incomplete group, no earlier quit of this task, "
                                f"and T − H > delta = {self.cfg.delta}")
        kn = self.knowledge
        released = kn.release(agent, task, self.cfg.release_order)
        kn.quit[agent, task] = True
        kn.quit_blocked[agent, task] = self.cfg.quit_block == "until_joined"
        self.counters.quits += 1
        self._pending_quits[agent, task] = None
        self._touch(agent)
        return released

    def release_options(self) -> np.ndarray:
        """(N, M) releases the protocol allows now (``release_actions``): every task of the agent's own bundle, where
        an outbid release could start (thesis §2.2.4); with ``release_guard = exchange`` only the tasks it bid on in
        an earlier round (tick), whose bids an exchange has since set against the others'; with ``once`` only those
        it never released before; none with the option off."""
        if not self.cfg.release_actions:
            return self._no_quits
        if not kernels.COMPILED:
            return self.releasable_reference()
        allowed = np.empty(self._released.shape, dtype=bool)
        releasable(self.view().in_bundle, self._bid_round, self._released, self.round,
                   RELEASE_GUARDS[self.cfg.release_guard], allowed)
        return allowed

    def releasable_reference(self) -> np.ndarray:
        """``release_options`` in numpy (the reference of ``kernels.quits.releasable``)."""
        guard = self.cfg.release_guard
        if guard == "none":
            return self.view().in_bundle
        allowed = self.view().in_bundle & (self._bid_round < self.round)
        return allowed & ~self._released if guard == "once" else allowed

    def explain_release(self, agent: int, task: int) -> str:
        """Why ``release_options`` refuses ``agent`` a release of ``task``."""
        if task not in self.knowledge.bundles[agent]:
            return f"it is not in its bundle {self.knowledge.bundles[agent]}"
        if self._released[agent, task]:
            return "it released it once already and release_guard = once allows one release per agent and task"
        return (f"it bid on it in this round ({self.round}) and release_guard = {self.cfg.release_guard} allows a "
                "release only after the exchange that follows the bid")

    def release(self, agent: int, task: int) -> list[int]:
        """Agent gives ``task`` up of its own accord (``release_actions``; ours): ``task`` and every task after it
        leave its bundle and path and its own bids on them are zeroed, exactly as when it is outbid on ``task``
        (``LocalKnowledge.release`` with ``release_order``; thesis §2.2.4, Johnson (3.11)–(3.12)); Phase 2 spreads
        it. Returns the released tasks after ``task``."""
        if not self.cfg.release_actions:
            raise ProtocolError(f"agent {agent} may not release task {task}: release actions need "
                                "release_actions=True")
        if not self.release_options()[agent, task]:
            raise ProtocolError(f"agent {agent} may not release task {task}: {self.explain_release(agent, task)}")
        released = self.knowledge.release(agent, task, self.cfg.release_order)
        self._released[agent, task] = True
        self.counters.releases += 1
        self._touch(agent)
        return released

    # -- Phase 2 and clean-up ------------------------------------------------------------------------------------
    def end_round(self) -> Traffic:
        """Drop-outs, sending and delivery, silent agents, outbid release, quit timers and the convergence test."""
        kn = self.knowledge
        self.round += 1
        self._fail_agents(self.dropouts.get(self.round, ()))
        appeared = bool(self._join_agents(self.joins.get(self.round, ()))) | self._release_tasks()
        own_before = kn.groups.own > 0
        snap = snapshot(kn, self.round)
        self._snapshots[self.round] = snap
        # the groups before the merge (the snapshot's copy, never written): for the quit timers and the quit block
        before = snap.groups if self.cfg.task_quitting or kn.quit_blocked.any() else None
        sent = self.network.send(self.round, np.flatnonzero(self.alive), snap.data_items)
        deliveries = self.network.deliver(self.round, self.alive)
        listing = self._quitter_listed()
        traffic = exchange(kn, deliveries, self._snapshots, self.round, self.scenario.task_agents, self.equipment,
                           self.cfg.cbba_table)
        self._count_seen_quits(listing)
        np.maximum.at(self.last_heard, (deliveries.receiver, deliveries.sender), deliveries.sent)
        oldest = min(self.network.in_flight(), default=self.round)
        self._snapshots = {r: v for r, v in self._snapshots.items() if r >= oldest}
        self._forget_silent()
        c = self.counters
        c.conflicting_bids += int((own_before & (kn.groups.own <= 0) & self.alive[:, None]).sum())
        self._release_outbid()
        counts = kn.member_counts() if self.cfg.task_quitting else None
        joined = kn.groups.joined(before) if before is not None else None      # for the timers and the quit blocks
        if before is not None and self.cfg.task_quitting:
            self._reset_quit_timers(before, counts, joined)
        if before is not None and kn.quit_blocked.any():  # another agent joined a quit task: the quitter may return
            kn.quit_blocked &= ~joined
        c.rounds = self.round
        c.messages += traffic.messages
        c.informative_messages += traffic.informative
        c.data_items += traffic.data_items
        c.messages_sent += sent.sent
        c.max_agent_messages = int(self.network.sent_by.max(initial=0))
        c.messages_lost += sent.lost
        c.messages_delayed += sent.delayed
        c.data_items_sent += sent.data_items
        changed = appeared or kn.groups != self._last_groups or kn.bundles != self._last_bundles
        if changed:                         # the state from here on is final if nothing changes again
            c.rounds_to_agreement, c.messages_to_agreement = self.round, c.messages
        self._last_groups = kn.groups.copy()
        self._last_bundles = [list(b) for b in kn.bundles]
        self.stable_rounds = 0 if changed or self._quit_pending(counts) else self.stable_rounds + 1
        stable = (self.stable_rounds >= self.live_graph.diameter + 1 and bool(self.released.all())
                  and not self.joins_ahead)
        if stable and not self._settled():
            self.converged = False
            self.unresolved = ("no table changed for D + 1 rounds, but an agent has not received a message its "
                               "neighbour sent after the last change (lost or delayed messages), or still counts "
                               "on a failed agent")
        else:
            self._decide(stable, "no table changed for D + 1 rounds, but the agents' tables disagree")
        if (not self.converged and self.unresolved is None and self.round >= self.max_rounds
                and not (self.network.perfect and not self.dropouts)):
            self.unresolved = ("the round bound T_max came while the tables were still changing (lost or delayed "
                               "messages, or failed agents)")
        self._touch()
        return traffic

    def _quitter_listed(self) -> np.ndarray | None:
        """(N, Q) whether each agent's table lists the quitter on each pending quit's task (None: no pending quit);
        taken just before a merge, for ``_count_seen_quits``."""
        if not self._pending_quits:
            return None
        quitter, task = np.array(list(self._pending_quits)).T
        return self.knowledge.groups.listing(quitter, task)

    def _count_seen_quits(self, listing: np.ndarray | None) -> None:
        """``quits_seen``: a pending quit (thesis Alg 9 l. 7, X_i[i][j] = 0) is seen when a merge (Alg 6; Johnson
        §3.3's rule for a sender's own entry) drops the quitter from the task's group in another agent's table that
        listed it. It is counted once; a quit the quitter re-bid before that is never seen (under
        ``quit_block=none`` the quitter re-bids in the same bundle phase, so nobody learns of the quit)."""
        if listing is None:
            return
        keys = list(self._pending_quits)
        quitter, task = np.array(keys).T
        seen = (listing & ~self.knowledge.groups.listing(quitter, task)).any(axis=0)
        for q in np.flatnonzero(seen):
            del self._pending_quits[keys[q]]
        self.counters.quits_seen += int(seen.sum())

    def _decide(self, stopped: bool, disagreement: str) -> None:
        """Converged: the stopping test passed and the agents agree (thesis §2.2.3: the two phases alternate "until
        assignments and consensus are achieved"); a stopping test passed without agreement is not convergence, and
        ``unresolved`` says why (under lost or delayed messages; docs/decisions.md "Convergence means agreement")."""
        agreed = stopped and self.agreement()
        self.converged = agreed
        self.unresolved = disagreement if stopped and not agreed else None

    @property
    def halted(self) -> bool:
        """Nothing can change any more and the agents disagree (synchronous agents keep broadcasting: never)."""
        return False

    @property
    def globally_converged(self) -> bool:
        """The synchronous stop is global (no table changed for D + 1 rounds); see ``AsyncProtocol`` for local."""
        return self.converged

    @property
    def locally_converged(self) -> bool:
        return self.converged

    def _release_tasks(self) -> bool:
        """Pop-up tasks due this round become visible to every agent (Johnson §4.1.1: task creation "enters through
        this channel", the listener; our choice: all agents learn of it at once). Returns whether any appeared."""
        if self.released.all():
            return False
        due = ~self.released & (self.release_tick <= self.round)
        self.released |= due
        return bool(due.any())

    def _settled(self) -> bool:
        """Every live agent has received a message each live neighbour sent after the last change (a delayed message
        sent before it carries the old table, so its send round counts, not its arrival), no older message is still
        travelling, and no live agent still counts on a failed one (always true on perfect links, where everyone
        hears everyone in every round and nobody fails)."""
        if self.network.perfect and not self.dropouts:
            return True
        last_change = self.counters.rounds_to_agreement
        links = self.live_graph.adjacency
        heard = np.all((self.last_heard > last_change) | ~links)
        counts_on_failed = bool((self.knowledge.groups.listed()[self.alive][:, ~self.alive]).any())
        return bool(heard) and not counts_on_failed and not np.any(self.network.in_flight() <= last_change)

    def _fail_agents(self, agents: tuple[int, ...]) -> None:
        """Agents that fail this round stop sending and receiving; their paths are no longer flown. A late joiner
        that fails before it joins never joins."""
        if not agents:
            return
        self.alive[list(agents)] = False
        self.to_join[list(agents)] = False
        self.live_graph = self._graph_of_present()
        self.counters.dropped_agents += len(agents)
        self._touch()

    def _join_agents(self, agents: tuple[int, ...]) -> list[int]:
        """Late joiners due this round enter: from now on they send and receive (``join_at``). Returns them."""
        joining = [a for a in agents if self.to_join[a]]
        if joining:
            self.to_join[joining] = False
            self.alive[joining] = True
            self.live_graph = self._graph_of_present()
            self._touch()
        return joining

    @property
    def joins_ahead(self) -> bool:
        """A late joiner is still to come."""
        return bool(self.to_join.any())

    def _graph_of_present(self) -> CommGraph:
        """The links between the agents present now (joined and not failed)."""
        return CommGraph(self.scenario.agent_pos, self.cfg.comm_range, self.cfg.edge_rule, self.alive)

    def _forget_silent(self) -> None:
        """A live agent that has heard nothing from or about k for ``silence_timeout`` rounds (its timestamp s_i[k],
        relayed stamps included) takes k for lost and clears k's bids from its table, so k's tasks can be
        re-assigned (Johnson §3.5: a synchronous scheme "stuck waiting for a message that was not going to arrive"
        never converges; the timeout is our rule, ``silence_timeout``)."""
        if self.network.perfect and not self.dropouts:
            return
        kn = self.knowledge
        silent = (self.round - kn.timestamps > self.silence_timeout) & self.alive[:, None]
        np.fill_diagonal(silent, False)
        holders, gone = np.nonzero(silent & kn.groups.listed())
        for i, k in zip(holders, gone):
            for j in np.flatnonzero((kn.groups.members[i] == k).any(axis=1)):
                kn.set_bid(int(i), int(k), int(j), 0.0)
            self.counters.silent_releases += 1

    def _release_outbid(self) -> None:
        """Release the first lost bundle task and everything after it (thesis §2.2.4; Johnson (3.11)–(3.12))."""
        kn = self.knowledge
        sizes = np.fromiter(map(len, kn.bundles), dtype=np.int64, count=len(kn.bundles))
        holders = np.repeat(np.arange(len(sizes)), sizes)
        tasks = np.fromiter(itertools.chain.from_iterable(kn.bundles), dtype=np.int64, count=len(holders))
        for i in sorted(set(holders[kn.groups.own[holders, tasks] <= 0].tolist())):   # agents that lost a task
            sequence = kn.bundles[i] if self.cfg.release_order == "bundle" else kn.paths[i]
            row = kn.groups.own[i].tolist()
            kn.release(i, next(j for j in sequence if row[j] <= 0), self.cfg.release_order)
            self._dirty.add(i)

    def _reset_quit_timers(self, before: GroupTable, counts: np.ndarray | None = None,
                           joined: np.ndarray | None = None) -> None:
        """H_i[j] = T when column j of an incomplete held group changed (Alg 9 lines 4–5, ``reset_on``); ``before``
        are the groups before the exchange, ``counts`` the tables' member counts after it, ``joined`` the columns a
        member joined since ``before`` if the caller has them already."""
        kn = self.knowledge
        if self.cfg.reset_on == "additions":
            updated = joined if joined is not None else kn.groups.joined(before)
        else:
            updated = kn.groups.changed(before)
        kn.assigned_at[updated & self._quittable(counts)] = self.round

    def _quit_pending(self, counts: np.ndarray | None) -> bool:
        """A quittable task whose timer had not run out in the last bundle phase: a quit may still follow."""
        if not self.cfg.task_quitting:
            return False
        return bool(np.any(self._quittable(counts) & (self.round - 1 - self.knowledge.assigned_at <= self.cfg.delta)))

    def allocation(self) -> Allocation:
        """The allocation as it stands: flown paths with start times, groups, validity, score, the run's figures."""
        paths = self.flown_paths
        team = self.score()             # the cached team score over the path table the bids keep timed
        return Allocation.scored(self.model, paths, [self._paths.start[i, path] for i, path in enumerate(paths)], team,
                                 counters=dataclasses.replace(self.counters), converged=self.converged,
                                 agreement=self.agreement(), globally_converged=self.globally_converged,
                                 locally_converged=self.locally_converged)

    # -- agreement -------------------------------------------------------------------------------------------------
    def agreement(self) -> bool:
        """Every pair of live agents in one connected component holds the same table (thesis §3.2.3's consensus)."""
        groups = self.knowledge.groups
        comp = self.live_graph.component
        live = np.flatnonzero(self.alive)
        return groups.same_table(live, comp[live])
