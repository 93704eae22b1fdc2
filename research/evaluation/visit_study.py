"""The visit study: CBAA, CBBA, ACBBA, PI and CBGA on the collaborative visit under five channels at 5–70 % loss.

    python -m research.evaluation.visit_study --episodes 200 --jobs 2

Ours, after the protocol of Nayak et al., "Experimental Comparison of Decentralized Task Allocation Algorithms Under
Imperfect Communication" (IEEE RA-L 5(2), 2020: collaborative visit of known targets; the maximum distance travelled
and the maximum number of messages sent by any agent; Bernoulli, Gilbert–Elliott and Rayleigh channels) and of its
2026 successor, the DCTA benchmark (500 paired instances of 4 robots on the left edge of a 19 × 19 grid and 10
target cells; ideal, Bernoulli, Gilbert–Elliott with lag-1 correlation ρ = 0.8 and Rayleigh-style channels at 5–70 %
nominal loss; completion kept apart from efficiency). Its scenario is ``configs/scenarios/visit.yaml`` (generator
``visit``, grid cells, Manhattan travel). The five channels (``CHANNELS``): ideal; ``bernoulli`` (each message lost
with probability ℓ); ``ge_rho`` (the DCTA benchmark's process: stationary loss ℓ, ρ = 0.8); ``ge_burst`` (the
transition-parameterised Gilbert–Elliott channel, ``loss_model: gilbert_elliott``, with a fixed mean burst of
1 / ``BURST_LEAVE`` = 5 messages and its entry probability set for stationary loss ℓ); ``rayleigh`` (distance-dependent
fading with the DCTA benchmark's path-loss exponent 3 and the fading distance at which the instance's links lose ℓ on
average, ``rayleigh_distance``). Every cell plays the same seeds, so every row of a seed solves the same instance
(the ``instance`` fingerprint is checked). Rows: ``results/visit/episodes.csv``; tables: ``results/visit/table.md``;
docs/results.md ("The visit study") quotes them next to the DCTA benchmark's published figures.

Solvers: the product's ``cbaa``, ``cbba``, ``acbba``, ``pi`` and ``cbga`` policies, each one episode (plan, then fly),
and ``cbaa-reauction`` (``research.evaluation.reauction``: CBAA run again after each visit, as the DCTA benchmark
re-allocates as robots reach their cells).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import itertools
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from research.evaluation.reauction import reauction
from taskalloc.evaluation.episodes import Episode, fingerprint, run_episode, solver_name
from taskalloc.evaluation.pool import as_finished
from taskalloc.evaluation.report import markdown_table
from taskalloc.evaluation.stats import format_p, paired
from taskalloc_env import TaskAllocConfig, resolve_config
from taskalloc_env.errors import ConfigError, run_cli, seed_argument
from taskalloc_env.scenario import visit_starts

SCENARIO = "visit"
CHANNELS = ("ideal", "bernoulli", "ge_rho", "ge_burst", "rayleigh")
CHANNEL_NAMES = {"ideal": "ideal", "bernoulli": "Bernoulli", "ge_rho": "Gilbert–Elliott ρ = 0.8",
                 "ge_burst": "Gilbert–Elliott, bursts of 5", "rayleigh": "Rayleigh"}
# the DCTA benchmark's three impaired channels (its published means average over them)
DCTA_CHANNELS = ("bernoulli", "ge_rho", "rayleigh")
LEVELS = (0.05, 0.2, 0.4, 0.7)
SOLVERS = ("cbaa", "cbaa-reauction", "cbba", "acbba", "pi", "cbga")
REAUCTION = "cbaa-reauction"
BURST_CORRELATION = 0.8         # the DCTA benchmark's ρ
BURST_LEAVE = 0.2               # ge_burst: P(bad → good) per message, so bursts last 5 messages on average
FADING_EXPONENT = 3.0           # the DCTA benchmark's path-loss exponent (tuned from 2.5 for its grid)
METRICS = ("completion", "max_travel", "max_agent_messages", "rounds", "score", "conflicts", "converged")
COLUMNS = ("channel", "level", "solver", "seed", "instance", *METRICS, "messages_lost")
OUT = Path("results/visit")
BATCH = 25                      # seeds per pool task


def rayleigh_distance(level: float, starts: np.ndarray, exponent: float = FADING_EXPONENT) -> float:
    """The fading distance d0 at which the directed links between ``starts`` lose ``level`` of their messages on
    average: mean over links of 1 − exp(−(d / d0)^α) = ℓ, solved by bisection on log d0 (the loss falls as d0
    grows). The DCTA benchmark calibrates its sensitivity the same way, over a fixed set of distances."""
    d = np.linalg.norm(starts[:, None, :] - starts[None, :, :], axis=2)[~np.eye(len(starts), dtype=bool)]
    if not (0 < level < 1) or not (d > 0).any():
        raise ConfigError(f"rayleigh level {level!r}: a loss in (0, 1) needs agents apart from each other")

    def loss(d0: float) -> float:
        return float(np.mean(1.0 - np.exp(-((d / d0) ** exponent))))

    low, high = math.log(d.max()) - 20.0, math.log(d.max()) + 20.0
    for _ in range(200):
        mid = (low + high) / 2
        low, high = (mid, high) if loss(math.exp(mid)) > level else (low, mid)
    return math.exp((low + high) / 2)


def channel_overrides(channel: str, level: float, cfg: TaskAllocConfig) -> dict[str, Any]:
    """The config fields of ``channel`` at stationary loss ``level`` (0 for ``ideal``)."""
    if channel == "ideal":
        return {}
    if not 0 < level < 1:
        raise ConfigError(f"--levels: got {level!r}; allowed: losses in (0, 1)")
    if channel == "bernoulli":
        return {"loss_model": "independent", "message_loss": level}
    if channel == "ge_rho":
        return {"loss_model": "gilbert_elliott_rho", "message_loss": level, "burst_correlation": BURST_CORRELATION}
    if channel == "ge_burst":
        # stationary P(bad) = a / (a + b) = ℓ with b = BURST_LEAVE: a = ℓ b / (1 − ℓ), a loss-free good state
        enter = level * BURST_LEAVE / (1 - level)
        if enter > 1:
            raise ConfigError(f"--levels: {level:g} needs P(good → bad) = {enter:.3g} > 1 with bursts of "
                              f"{1 / BURST_LEAVE:g}; allowed: losses up to {1 / (1 + BURST_LEAVE):.3g}")
        return {"loss_model": "gilbert_elliott", "message_loss": 0.0, "burst_loss": 1.0,
                "burst_enter": enter, "burst_leave": BURST_LEAVE}
    if channel == "rayleigh":
        return {"loss_model": "rayleigh", "fading_exponent": FADING_EXPONENT,
                "fading_distance": rayleigh_distance(level, visit_starts(cfg))}
    raise ConfigError(f"channel {channel!r}; allowed: {' | '.join(CHANNELS)}")


@dataclasses.dataclass(frozen=True)
class Cell:
    """One (channel, level) condition: its label and its config."""

    channel: str
    level: float
    config: TaskAllocConfig


def conditions(levels: Sequence[float], channels: Sequence[str] = CHANNELS,
               overrides: Mapping[str, Any] | None = None) -> list[Cell]:
    """Ideal (if among ``channels``), then every impaired channel at every level, on ``visit.yaml`` with
    ``overrides``."""
    base = resolve_config(SCENARIO, **(overrides or {}))
    cells = [Cell("ideal", 0.0, base)] if "ideal" in channels else []
    for channel in (c for c in CHANNELS[1:] if c in channels):
        cells += [Cell(channel, level, base.replace(**channel_overrides(channel, level, base))) for level in levels]
    return cells


def display(solver: str) -> str:
    """The solver's name in the rows: the policy's own (``CBAA``), or ``CBAA re-auctioned``."""
    return "CBAA re-auctioned" if solver == REAUCTION else solver_name(solver)


def run_item(item: tuple[str, Cell, int]) -> dict[str, Any]:
    """One row: ``solver`` on instance ``seed`` of ``cell``."""
    solver, cell, seed = item
    labels = {"channel": cell.channel, "level": cell.level}
    if solver == REAUCTION:
        outcome = reauction(cell.config, seed)
        a = outcome.allocation
        figures = {"completion": a.completion, "max_travel": a.max_travel,
                   "max_agent_messages": outcome.max_agent_messages, "rounds": outcome.rounds, "score": a.score,
                   "conflicts": outcome.duplicate_visits, "converged": outcome.converged,
                   "messages_lost": outcome.messages_lost,
                   "instance": fingerprint(outcome.instance)}
        return {**labels, "solver": display(solver), "seed": seed, **figures}
    row = run_episode(Episode(solver, cell.config, seed))
    return {**labels, **{k: row[k] for k in COLUMNS if k in row}}


def run_batch(batch: tuple[str, Cell, Sequence[int]]) -> list[dict[str, Any]]:
    """The rows of one solver on one cell over a run of seeds (one task for the pool, so that tens of thousands of
    episodes are a few hundred tasks)."""
    solver, cell, seeds = batch
    return [run_item((solver, cell, seed)) for seed in seeds]


def run(cells: Sequence[Cell], solvers: Sequence[str], seeds: Sequence[int], jobs: int,
        progress: bool = True) -> list[dict[str, Any]]:
    """Every (cell, solver, seed), rows in that order; the pairing of instances is checked."""
    seeds = list(seeds)
    chunks = [seeds[k:k + BATCH] for k in range(0, len(seeds), BATCH)]
    batches = [(solver, cell, chunk) for cell in cells for solver in solvers for chunk in chunks]
    rows: list[list[dict[str, Any]]] = [[] for _ in batches]
    with tqdm(total=len(batches) and sum(map(len, (b[2] for b in batches))), desc="visit", unit="ep",
              disable=not progress, dynamic_ncols=True) as bar:
        for index, batch_rows in as_finished(run_batch, batches, jobs):
            rows[index] = batch_rows
            bar.update(len(batch_rows))
    done = [row for batch_rows in rows for row in batch_rows]
    instances: dict[int, str] = {}
    broken = [r for r in done if instances.setdefault(r["seed"], r["instance"]) != r["instance"]]
    if broken:
        raise RuntimeError(f"{len(broken)} rows solved another instance than their seed's first row")
    return done


def means(rows: Iterable[Mapping[str, Any]]) -> dict[tuple[str, float, str], dict[str, float]]:
    """Per (channel, level, solver): the mean of every metric over the seeds."""
    groups: dict[tuple[str, float, str], list[Mapping[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["channel"], float(row["level"]), row["solver"]), []).append(row)
    return {key: {m: float(np.mean([_number(r[m]) for r in group])) for m in METRICS} | {"n": len(group)}
            for key, group in groups.items()}


def _number(value: Any) -> float:
    if isinstance(value, str):
        return float(value in ("True", "true")) if value in ("True", "False", "true", "false") else float(value)
    return float(value)


def impaired_means(cells: Mapping[tuple[str, float, str], Mapping[str, float]], channels: Sequence[str],
                   metric: str) -> dict[str, float]:
    """Per solver: the unweighted mean of ``metric`` over the impaired conditions of ``channels`` (the DCTA
    benchmark's average over its 24 impaired conditions, here over its channels' conditions we ran)."""
    out: dict[str, list[float]] = {}
    for (channel, _, solver), figures in cells.items():
        if channel in channels:
            out.setdefault(solver, []).append(figures[metric])
    return {solver: float(np.mean(values)) for solver, values in out.items()}


def tables(rows: Sequence[Mapping[str, Any]]) -> str:
    """The markdown of the study: per condition the metrics of every solver, then the impaired means."""
    cells = means(rows)
    solvers = list(dict.fromkeys(r["solver"] for r in rows))
    seeds = sorted({int(r["seed"]) for r in rows})
    text = [f"{len(seeds)} paired instances (seeds {seeds[0]}–{seeds[-1]}) of `configs/scenarios/visit.yaml`; "
            "means per condition.\n"]
    header = ("channel", "loss", "solver", "completion", "max travel", "max agent msgs", "rounds", "score",
              "conflicts", "converged")
    body = []
    for (channel, level, solver), f in cells.items():
        body.append((CHANNEL_NAMES.get(channel, channel), f"{100 * level:.0f} %", solver, f"{f['completion']:.3f}",
                     f"{f['max_travel']:.2f}", f"{f['max_agent_messages']:.1f}", f"{f['rounds']:.1f}",
                     f"{f['score']:.1f}", f"{f['conflicts']:.2f}", f"{100 * f['converged']:.0f} %"))
    text.append(markdown_table(header, body, "lllrrrrrrr"))
    shown: list[list[str]] = []
    for label, channels in (("the DCTA benchmark's three impaired channels", DCTA_CHANNELS),
                            ("every impaired channel run", CHANNELS[1:])):
        present = [c for c in channels if any(k[0] == c for k in cells)]
        if not present or present in shown:
            continue
        shown.append(present)
        label = f"{label} ({', '.join(CHANNEL_NAMES[c] for c in present)})"
        avg = {m: impaired_means(cells, present, m) for m in ("completion", "max_travel", "max_agent_messages",
                                                               "rounds", "score")}
        text.append(f"\nUnweighted means over the impaired conditions of {label}:\n")
        text.append(markdown_table(("solver", "completion", "max travel", "max agent msgs", "rounds", "score"), [
            (s, f"{avg['completion'][s]:.3f}", f"{avg['max_travel'][s]:.2f}", f"{avg['max_agent_messages'][s]:.1f}",
             f"{avg['rounds'][s]:.1f}", f"{avg['score'][s]:.1f}") for s in solvers if s in avg["max_travel"]]))
        text.append(ranking(rows, present, "max_travel"))
    return "".join(text)


def seed_means(rows: Iterable[Mapping[str, Any]], channels: Sequence[str], metric: str) -> dict[str, np.ndarray]:
    """Per solver: each seed's mean of ``metric`` over the impaired conditions of ``channels``, in seed order."""
    values: dict[str, dict[int, list[float]]] = {}
    for row in rows:
        if row["channel"] in channels:
            values.setdefault(row["solver"], {}).setdefault(int(row["seed"]), []).append(_number(row[metric]))
    return {solver: np.array([np.mean(by_seed[k]) for k in sorted(by_seed)]) for solver, by_seed in values.items()}


