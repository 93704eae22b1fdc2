"""When each task becomes known: pop-up tasks released during the episode (Johnson §4.1.3, Figs 4-3 and 4-4).

Johnson's dynamic runs start from "an initial allocation of 10 tasks", then "every 0.2 seconds after, a single
pop-up task is added" (Johnson §4.1.3, extraction line 923), or every 50 ms (line 930). Here the last
``popup_tasks`` task ids are the pop-ups, the others are known at tick (round) 0. The k-th pop-up is released at

* ``popup_times[k]``, when given;
* (k + 1) · ``popup_period`` with ``popup_arrivals="periodic"`` (Johnson's schedule);
* with ``"poisson"``, at the k-th of ``popup_tasks`` uniform draws over (0, ``popup_tasks`` · ``popup_period``],
  sorted and rounded up to whole ticks: a Poisson process of rate 1 / ``popup_period`` conditioned on its count, so
  the last release never passes ``config.release_horizon`` (our choice; Johnson uses fixed periods only).

Ticks are env steps under ``consensus="acbba"`` and rounds under the synchronous modes.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.config import TaskAllocConfig


def release_ticks(cfg: TaskAllocConfig, n_tasks: int, rng: np.random.Generator) -> np.ndarray:
    """(M,) the tick at which each task is released (0: known from the start); draws only for Poisson arrivals."""
    release = np.zeros(n_tasks, dtype=np.int64)
    count = cfg.popup_tasks
    if not count:
        return release
    if cfg.popup_times is not None:
        ticks = np.asarray(cfg.popup_times, dtype=np.int64)
    elif cfg.popup_arrivals == "periodic":
        ticks = cfg.popup_period * np.arange(1, count + 1, dtype=np.int64)
    else:
        horizon = count * cfg.popup_period
        ticks = np.maximum(np.ceil(np.sort(horizon - rng.uniform(0, horizon, count))), 1).astype(np.int64)
    release[n_tasks - count:] = ticks
    return release
