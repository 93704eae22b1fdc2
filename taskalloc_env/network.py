"""Who hears whom, and when: the communication graph and the ``Network`` that delivers messages.

A round of consensus (thesis §3.2.3, Phase 2) has two halves: *sending* — every live agent broadcasts a snapshot of its
own table to its neighbours (``consensus.snapshot``; under ``consensus="acbba"`` an agent broadcasts when its bundle
build completes, ``async_protocol``) — and *delivery*, decided here: which receiver gets which
message, and in which round. The consensus rules (``consensus.exchange``) only see the messages that arrive, so they
never need to know how the network behaves. ``Network`` composes the graph with a loss model and a delay:

* ``perfect`` links (the default): every message arrives in the round it is sent;
* ``message_loss`` p: each message is lost independently with probability p; ``loss_model="gilbert_elliott"``:
  each link is a two-state channel (Gilbert 1960, Elliott 1963) that enters the bad state with probability
  ``burst_enter`` and leaves it with ``burst_leave`` per round, losing messages with p in the good state and
  ``burst_loss`` in the bad one, so losses come in bursts; ``"gilbert_elliott_rho"``: the same channel set by its
  stationary loss rate (``message_loss``) and lag-1 correlation ``burst_correlation``; ``"rayleigh"``: a message
  arrives with a probability falling with the distance between sender and receiver (``faults`` derives both);
* ``max_delay`` d: each message arrives after a uniform random number of rounds in 0..d, so rounds overlap and a
  receiver may process an old message after a newer one (the timestamps of thesis (2.4) sort that out).

All randomness comes from one ``numpy.random.Generator`` handed in by the environment (spawned from its seeded
generator), so an episode with faults is exactly reproducible from its seed.

The graph g_ik (thesis §2.2.4, §3.2.1): fully connected, or range-limited between start positions.

The thesis's edge rule is overlapping range circles (thesis §4.3: "any overlapping circles show the available
communication channels", Figs 4.2–4.5) but it does not state the circles' radius, so that is our choice:
``edge_rule="dist"`` (radius r/2) links agents at distance ≤ r; ``"circles_overlap"`` (radius r) at distance ≤ 2r.
``comm_range=None`` is global broadcast. Messages are forwarded whole, so bids travel multi-hop; D (the diameter,
the largest over connected components) bounds how many rounds that takes (a bid needs up to D rounds to cross the
network, thesis §4.3).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components, shortest_path

from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.errors import ConfigError
from taskalloc_env.faults import (
    LOSS_MODELS,
    GilbertElliott,
    IndependentLoss,
    LossModel,
    NoLoss,
    RayleighFading,
    StationaryGilbertElliott,
)

__all__ = ["GilbertElliott", "IndependentLoss", "LossModel", "NoLoss", "RayleighFading",   # the loss models live in
           "StationaryGilbertElliott"]                                                    # faults


class CommGraph:
    """Symmetric graph without self-loops: its links, degrees, hop distances, diameter and components."""

    def __init__(self, positions: np.ndarray, comm_range: float | None = None, edge_rule: str = "dist",
                 alive: np.ndarray | None = None) -> None:
        """Links between ``positions`` (kept: distance-dependent loss models read them); agents not ``alive``
        (failed) have none."""
        n = len(positions)
        self.positions = positions
        if comm_range is None:
            adjacency = ~np.eye(n, dtype=bool)
        else:
            reach = comm_range if edge_rule == "dist" else 2.0 * comm_range
            dist = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=2)
            adjacency = (dist <= reach) & ~np.eye(n, dtype=bool)
        if alive is not None:
            adjacency &= alive[:, None] & alive[None, :]
        self.adjacency = adjacency
        self.adjacency.setflags(write=False)
        self.degree = adjacency.sum(axis=1)
        if comm_range is None and alive is None:        # everyone hears everyone: one hop, one component
            self.hops = np.ones((n, n)) - np.eye(n)
            self.diameter = 1 if n > 1 else 0
            self.component = np.zeros(n, dtype=np.int64)
            return
        graph = csr_array(adjacency)
        # breadth-first search from every agent: O(N · links), not the O(N³) of boolean matrix powers
        self.hops = shortest_path(graph, method="D", unweighted=True, directed=False)
        finite = self.hops[np.isfinite(self.hops)]
        self.diameter = int(finite.max()) if finite.size else 0
        labels = connected_components(graph, directed=False)[1]
        lowest = np.full(labels.max(initial=-1) + 1, n)
        np.minimum.at(lowest, labels, np.arange(n))
        self.component = lowest[labels]          # component label per agent: the lowest id in its component

    @property
    def n_agents(self) -> int:
        return len(self.adjacency)


_NOTHING = np.zeros(0, dtype=np.int64)
_NOTHING.setflags(write=False)


# -- delivery -------------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Deliveries:
    """Messages arriving in one round, sorted by receiver, then by the round they were sent in, then by sender.

    A receiver handles its messages in that order (thesis §3.2.3: in ascending sender id within a round).
    """

    receiver: np.ndarray        # (K,)
    sender: np.ndarray          # (K,)
    sent: np.ndarray            # (K,) the round each was sent in

    @classmethod
    def of(cls, receiver: np.ndarray, sender: np.ndarray, sent: np.ndarray) -> Deliveries:
        order = np.lexsort((sender, sent, receiver))
        return cls(receiver[order], sender[order], sent[order])

    def __len__(self) -> int:
        return len(self.receiver)

    def positions(self) -> list[np.ndarray]:
        """Index arrays: position p holds every receiver's p-th message, so no receiver appears twice in one."""
        if not len(self):
            return []
        first = np.r_[0, np.flatnonzero(np.diff(self.receiver)) + 1]
        rank = np.arange(len(self)) - np.repeat(first, np.diff(np.r_[first, len(self)]))
        return [np.flatnonzero(rank == p) for p in range(int(rank.max()) + 1)]