def ranking(rows: Sequence[Mapping[str, Any]], channels: Sequence[str], metric: str) -> str:
    """The solvers that serve (nearly) every target (mean completion ≥ 0.99: not the one-shot CBAA), ordered by their
    impaired mean of ``metric`` (lowest first), each against the next on the same seeds (each seed's mean over the
    conditions: paired t-test)."""
    per_seed = seed_means(rows, channels, metric)
    complete = seed_means(rows, channels, "completion")
    order = sorted((s for s in per_seed if complete[s].mean() >= 0.99), key=lambda s: per_seed[s].mean())
    body = []
    for a, b in itertools.pairwise(order):
        pc = paired(per_seed[a], per_seed[b])
        body.append((f"{a} < {b}", f"{pc.mean_diff:+.2f}", f"[{pc.ci95[0]:+.2f}, {pc.ci95[1]:+.2f}]",
                     format_p(pc.p_t), f"{100 * (1 - pc.better - pc.tied):.0f} %"))
    return (f"\nRanking by {metric} (solvers with completion ≥ 0.99; each seed's mean over these conditions):\n"
            + markdown_table(("pair", "Δ mean", "95 % interval", "p (t)", "seeds lower"), body))


def merged(old: Sequence[Mapping[str, Any]], new: Sequence[Mapping[str, Any]],
           rerun: set[str]) -> list[Mapping[str, Any]]:
    """``old`` with the rows of the ``rerun`` solvers replaced by ``new``, which must cover the same conditions and
    seeds and solve the same instances."""
    def key(r: Mapping[str, Any]) -> tuple[str, float, str, int]:
        return r["channel"], float(r["level"]), r["solver"], int(r["seed"])

    replaced = {key(r) for r in old if r["solver"] in rerun}
    if replaced != {key(r) for r in new}:
        raise ConfigError("--solver with an existing episodes.csv: the run must cover the file's conditions and seeds "
                          "(the same --levels, --channel, --episodes and --seed-start)")
    instances = {int(r["seed"]): r["instance"] for r in old}
    if any(instances.get(int(r["seed"])) != r["instance"] for r in new):
        raise ConfigError("--solver with an existing episodes.csv: the rows solve other instances than the file's")
    fresh = {key(r): r for r in new}
    return [fresh.get(key(r), r) for r in old]


