"""ACBBA: the asynchronous consensus on a global tick clock (Johnson §4.1, Fig. 4-1), one env step per tick.

Each agent runs two modules (Johnson §4.1.1, extraction lines 758–773):

* the **listener** processes the messages that reach the agent, one at a time in arrival order, each taking the
  agent's own time per message (``message_ticks``, a per-agent uniform draw, fractions of a tick allowed; 0: every
  message the tick it arrives); a listener slower than its arrivals builds a backlog of stale messages. Relevant
  information (``async_consensus.listen``) goes to the two buffers of Fig. 4-1: the agent's *outgoing buffer* (task
  ids to rebroadcast) and its *bundle-building buffer*;
* the **bundle builder** is throttled: it runs only when its buffer holds news ("spawned on an iteration time but
  with the caveat that it doesn't run unless new information is available", line 769). A build takes the buffer
  (news arriving meanwhile fills it again: the second of Fig. 4-1's "two buffers to avoid unexpected message
  overriding", so another build follows) and becomes *ready* after the agent's own ``build_ticks``. A ready agent
  first releases every task it was outbid on and everything after it (Module 1, line 773), then decides one step at a
  time: bid (stamped with the tick, line 812), quit, or pass. A pass completes the build and flushes the outgoing
  buffer as one broadcast ("outgoing buffers manage rebroadcasting of information, triggered by the completion of the
  BundleBuilder thread", line 763). Agents that are not ready may only pass.

Released bundle tasks that the agent still held go out as an empty bid with the current time (the only empty-bid
form Johnson defines, Table 4.1's rebroadcast*, line 866; our reading of "any changes to this agent's bundle are
noted and sent to the same rebroadcast buffer", line 769).

Messages travel on the same seam as the synchronous protocol: ``Message`` payloads are kept by (sender, sent tick)
here, and ``network.Network`` decides which neighbour receives each and when (perfect, lossy, bursty, delayed links;
range; drop-outs). A message sent at tick T arrives at T + 1 + its delay.

Events entering the listener from outside (line 765): a pop-up task's release (every live agent learns of it at
once, our choice) and, ``silence_timeout`` ticks after an agent fails, a notice to every live agent, which clears the
failed agent's bids as empty bids with the current time (our rule; in a protocol without periodic messages silence
carries no information).

Lost messages are never resent by Johnson's rules, so on a lossy network an agent that has heard nothing relevant for
``separation_time`` ticks first announces its whole state (every task it has a record of) and repeats this
``confirmations`` times before it counts as converged; a receiver that agrees sinks every record (rows 5, 13, 22,
32 with equal times), one that does not answers, and the exchange resumes (our rule, not in the sources; off on
loss-free networks, docs/decisions.md).

Convergence (Johnson §4.1.3): *global* when the network is quiet — no message travelling or queued, every buffer
empty, no build running, no event still to come ("Once the network goes quiet in this configuration we say that the
network has converged", line 921); *local* for an agent after more than ``separation_time`` ticks of its separation
clock (lines 941–943). What restarts the clock is ``local_convergence``: ``bundle`` (default), a change of the agent's
own bundle (a bid, a quit, a release) or of the record of a task it holds (outbid, its bid disputed), and the agent
declares only with its builder idle and no news waiting, so that agents which keep their bundles "can decide that
they have reached self convergence ... even though others are still actively engaging in a consensus phase" (line
939); ``table``, any relevant information (every table action but the sink, a release, a failure notice: "any
information that affects the local agents' ACBBA state", line 941, read literally). Builder wake-ups and
rebroadcasts are Table 4.1's under both. The episode terminates at global convergence, or at local convergence of
every live agent (``termination``; ``auto``: local with pop-up tasks). T_max (``episode_bound``) truncates it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from taskalloc_env.async_consensus import Message, Times, compose, listen
from taskalloc_env.bidding import BidView
from taskalloc_env.cbba_table import NONE
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.protocol import Protocol
from taskalloc_env.scenario import Scenario
from taskalloc_env.stamps import NEVER, stamp

IDLE = -1


class AsyncProtocol(Protocol):
    """All agents' tables, times and buffers, advanced one tick at a time (``round`` is the tick)."""

    def __init__(self, scenario: Scenario, cfg: TaskAllocConfig, rng: np.random.Generator | None = None) -> None:
        super().__init__(scenario, cfg, rng)
        hop = 2 + cfg.max_delay + cfg.build_ticks[1] + int(np.ceil(scenario.n_agents * cfg.message_ticks[1]))
        self.silence_timeout = cfg.silence_timeout or 2 * (self.graph.diameter + 1) * hop

    def reset(self) -> None:
        """Tick 0: per-agent processing times drawn, empty times and buffers; the initial tasks wake every builder."""
        super().reset()
        n, m = self.scenario.n_agents, self.scenario.n_tasks
        lo, hi = self.cfg.message_ticks
        self.message_ticks = self.rng.uniform(lo, hi, n) if hi > lo else np.full(n, lo)
        lo, hi = self.cfg.build_ticks
        self.build_ticks = self.rng.integers(lo, hi + 1, n) if hi > lo else np.full(n, lo, dtype=np.int64)
        self.times = Times.empty(n, m)
        self.outgoing = np.zeros((n, m), dtype=bool)          # the rebroadcast buffer: task ids
        self.inbox = np.zeros(n, dtype=bool)                  # the bundle-building buffer holds news
        self.ready_at = np.full(n, IDLE, dtype=np.int64)      # the tick the running build becomes ready
        self.queue = np.zeros((4, 0), dtype=np.int64)         # incoming: receiver, sender, sent, arrival
        self.listener_free = np.zeros(n)                      # the time each listener finishes its last message
        self.payloads: dict[tuple[int, int], Message] = {}
        self.notices: dict[int, tuple[int, ...]] = {}         # tick → failed agents announced then
        self.last_relevant = np.zeros(n, dtype=np.int64)
        self.quiet_since = np.zeros(n, dtype=np.int64)        # last relevant news or own confirmation
        self.settled_since = np.zeros(n, dtype=np.int64)      # last change of the own bundle or of a held record
        self.confirmed = np.zeros(n, dtype=np.int64)          # confirmations sent since the last relevant news
        self.confirmed_at = np.zeros(n, dtype=np.int64)       # the tick of the last confirmation
        self.declared_at = np.full(n, -1, dtype=np.int64)     # the tick the current declaration began, −1: none
        self.broadcast_log: list[tuple[int, int, int]] = []   # (tick, sender, data items) of every broadcast
        self.quiet = False
        self.local = False
        self.bundle_tick = 0                                  # the last tick the bundles reached a new state
        self._bundles_seen: list[list[int]] = []
        self._bundle_states: set[tuple[tuple[int, ...], ...]] = set()   # every state of the bundles so far
        self.inbox[:] = True                                  # the initial tasks enter every listener at tick 0
        self._schedule_builds()

    # -- the agents' decisions -------------------------------------------------------------------------------------
    @property
    def ready(self) -> np.ndarray:
        """(N,) agents whose build is ready: they may bid, quit or pass this tick."""
        return (self.ready_at != IDLE) & (self.ready_at <= self.round) & self.alive

    def bid(self, agent: int, task: int, view: BidView | None = None) -> float:
        """Protocol.bid, stamped with the current tick (line 812) and queued for rebroadcast."""
        value = super().bid(agent, task, view)
        if self.knowledge.single[task]:
            self.times.task[agent, task] = stamp(self.round, agent)
        else:
            self.times.entry[agent, agent, task] = stamp(self.round, agent)
        self.outgoing[agent, task] = True
        self._settle(agent)
        return value

    def quit(self, agent: int, task: int) -> list[int]:
        """Protocol.quit; the withdrawn entries go out with the current time."""
        return self._giving_up(agent, task, super().quit)

    def release(self, agent: int, task: int) -> list[int]:
        """Protocol.release; the withdrawn entries go out with the current time, as a quit's do."""
        return self._giving_up(agent, task, super().release)

    def _giving_up(self, agent: int, task: int, give_up: Callable[[int, int], list[int]]) -> list[int]:
        """``give_up(agent, task)`` (the synchronous quit or release), then send what it withdrew, stamped now."""
        held = self.knowledge.own_bids()[agent] > 0
        released = give_up(agent, task)
        self._withdrawn(agent, [task, *released], held)
        self._settle(agent)
        return released

    def finish(self, agent: int) -> None:
        """The agent passed: its build is complete; its outgoing buffer goes out as one broadcast (line 763)."""
        self.ready_at[agent] = IDLE
        tasks = self.outgoing[agent]
        if not tasks.any():
            return
        message = compose(self.knowledge, self.times, agent, self.round, tasks)
        self.payloads[(agent, self.round)] = message
        items = np.zeros(self.scenario.n_agents, dtype=np.int64)
        items[agent] = message.data_items
        sent = self.network.send(self.round, np.array([agent]), items)
        self.outgoing[agent] = False
        self.broadcast_log.append((self.round, agent, message.data_items))
        c = self.counters
        c.broadcasts += 1
        c.messages_sent += sent.sent
        c.max_agent_messages = max(c.max_agent_messages, int(self.network.sent_by[agent]))
        c.messages_lost += sent.lost
        c.messages_delayed += sent.delayed
        c.data_items_sent += sent.data_items

    def _withdrawn(self, agent: int, tasks: list[int], held: np.ndarray) -> None:
        """Bundle tasks ``agent`` gave up, stamped now: an empty bid for a single-agent task it still ``held`` (one it
        was outbid on keeps the new winner's record), a withdrawn entry for every multi-agent task."""
        single = self.knowledge.single
        for j in tasks:
            if single[j] and held[j]:
                self.times.task[agent, j] = stamp(self.round, agent)
            elif not single[j]:
                self.times.entry[agent, agent, j] = stamp(self.round, agent)
            else:
                continue
            self.outgoing[agent, j] = True

    # -- one tick --------------------------------------------------------------------------------------------------
    def advance(self) -> None:
        """The next tick: failures and releases, deliveries, the listeners, builds, releases of outbid tasks."""
        kn = self.knowledge
        c = self.counters
        self.round += 1
        now = self.round
        before = kn.groups.copy()
        own_before = kn.own_bids() > 0
        bundles_before = [list(b) for b in kn.bundles]
        self._fail(self.dropouts.get(now, ()))
        self._welcome(self._join_agents(self.joins.get(now, ())))
        self._notice(self.notices.pop(now, ()))
        if self._release_tasks():
            self._news(np.flatnonzero(self.alive))
        deliveries = self.network.deliver(now, self.alive)
        if len(deliveries):
            arrived = np.stack([deliveries.receiver, deliveries.sender, deliveries.sent,
                                np.full(len(deliveries), now)])
            self.queue = np.concatenate([self.queue, arrived], axis=1)
        listing = self._quitter_listed()
        self._listen(now)
        self._count_seen_quits(listing)
        kn.timestamps[np.arange(len(self.alive)), np.arange(len(self.alive))] = now
        c.conflicting_bids += int((own_before & (kn.own_bids() <= 0) & self.alive[:, None]).sum())
        if self.cfg.task_quitting:
            self._reset_quit_timers(before)
            self.inbox |= (self._quittable() & (now - kn.assigned_at == self.cfg.delta + 1)).any(axis=1)
        if kn.quit_blocked.any():
            kn.quit_blocked &= ~kn.groups.joined(before)
        self._confirm()
        self._schedule_builds()
        self._release_lost()
        keep = self.network.travelling() | set(zip(self.queue[1].tolist(), self.queue[2].tolist()))
        self.payloads = {key: msg for key, msg in self.payloads.items() if key in keep}
        c.rounds = now
        if kn.groups != before or kn.bundles != bundles_before:
            c.rounds_to_agreement, c.messages_to_agreement = now, c.messages
        if kn.bundles != self._bundles_seen:
            self._bundles_seen = [list(b) for b in kn.bundles]
            state = tuple(tuple(b) for b in kn.bundles)
            if state not in self._bundle_states:      # a cycle through known states is no progress (livelock)
                self._bundle_states.add(state)
                self.bundle_tick = now
        self._check_convergence()
        self._touch()

    def _listen(self, now: int) -> None:
        """Process every queued message whose processing completes by ``now``, in arrival order per receiver."""
        if not self.queue.shape[1]:
            return
        receiver, sender, sent, arrival = self.queue
        order = np.lexsort((sender, sent, arrival, receiver))
        self.queue = self.queue[:, order]
        receiver, sender, sent, arrival = self.queue
        done = np.zeros(len(receiver), dtype=bool)
        for r in np.unique(receiver):
            rows = np.flatnonzero(receiver == r)
            pace = self.message_ticks[r]
            if pace == 0:
                done[rows] = True
                continue
            for q in rows:
                finish = max(self.listener_free[r], arrival[q]) + pace
                if finish > now:
                    break
                self.listener_free[r] = finish
                done[q] = True
        picked = self.queue[:, done]
        self.queue = self.queue[:, ~done]
        receiver, sender, sent, _ = picked
        first = np.r_[0, np.flatnonzero(np.diff(receiver)) + 1] if len(receiver) else np.zeros(0, dtype=np.int64)
        rank = np.arange(len(receiver)) - np.repeat(first, np.diff(np.r_[first, len(receiver)]))
        for position in range(int(rank.max(initial=-1)) + 1):
            at = np.flatnonzero(rank == position)
            live = at[self.alive[receiver[at]]]
            if not live.size:
                continue
            receivers = receiver[live]
            messages = [self.payloads[(int(k), int(t))] for k, t in zip(sender[live], sent[live])]
            held = self.knowledge.own_bids()[receivers] > 0
            relevant = listen(self.knowledge, self.times, receivers, messages, now, self.cfg,
                              self.scenario.task_agents, self.equipment)
            self.outgoing[receivers] |= relevant
            news = relevant.any(axis=1)
            heard = receivers[news]
            gap = now - self.last_relevant[heard]
            self.counters.separation_ticks = max(self.counters.separation_ticks, int(gap.max(initial=0)))
            self._news(heard)
            self._settle(receivers[(relevant & held).any(axis=1)])
            self.counters.messages += len(live)
            self.counters.informative_messages += int(news.sum())
            self.counters.data_items += sum(msg.data_items for msg in messages)

    def _news(self, agents: np.ndarray) -> None:
        """Relevant information reached ``agents`` now: their builders wake, their quiet periods restart."""
        self.inbox[agents] = True
        self.last_relevant[agents] = self.round
        self.quiet_since[agents] = self.round
        self.confirmed[agents] = 0

    def _settle(self, agents: np.ndarray | int) -> None:
        """The own state of ``agents`` changed now: their bundle, or the record of a task they hold (the clock of
        ``local_convergence = bundle``)."""
        self.settled_since[agents] = self.round

    def _confirm(self) -> None:
        """Agents quiet for ``separation_time`` ticks that still owe a confirmation announce every record they hold."""
        due = (self.alive & (self.confirmed < self.cfg.confirmation_count) & (self.ready_at == IDLE)
               & (self.round - self.quiet_since > self.cfg.separation_time))
        if not due.any():
            return
        self.outgoing[due] |= self._held()[due]
        self.inbox[due] = True
        self.confirmed[due] += 1
        self.quiet_since[due] = self.round
        self.confirmed_at[due] = self.round

    def _held(self) -> np.ndarray:
        """(N, M) the released tasks each agent has a record of (what a full announcement carries)."""
        kn = self.knowledge
        held = np.where(kn.single[None, :], self.times.task != NEVER, (self.times.entry != NEVER).any(axis=1))
        return held & self.released[None, :]

    def _welcome(self, joined: list[int]) -> None:
        """Late joiners enter knowing nothing, and ACBBA rebroadcasts only changes, so each present neighbour of a
        joiner announces every record it holds (as a confirmation does) and the joiners' builders wake on the tasks
        they know (our rule: Johnson §2.2 lets agents enter the network but gives no rule for it)."""
        if not joined:
            return
        neighbours = self.live_graph.adjacency[joined].any(axis=0)
        neighbours[joined] = False
        self.outgoing[neighbours] |= self._held()[neighbours]
        self._news(np.union1d(np.flatnonzero(neighbours), joined))

    def _schedule_builds(self) -> None:
        """An idle builder with news starts a build; it takes its buffer and is ready ``build_ticks`` later."""
        start = (self.ready_at == IDLE) & self.inbox & self.alive
        self.ready_at[start] = self.round + self.build_ticks[start]
        self.inbox[start] = False

    def _release_lost(self) -> None:
        """Ready agents release the first task they were outbid on and every task after it (Module 1, line 773).
        The later tasks they held go out as empty bids. On a single-agent task the new winner's record of the lost
        task stays; on a multi-agent task the agent withdraws its displaced entry with the current time, so that no
        agent that still lists it re-admits it (the member decides its own membership; our rule)."""
        kn = self.knowledge
        own = kn.own_bids()
        for i in np.flatnonzero(self.ready):
            bundle = kn.bundles[i]
            sequence = bundle if self.cfg.release_order == "bundle" else kn.paths[i]
            lost = next((j for j in sequence if own[i, j] <= 0), None)
            if lost is None:
                continue
            released = kn.release(i, lost, self.cfg.release_order)
            self._withdrawn(i, [lost, *released], own[i] > 0)
            self._settle(i)
            self._dirty.add(i)

    # -- failures --------------------------------------------------------------------------------------------------
    def _fail(self, agents: tuple[int, ...]) -> None:
        """Failed agents stop; every live agent is told ``silence_timeout`` ticks later."""
        if not agents:
            return
        self._fail_agents(agents)
        dead = list(agents)
        self.inbox[dead] = False
        self.outgoing[dead] = False
        self.ready_at[dead] = IDLE
        self.queue = self.queue[:, self.alive[self.queue[0]]]
        due = self.round + self.silence_timeout
        self.notices[due] = (*self.notices.get(due, ()), *agents)

    def _notice(self, failed: tuple[int, ...]) -> None:
        """Every live agent drops the failed agents' bids: empty bids (entries) with the current time."""
        kn = self.knowledge
        for k in failed:
            for i in np.flatnonzero(self.alive):
                listed = (kn.groups.members[i] == k).any(axis=1)
                single = np.flatnonzero(kn.single & listed)
                entries = np.flatnonzero(~kn.single & listed)
                if not (single.size or entries.size):
                    continue
                if (kn.own_bids()[i, entries] > 0).any():      # a group it belongs to lost a member
                    self._settle(i)
                kn.set_single_columns(np.full(single.size, i), single, np.full(single.size, NONE),
                                      np.zeros(single.size))
                for j in entries:
                    kn.set_bid(int(i), k, int(j), 0.0)
                self.times.task[i, single] = stamp(self.round, i)
                self.times.entry[i, k, entries] = stamp(self.round, i)
                self.outgoing[i, single] = True
                self.outgoing[i, entries] = True
                self._news(np.array([i]))
                self.counters.silent_releases += 1

    # -- convergence -----------------------------------------------------------------------------------------------
    def _events_ahead(self) -> bool:
        """A release, a failure, a join, a failure notice or a quit timer is still to come."""
        timers = self.cfg.task_quitting and bool(np.any(self._quittable()
                                                        & (self.round - self.knowledge.assigned_at <= self.cfg.delta)))
        future = any(tick > self.round for tick in self.dropouts)
        owed = bool((self.confirmed[self.alive] < self.cfg.confirmation_count).any())
        return not self.released.all() or future or self.joins_ahead or bool(self.notices) or timers or owed

    def _check_convergence(self) -> None:
        """Global: quiet network and nothing to come; local: every live agent past its separation time."""
        live = self.alive
        ahead = self._events_ahead()
        quiet = (not ahead and not len(self.network.in_flight()) and not self.queue.shape[1]
                 and not self.outgoing[live].any() and not self.inbox[live].any()
                 and not (self.ready_at[live] != IDLE).any())
        declared = self.agents_locally_converged
        self.declared_at = np.where(declared, np.where(self.declared_at >= 0, self.declared_at, self.round), -1)
        local = not ahead and bool(np.all(declared[live]))
        c = self.counters
        if local and not self.local:
            c.local_tick = self.round
        if quiet and not self.quiet:
            c.quiet_tick = self.round
            if not (local or self.local):   # nothing relevant can come: each agent declares itself converged later
                c.local_tick = int(self._clock()[live].max(initial=0)) + self.cfg.separation_time + 1
        self.quiet, self.local = self.quiet or quiet, self.local or local
        if self.quiet:
            self._decide(True, "the network went quiet with the agents' tables disagreeing: a lost message is never "
                               "resent (Johnson §4.1.3), so nothing can change any more")
            self.converged = self.converged and (self.local or not self.cfg.local_termination)
        else:
            self._decide(self.local and self.cfg.local_termination,
                         "every agent declared local convergence, but the agents' tables disagree")

    def _clock(self) -> np.ndarray:
        """(N,) the tick each agent's separation clock last restarted (``local_convergence``): its last relevant news
        or confirmation (``table``), or the last change of its own state or its last confirmation (``bundle``)."""
        if self.cfg.local_convergence == "table":
            return self.quiet_since
        return np.maximum(self.settled_since, self.confirmed_at)

    @property
    def agents_locally_converged(self) -> np.ndarray:
        """(N,) each live agent's own declaration (Johnson §4.1.3, separation time, l. 939–943): its clock
        (``_clock``) ran for more than ``separation_time`` ticks, after its confirmations (our rule); with
        ``local_convergence = bundle`` also its builder idle with no news waiting ("when it is clear that they will
        not win it", l. 939). It knows nothing of future events, so it may declare before a pop-up task and
        withdraw the declaration when one arrives (every builder wakes)."""
        declared = (self.alive & (self.round - self._clock() > self.cfg.separation_time)
                    & (self.confirmed >= self.cfg.confirmation_count))
        if self.cfg.local_convergence == "bundle":
            declared &= (self.ready_at == IDLE) & ~self.inbox
        return declared

    @property
    def local_ticks(self) -> np.ndarray:
        """(N,) the tick each agent's current declaration of local convergence began, −1 while it has none."""
        return self.declared_at.copy()

    @property
    def livelocked(self) -> bool:
        """Not converged, and for the later half of the run agents kept broadcasting while the bundles reached no
        state they had not held before (unchanged, or cycling through known states): the signature of the row-15
        loop and of stale bids refreshed against their owner's withdrawal, whose bidders keep bidding and losing
        (note §8.22; docs/decisions.md)."""
        talking = any(tick > self.bundle_tick for tick, _, _ in self.broadcast_log)
        return not self.converged and talking and self.round - self.bundle_tick > self.round // 2

    @property
    def halted(self) -> bool:
        """The network is quiet and nothing is to come, yet the agents disagree: nothing can change any more."""
        return self.quiet and self.unresolved is not None

    @property
    def globally_converged(self) -> bool:
        """The network went quiet (Johnson §4.1.3, l. 921) with every agent holding the same table."""
        return self.quiet and self.unresolved is None

    @property
    def locally_converged(self) -> bool:
        return self.local or self.quiet
