"""The communication graph g_ik (thesis §2.2.4, §3.2.1): fully connected, or range-limited between start positions.

The thesis draws a range circle per agent (thesis §4.3, Figs 4.2–4.5) but never writes the edge rule, so it is our
choice: ``edge_rule="dist"`` links agents at distance ≤ r; ``"circles_overlap"`` links them when their range
circles overlap (distance ≤ 2r). ``comm_range=None`` is global broadcast. Messages are forwarded whole, so bids
travel multi-hop; D (the diameter, the largest over connected components) bounds how many rounds that takes (a bid
needs up to D rounds to cross the network, thesis §4.3).
"""

from __future__ import annotations

import numpy as np


class CommGraph:
    """Symmetric graph without self-loops; neighbours of each agent in ascending id order."""

    def __init__(self, positions: np.ndarray, comm_range: float | None = None, edge_rule: str = "dist") -> None:
        n = len(positions)
        if comm_range is None:
            adjacency = ~np.eye(n, dtype=bool)
        else:
            reach = comm_range if edge_rule == "dist" else 2.0 * comm_range
            dist = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=2)
            adjacency = (dist <= reach) & ~np.eye(n, dtype=bool)
        self.adjacency = adjacency
        self.adjacency.setflags(write=False)
        self.neighbours = [np.flatnonzero(adjacency[i]) for i in range(n)]
        self.degree = adjacency.sum(axis=1)
        self.hops = _hop_distances(adjacency)
        finite = self.hops[np.isfinite(self.hops)]
        self.diameter = int(finite.max()) if finite.size else 0
        self.component = _components(self.hops)
        # inbox position t of every receiver with more than t neighbours, for vectorised rounds
        self.inbox = []
        for t in range(int(self.degree.max(initial=0))):
            receivers = np.flatnonzero(self.degree > t)
            senders = np.array([self.neighbours[i][t] for i in receivers], dtype=np.int64)
            self.inbox.append((receivers, senders))

    @property
    def n_agents(self) -> int:
        return len(self.adjacency)


def _hop_distances(adjacency: np.ndarray) -> np.ndarray:
    """All-pairs hop counts by breadth-first search over boolean matrix powers (inf where unreachable)."""
    n = len(adjacency)
    hops = np.full((n, n), np.inf)
    np.fill_diagonal(hops, 0)
    frontier = np.eye(n, dtype=bool)
    reached = frontier.copy()
    step = 0
    while frontier.any():
        step += 1
        frontier = (frontier.astype(np.int64) @ adjacency.astype(np.int64) > 0) & ~reached
        hops[frontier] = step
        reached |= frontier
    return hops


def _components(hops: np.ndarray) -> np.ndarray:
    """Component label per agent: the lowest id it can reach."""
    return np.argmax(np.isfinite(hops), axis=1)