def write_rows(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: f"{row[k]:.6g}" if isinstance(row[k], float) else row[k] for k in COLUMNS})


def read_rows(path: Path) -> list[dict[str, Any]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _settings(pairs: Sequence[str]) -> dict[str, Any]:
    """``FIELD=VALUE`` pairs, each value read as YAML (the config checks the field and the value)."""
    out = {}
    for pair in pairs:
        field, sep, value = pair.partition("=")
        if not sep or not field:
            raise ConfigError(f"--set: got {pair!r}; allowed: FIELD=VALUE")
        out[field] = yaml.safe_load(value)
    return out


def main(argv: Sequence[str] | None = None) -> str:
    parser = argparse.ArgumentParser(prog="python -m research.evaluation.visit_study", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=200, help="paired instances per cell (default 200)")
    parser.add_argument("--seed-start", type=seed_argument, default=0, help="first seed (default 0)")
    parser.add_argument("--levels", type=float, nargs="+", default=list(LEVELS),
                        help="stationary losses of the impaired channels (default 0.05 0.2 0.4 0.7)")
    parser.add_argument("--solver", action="append", choices=SOLVERS,
                        help="solvers (default: all); with an existing episodes.csv in --out, their rows are replaced")
    parser.add_argument("--channel", action="append", choices=CHANNELS, help="channels (default: all five)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="a config field of the scenario, as YAML (e.g. time_discount=0)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--out", type=Path, default=OUT, help=f"results folder (default {OUT})")
    parser.add_argument("--report", action="store_true", help="rewrite table.md from the folder's episodes.csv")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    if args.report:
        text = tables(read_rows(args.out / "episodes.csv"))
    else:
        if not 1 <= args.episodes <= 100_000:
            raise ConfigError(f"--episodes: got {args.episodes}; allowed: 1..100000")
        if args.jobs < 1:
            raise ConfigError(f"--jobs: got {args.jobs}; allowed: integers >= 1")
        cells = conditions(args.levels, args.channel or CHANNELS, _settings(args.set))
        seeds = range(args.seed_start, args.seed_start + args.episodes)
        rows = run(cells, args.solver or SOLVERS, seeds, args.jobs, progress=not args.no_progress)
        if args.solver and (args.out / "episodes.csv").is_file():       # one solver again: keep the others' rows
            rerun = {display(s) for s in args.solver}
            rows = merged(read_rows(args.out / "episodes.csv"), rows, rerun)
        write_rows(args.out / "episodes.csv", rows)
        text = tables(rows)
    (args.out / "table.md").write_text(text)
    print(text)
    return text


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
