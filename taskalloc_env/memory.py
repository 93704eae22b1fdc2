"""How much memory an episode of a given size may hold, and the refusal of a size that does not fit (ours).

The thesis sizes no memory; the estimate counts the arrays the protocol (``protocol``, ``async_protocol``), the
scoring and the observations keep, so that ``TaskAllocEnv`` refuses an episode too large for the machine with one
``ConfigError`` before anything of that size exists.
"""

from __future__ import annotations

import math
import os

from taskalloc_env.errors import ConfigError


def memory_estimate(n_agents: int, n_tasks: int, max_bundle: int | None = None, group_width: int | None = None,
                    asynchronous: bool = False) -> int:
    """Bytes an episode of this size may hold at once (an upper estimate, 8 bytes a value).

    The local tables X_i[k][j] are N·M·W member slots, ids and bids (W = max_j L_j ≤ N, ``group_table``;
    ``group_width`` = W, N when not given); the asynchronous protocol also keeps a time per (holder, agent, task)
    entry (``async_consensus.Times``), N·N·M values. A round copies the tables about seven times (the snapshot sent,
    the merge's receiver blocks, the before/after tables of the convergence test). A batched gain computation holds
    ten (N, P + 1, M) arrays for paths of up to P = max_bundle tasks; observations are N·22·M values, built three
    times. Twelve N·N arrays: the graph's distances (three coordinates) and hops, the timestamps s_i[k], the relayed
    stamps and the copies a round makes of them, the observation's silence. Four M·M arrays: the prerequisites and
    the task-to-task distances.
    """
    return sum(_memory_terms(n_agents, n_tasks, max_bundle, group_width, asynchronous).values())


def _memory_terms(n_agents: int, n_tasks: int, max_bundle: int | None, group_width: int | None = None,
                  asynchronous: bool = False) -> dict[str, int]:
    """The terms of ``memory_estimate`` in bytes, keyed by what they hold."""
    n, m = int(n_agents), int(n_tasks)
    p = min(m, int(max_bundle or m))
    w = min(n, int(group_width or n))
    tables = ({"per-entry times of N·N·M values (asynchronous)": 8 * 7 * n * n * m} if asynchronous else {})
    return {"local tables of N·M·L member slots": 8 * 7 * 2 * n * m * w, **tables,
            "N·N arrays (graph distances and hops, timestamps s_i[k] and their copies)": 8 * 12 * n * n,
            "M·M arrays (prerequisites, task-to-task distances)": 8 * 4 * m * m,
            "path gains of N·M·(P+1) values (P = max_bundle)": 8 * 10 * n * m * (p + 1),
            "observations of N·22·M values": 8 * 70 * n * m}


def available_memory() -> int:
    """Bytes this machine can still give a process (Linux: MemAvailable; elsewhere physical memory)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_memory(n_agents: int, n_tasks: int, max_bundle: int | None, limit_gb: float | None,
                 group_width: int | None = None, asynchronous: bool = False) -> None:
    """Refuse a size whose estimate exceeds ``limit_gb`` (default: the memory available now), before allocating."""
    if limit_gb is not None and (isinstance(limit_gb, bool) or not isinstance(limit_gb, (int, float))
                                 or not 0 < limit_gb < math.inf):
        raise ConfigError(f"memory_limit_gb: got {str(limit_gb)[:40]}; allowed: a finite number > 0, or None")
    terms = _memory_terms(n_agents, n_tasks, max_bundle, group_width, asynchronous)
    need, largest = sum(terms.values()), max(terms, key=terms.__getitem__)
    limit = available_memory() if limit_gb is None else limit_gb * 2**30
    if need > limit:
        raise ConfigError(f"{n_agents} agents × {n_tasks} tasks need about {need / 2**30:.1f} GiB (mostly {largest}, "
                          f"see memory_estimate); the limit is {limit / 2**30:.1f} GiB "
                          f"({'available now' if limit_gb is None else 'memory_limit_gb'}); pass memory_limit_gb= to "
                          "raise it")
