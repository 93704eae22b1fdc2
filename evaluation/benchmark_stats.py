"""The benchmark's figures: normalised scores, their 95 % intervals, the aggregate over tasks and marl-eval's JSON.

Normalised score of a task (ours, the usual min-max normalisation of Agarwal et al. 2021): ``(score − random) /
(normaliser − random)`` with the task's mean scores on the same seeds, so the normalising baseline (CBGABI, or the
baseline the task's card names) is 1 and the uniform random masked policy 0. Per instance the value is paired with
random on the same seed, ``(s_i − random_i) / (normaliser − random)`` (the paired design of thesis §5.3.1: the
instance's difficulty cancels); these average to the task's figure, and their 95 % t-interval is the interval over
instances. With several runs (training seeds) of a learned policy the interval is over the runs' means.
The aggregate over tasks is rliable's interquartile mean with its stratified bootstrap (Agarwal et al. 2021,
``rliable.library.get_interval_estimates``): one row per run (several runs) or per instance (one run; the k-th test
seed of every task is a row, tasks being independent).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.stats import ci95_half
from taskalloc_env.errors import ConfigError

BOOTSTRAP_REPS = 2000
BOOTSTRAP_SEED = 0


def normalise(scores: Sequence[float] | np.ndarray, reference: Mapping[str, Any]) -> np.ndarray:
    """``(s_i − random_i) / (normaliser − random)`` per seed (the last axis of ``scores``, in ``reference``'s seed
    order); nan when the two baselines' means tie (no scale to measure with)."""
    gap = reference["normaliser_score"] - reference["random"]
    values = np.asarray(scores, dtype=float)
    if gap == 0:
        return np.full(values.shape, np.nan)
    return (values - np.asarray(reference["random_per_seed"], dtype=float)) / gap


def interval(values: np.ndarray) -> list[float]:
    """The 95 % t-interval of the mean of ``values`` (a point for one value)."""
    mean = float(np.mean(values))
    half = float(ci95_half(values))
    return [mean - half, mean + half]


def task_figures(runs: Sequence[Sequence[float]], reference: Mapping[str, Any]) -> dict[str, Any]:
    """One task's figures from ``runs`` (per run, the raw score per test seed, in ``reference``'s seed order).

    ``reference`` holds the seeds' mean scores of ``random``, of the normalising baseline and of the best-known
    solver, and random's score per seed (the first ``len(runs[0])`` seeds of ``taskalloc.evaluation.suite_reference``).
    """
    scores = np.asarray(runs, dtype=float)                      # runs × instances
    normalised = normalise(scores, reference)
    per_run = normalised.mean(axis=1)
    best = reference["best_known_score"]
    return {
        "score": float(scores.mean()),
        "normalised": float(per_run.mean()),
        "ci95": interval(per_run) if len(runs) > 1 else interval(normalised[0]),
        "ci95_instances": interval(normalised.mean(axis=0)),
        "ci95_runs": interval(per_run) if len(runs) > 1 else None,
        "best_known_share": float(scores.mean() / best) if best else None,
        "per_run_normalised": [float(v) for v in per_run],
    }


def aggregate(matrix: np.ndarray, reps: int = BOOTSTRAP_REPS) -> dict[str, Any]:
    """rliable's IQM and mean over the tasks (columns) with 95 % stratified-bootstrap intervals (rows: runs or
    instances); ``ConfigError`` naming the extra when rliable is not installed."""
    try:
        from rliable import library as rly
        from rliable import metrics
    except ImportError:
        raise ConfigError("the benchmark's aggregate needs rliable: pip install 'taskalloc[benchmark]'") from None
    functions = {"iqm": metrics.aggregate_iqm, "mean": metrics.aggregate_mean}
    out: dict[str, Any] = {"method": "rliable stratified bootstrap", "reps": reps, "rows": int(matrix.shape[0]),
                           "tasks": int(matrix.shape[1])}
    for name, function in functions.items():
        # rliable's bootstrap draws from numpy's global generator as well as the RandomState it is given (arch, under
        # it, deprecates that argument): seed both for reproducible intervals, then give the global state back
        saved = np.random.get_state()  # noqa: NPY002
        np.random.seed(BOOTSTRAP_SEED)  # noqa: NPY002
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", FutureWarning)
                point, bounds = rly.get_interval_estimates(
                    {"policy": matrix}, lambda x, f=function: np.array([f(x)]), reps=reps,
                    random_state=np.random.RandomState(BOOTSTRAP_SEED))
        finally:
            np.random.set_state(saved)  # noqa: NPY002
        out[name] = float(point["policy"][0])
        out[f"{name}_ci95"] = [float(bounds["policy"][0][0]), float(bounds["policy"][1][0])]
    return out


def aggregate_matrix(per_task: Mapping[str, np.ndarray]) -> np.ndarray:
    """Rows × tasks for ``aggregate``: each task's normalised values, ``runs × instances``; with several runs a row is
    a run (its mean over instances), with one run a row is the k-th instance of every task (cut to the fewest)."""
    arrays = list(per_task.values())
    if arrays[0].shape[0] > 1:
        return np.stack([a.mean(axis=1) for a in arrays], axis=1)
    rows = min(a.shape[1] for a in arrays)
    return np.stack([a[0, :rows] for a in arrays], axis=1)


def marl_eval_json(policy: str, per_task_scores: Mapping[str, np.ndarray],
                   per_task_normalised: Mapping[str, np.ndarray], env_name: str = "taskalloc") -> dict[str, Any]:
    """marl-eval's raw-data layout ``{env: {task: {algorithm: {run_k: {"step_0": {metric: [..]}, "absolute_metrics":
    {metric: [..]}}}}}}`` (one evaluation step: the benchmark evaluates a finished policy), episode values listed."""
    tasks: dict[str, Any] = {}
    for task_id, scores in per_task_scores.items():
        runs = {}
        for k, (raw, norm) in enumerate(zip(scores, per_task_normalised[task_id])):
            metrics = {"return": [float(v) for v in raw], "normalised_return": [float(v) for v in norm]}
            runs[f"run_{k}"] = {"step_0": {"step_count": 0, **metrics}, "absolute_metrics": metrics}
        tasks[task_id.split("/", 1)[-1]] = {policy: runs}
    return {env_name: tasks}
