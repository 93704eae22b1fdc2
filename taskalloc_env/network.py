"""The communication graph g_ik (thesis §2.2.4, §3.2.1): fully connected, or range-limited between start positions.

The thesis draws a range circle per agent (thesis §4.3, Figs 4.2–4.5) but never writes the edge rule, so it is our
choice: ``edge_rule="dist"`` links agents at distance ≤ r; ``"circles_overlap"`` links them when their range
circles overlap (distance ≤ 2r). ``comm_range=None`` is global broadcast. Messages are forwarded whole, so bids
travel multi-hop; D (the diameter, the largest over connected components) bounds how many rounds that takes (a bid
needs up to D rounds to cross the network, thesis §4.3).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components, shortest_path


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
        graph = csr_array(adjacency)
        # breadth-first search from every agent: O(N · links), not the O(N³) of boolean matrix powers
        self.hops = np.ones((n, n)) - np.eye(n) if comm_range is None else \
            shortest_path(graph, method="D", unweighted=True, directed=False)
        finite = self.hops[np.isfinite(self.hops)]
        self.diameter = int(finite.max()) if finite.size else 0
        labels = connected_components(graph, directed=False)[1]
        lowest = np.full(labels.max(initial=-1) + 1, n)
        np.minimum.at(lowest, labels, np.arange(n))
        self.component = lowest[labels]          # component label per agent: the lowest id in its component
        # inbox position t of every receiver with more than t neighbours, for vectorised rounds
        self.inbox = []
        for t in range(int(self.degree.max(initial=0))):
            receivers = np.flatnonzero(self.degree > t)
            senders = np.array([self.neighbours[i][t] for i in receivers], dtype=np.int64)
            self.inbox.append((receivers, senders))

    @property
    def n_agents(self) -> int:
        return len(self.adjacency)
