"""Paired statistics for policy comparisons on shared seeds.

The thesis quotes means ± (presumably) standard deviations and p-values without naming the test (§3.3.3, §5.3.2);
the design is paired (the same seeds for every algorithm, thesis §5.3.1), so we use a paired t-test and the
Wilcoxon signed-rank test as a check (our choice), plus the share of seeds on which one variant beats another
(thesis §5.3.2, Fig 5.16).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from scipy import stats


def mean_sd(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof = 1; 0 for a single value, nan for none)."""
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        return float("nan"), float("nan")
    return float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else 0.0


def format_mean_sd(values: Sequence[float], digits: int = 0) -> str:
    """``mean ± sd`` rounded to ``digits`` decimals (``–`` for no values)."""
    mean, sd = mean_sd(values)
    if np.isnan(mean):
        return "–"
    return f"{mean:.{digits}f} ± {sd:.{digits}f}"


def ci95_half(values: Sequence[float] | np.ndarray, axis: int | None = None) -> float | np.ndarray:
    """Half-width of the 95 % t-interval of the mean (over ``axis``; all values without one); 0 for fewer than
    two values."""
    x = np.asarray(values, dtype=float)
    n = x.size if axis is None else x.shape[axis]
    if n < 2:
        return 0.0 if axis is None else np.zeros(np.delete(x.shape, axis))
    half = stats.t.ppf(0.975, n - 1) * x.std(axis=axis, ddof=1) / np.sqrt(n)
    return float(half) if axis is None else half


def paired_t_pvalue(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided paired t-test p-value of a − b; 1.0 when every difference is equal (no evidence either way)."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    if d.size < 2:
        return float("nan")
    if np.allclose(d, d[0]):
        return 1.0 if np.isclose(d[0], 0.0) else 0.0
    return float(stats.ttest_rel(a, b).pvalue)


def wilcoxon_pvalue(a: Sequence[float], b: Sequence[float]) -> float:
    """Two-sided Wilcoxon signed-rank p-value of a − b (zero differences dropped); 1.0 if all are zero."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    d = d[~np.isclose(d, 0.0)]
    if d.size == 0:
        return 1.0
    return float(stats.wilcoxon(d).pvalue)


def share_better(a: Sequence[float], b: Sequence[float], tol: float = 1e-9) -> float:
    """Share of paired seeds on which a > b by more than ``tol`` (Fig 5.16's "beats CBGA in 78 % of runs")."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    return float(np.mean(d > tol)) if d.size else float("nan")


def share_tied(a: Sequence[float], b: Sequence[float], tol: float = 1e-9) -> float:
    """Share of paired seeds on which |a − b| ≤ ``tol``."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    return float(np.mean(np.abs(d) <= tol)) if d.size else float("nan")


@dataclasses.dataclass(frozen=True)
class PairedComparison:
    """A against B on the same seeds."""

    n: int
    mean_diff: float        # mean of a − b
    sd_diff: float
    ci95: tuple[float, float]   # 95 % t-interval of the mean difference
    ratio: float            # mean(a) / mean(b)
    p_t: float              # paired t-test, two-sided
    p_wilcoxon: float
    better: float           # share of seeds with a > b
    tied: float             # share of seeds with a = b


def paired(a: Sequence[float], b: Sequence[float]) -> PairedComparison:
    """Every paired figure of a against b (same length, same seed order)."""
    a_arr, b_arr = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a_arr.shape != b_arr.shape:
        raise ValueError(f"paired samples need equal lengths, got {a_arr.size} and {b_arr.size}")
    mean_diff, sd_diff = mean_sd(a_arr - b_arr)
    half = ci95_half(a_arr - b_arr) if a_arr.size > 1 else np.nan
    denominator = b_arr.mean() if b_arr.size else float("nan")
    ratio = float(a_arr.mean() / denominator) if denominator else float("nan")
    return PairedComparison(n=int(a_arr.size), mean_diff=mean_diff, sd_diff=sd_diff,
                            ci95=(mean_diff - half, mean_diff + half), ratio=ratio,
                            p_t=paired_t_pvalue(a_arr, b_arr), p_wilcoxon=wilcoxon_pvalue(a_arr, b_arr),
                            better=share_better(a_arr, b_arr), tied=share_tied(a_arr, b_arr))


def format_p(p: float) -> str:
    """p-values as tables print them: ``<0.001``, ``0.004``, ``0.21``."""
    if np.isnan(p):
        return "–"
    if p < 0.001:
        return "<0.001"
    return f"{p:.3f}" if p < 0.1 else f"{p:.2f}"