@dataclasses.dataclass(frozen=True)
class Sent:
    """What one round of sending did: messages sent, lost and delayed (not delivered in the round they were sent)."""

    sent: int
    lost: int
    delayed: int
    data_items: int


class Network:
    """Delivers each round's broadcasts over ``graph`` through a loss model and a random delay.

    ``send`` queues the messages of the senders (each to all its neighbours), ``deliver`` hands out those due;
    ``sent_by`` counts the messages each agent has sent (one per neighbour per broadcast, lost ones included).
    """

    def __init__(self, graph: CommGraph, loss: LossModel | None = None, max_delay: int = 0,
                 rng: np.random.Generator | None = None) -> None:
        self.graph = graph
        self.loss = loss or NoLoss()
        self.max_delay = max_delay
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._queue = (_NOTHING,) * 4                         # receiver, sender, sent, due
        self._link_cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        self.sent_by = np.zeros(graph.n_agents, dtype=np.int64)

    @property
    def perfect(self) -> bool:
        return isinstance(self.loss, NoLoss) and self.max_delay == 0

    def send(self, now: int, senders: np.ndarray, items: np.ndarray) -> Sent:
        """Every agent of ``senders`` broadcasts to its neighbours; ``items`` (N,) the data items of each message."""
        sender, receiver = self._links(senders)
        self.sent_by[senders] += self.graph.degree[senders]
        if self.perfect:                    # nothing is lost or delayed, and nothing is drawn
            stamp = np.full(len(sender), now)
            queued, lost, delayed = (receiver, sender, stamp, stamp), 0, 0
        else:
            dropped = self.loss.lost(sender, receiver, self.rng)
            delay = (self.rng.integers(0, self.max_delay + 1, len(sender)) if self.max_delay
                     else np.zeros(len(sender), int))
            keep = ~dropped
            queued = (receiver[keep], sender[keep], np.full(int(keep.sum()), now), now + delay[keep])
            lost, delayed = int(dropped.sum()), int((delay[keep] > 0).sum())
        self._queue = (queued if not len(self._queue[0])
                       else tuple(np.concatenate([old, new]) for old, new in zip(self._queue, queued)))
        return Sent(sent=len(sender), lost=lost, delayed=delayed, data_items=int(items[sender].sum()))

    def _links(self, senders: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sender, receiver) of every link out of ``senders``, sender-major, ascending (the same senders round
        after round: cached by the set)."""
        key = np.asarray(senders, dtype=np.int64).tobytes()
        if key not in self._link_cache:
            sending = np.zeros(self.graph.n_agents, dtype=bool)
            sending[senders] = True
            links = np.nonzero(self.graph.adjacency & sending[:, None])
            for array in links:             # shared with the queue: never written
                array.setflags(write=False)
            self._link_cache[key] = links
        return self._link_cache[key]

    def deliver(self, now: int, alive: np.ndarray) -> Deliveries:
        """The messages due by ``now`` whose receiver is alive (a failed receiver's messages are dropped)."""
        receiver, sender, sent, due = self._queue
        ready = due <= now
        if ready.all():                     # everything is due (always on perfect links)
            self._queue = (_NOTHING,) * 4
            take = alive[receiver]
        else:
            self._queue = tuple(a[~ready] for a in self._queue)
            take = ready & alive[receiver]
        if take.all():
            return Deliveries.of(receiver, sender, sent)
        return Deliveries.of(receiver[take], sender[take], sent[take])

    def in_flight(self) -> np.ndarray:
        """The send rounds of the messages still travelling."""
        return self._queue[2]

    def travelling(self) -> set[tuple[int, int]]:
        """(sender, send round) of the messages still travelling: the payloads a protocol must still keep."""
        return set(zip(self._queue[1].tolist(), self._queue[2].tolist()))


def make_network(graph: CommGraph, cfg: TaskAllocConfig, rng: np.random.Generator) -> Network:
    """The ``Network`` the config names (``message_loss``, ``loss_model`` with its ``burst_*`` or ``fading_*``
    fields, ``max_delay``); the loss model is set up for the agents at the graph's positions."""
    loss = LOSS_MODELS[cfg.loss_model].from_config(cfg, graph.positions)
    return Network(graph, loss, cfg.max_delay, rng)


def dropout_schedule(cfg: TaskAllocConfig, n_agents: int, horizon: int,
                     rng: np.random.Generator) -> dict[int, tuple[int, ...]]:
    """Round → the agents that fail at its start: ``dropout_schedule`` as given, or ``dropouts`` agents drawn at
    random, each at a round drawn uniformly from ``dropout_rounds``. A round past ``horizon`` (the round bound) is an
    error: that agent could never fail."""
    if cfg.dropout_schedule:
        pairs = list(cfg.dropout_schedule)
    elif cfg.dropouts:
        agents = rng.choice(n_agents, size=cfg.dropouts, replace=False)
        lo, hi = cfg.dropout_rounds
        pairs = [(int(a), int(r)) for a, r in zip(agents, rng.integers(lo, hi + 1, size=cfg.dropouts))]
    else:
        return {}
    schedule: dict[int, tuple[int, ...]] = {}
    for agent, round_ in pairs:
        if not 0 <= agent < n_agents:
            raise ConfigError(f"config field 'dropout_schedule': agent {agent} does not exist (0..{n_agents - 1})")
        if round_ > horizon:
            raise ConfigError(f"config field 'dropout_schedule'/'dropout_rounds': round {round_} is past the round "
                              f"bound {horizon}; allowed: 1..{horizon}")
        schedule[round_] = (*schedule.get(round_, ()), agent)
    return schedule


def join_schedule(cfg: TaskAllocConfig, horizon: int) -> dict[int, tuple[int, ...]]:
    """Round → the agents that join at its start (``join_at``). A round past ``horizon`` (the round bound) is an
    error: that agent could never join."""
    schedule: dict[int, tuple[int, ...]] = {}
    for agent, round_ in cfg.join_at or ():
        if round_ > horizon:
            raise ConfigError(f"config field 'join_at': agent {agent} joins at round {round_}, past the round bound "
                              f"{horizon}; allowed: 1..{horizon}")
        schedule[round_] = (*schedule.get(round_, ()), agent)
    return schedule
