"""Compiled kernels (numba) of the hot loops; the numpy code they mirror stays the reference.

* ``merge.exchange_all``: a round's deliveries on the receivers' tables (``consensus.exchange_reference``);
* ``plan.plan_paths``: path timing and insertion gains (``scoring.ScoringModel.plan_reference``);
* ``bids.bid_rows``: the bid view's rows, eligibility and the outbid test (``bidding.bid_view``);
* ``score.paid_groups``: who is paid in a team score (``scoring.paid_groups_reference``);
* ``observe.step_features``: the per-step columns of the observations (``ObservationBuilder.observe_reference``);
* ``masks.fill_masks``: every agent's action mask (``engine.action_masks_reference``);
* ``table.set_member``: one write X_i[k][j] to the group table (``GroupTable.set_reference``);
* ``table.joined_members``: the columns a member joined since a copy (``GroupTable.joined_reference``);
* ``quits.quittable``: the quit conditions of thesis Alg 9 (``Protocol.quittable_reference``);
* ``batch``: the step of K instances held as (K, …) arrays, on the kernels above (the batched env's arrays engine);
* ``taskalloc.policies.greedy.greedy_actions`` (in the policies' layer, on this module's ``jit``): the scripted bundle
rule
  (``CBGAPolicy.choose_reference``).

Without numba, or with the environment variable ``TASKALLOC_KERNELS=reference``, ``COMPILED`` is false and the
numpy references run instead (the same allocations; observations may differ in the last bit of an ``exp``, see
docs/decisions.md). ``tests/test_kernels.py`` compares each kernel with its reference on random inputs. The machine
code is cached in a user folder shared by every process (``kernels.cache``: ``~/.cache/taskalloc/numba`` unless
``NUMBA_CACHE_DIR`` is set, one sub-folder per version of the kernels' sources); a process that compiles says so in
one line on stderr.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from taskalloc_env.kernels.cache import CompileNotice, caching_in, kernel_cache_dir

try:
    import numba
except ImportError:          # pragma: no cover - numba is a dependency; the references still work without it
    numba = None

MODES = ("compiled", "reference")
MODE = os.environ.get("TASKALLOC_KERNELS", "compiled")
if MODE not in MODES:
    raise ImportError(f"TASKALLOC_KERNELS={MODE!r} is not one of {MODES}")
COMPILED = numba is not None and MODE == "compiled"
NOTICE = CompileNotice()        # this process's compiles of the kernels below (cache misses)
CACHE = kernel_cache_dir() if COMPILED else None      # one folder per version of the kernels' sources
if COMPILED:
    NOTICE.listen()


def jit(function: Callable[..., Any] | None = None, *, inline: bool = False) -> Any:
    """``numba.njit`` with an on-disk cache in ``CACHE``, or the function itself without numba; ``@jit(inline=
    True)`` compiles a small helper into each caller (numba's ``inline="always"``), for helpers called so often that
    the call costs more than their body."""
    if function is None:
        return lambda f: jit(f, inline=inline)
    if not COMPILED:
        return function
    with caching_in(numba, CACHE):
        return NOTICE.watch(numba.njit(cache=True, nogil=True, inline="always" if inline else "never")(function))
