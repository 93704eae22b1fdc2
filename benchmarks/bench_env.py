"""Speed benchmarks in one run: CBBA-Python ratios, env throughput, consensus scaling, peak memory.

    python -m benchmarks.bench_env --reference ../shared/anchors/CBBA-Python   # everything (about 5 CPU-minutes)
    python -m benchmarks.bench_env --quick                                     # up to 20 × 50, well under a minute
    python -m benchmarks.bench_env --only scaling,memory --max-size 50x100     # some sections, smaller sizes

Every time is CPU time of this process (``time.process_time``), so a busy machine slows the figures less than wall
time would; they are still only comparable within one machine. Each section prints a markdown table:

- reference: CBBA side by side with the public CBBA-Python on its own instances (``benchmarks.cbba_python``; only
  with ``--reference``), ours in both consensus modes through the env and through ``taskalloc.policies.fast.solve``.
- env: agent-steps per CPU second of the default scenario with the random masked policy, and a whole scripted CBGA
  and CBGABI episode of the default scenario (env rollout and direct solve), the fastest of ``--repeats`` timings.
- scaling: one solve (``taskalloc.policies.fast.solve``) of CBBA (L_j = 1), CBGA and CBGABI (L_j = 4) over N = 10…100
agents at
  M = 2N tasks and M = N…5N at the largest N, with the exponents of N and M fitted by least squares on
  log t = c + a log N + b log M (per solve and per consensus round), on all sizes and on those with N ≥ half the
  largest (fixed costs flatten the small ones).
- memory: tracemalloc's peak of one solve (what numpy and Python allocate; arrays numba allocates inside a compiled
  kernel are not traced), with the same fit, next to the size of one group table (``group_table.GroupTable``:
  N·M·L member ids and bids plus N·M counts and own bids, the sparse store of the local tables) and, for comparison,
  of the dense (holder, agent, task) float64 array it replaced (N·N·M).
- strategies: the default scenario with CBGA under each network strategy, as ratios to perfect links.

In a tree without ``taskalloc.policies.fast`` (the one before the speed work) the solves are whole env episodes instead.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time
import tracemalloc
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.bench_allocation_time import machine
from benchmarks.cbba_python import SIZES, load_reference, reference_table, solve
from taskalloc.evaluation.report import markdown_table
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.allocation import Allocation
from taskalloc_env.errors import ConfigError, run_cli

SECTIONS = ("reference", "env", "scaling", "memory", "strategies")
SOLVERS = {"CBBA (L_j = 1)": ("cbba", 1), "CBGA (L_j = 4)": ("cbga", 4), "CBGABI (L_j = 4)": ("cbgabi", 4)}
N_SWEEP = (10, 20, 50, 100)     # agents, at M = 2N tasks
M_FACTORS = (1, 2, 5)           # tasks per agent at the largest N
QUICK = {"max_size": "20x50", "runs": 1, "seeds": 1, "seconds": 1.0, "strategy_seeds": 2, "repeats": 1}
FULL = {"max_size": "100x500", "runs": 3, "seeds": 2, "seconds": 5.0, "strategy_seeds": 20, "repeats": 10}
# the communication strategies of the default scenario: name -> config overrides (perfect first: the reference)
STRATEGIES = {
    "perfect": {},
    "loss 20 %": {"message_loss": 0.2},
    "bursts": {"loss_model": "gilbert_elliott"},
    "delay 2": {"max_delay": 2},
    "loss+delay": {"message_loss": 0.2, "max_delay": 2},
    "range 2.5": {"comm_range": 2.5},
    "2 drop-outs": {"dropouts": 2},
}


def cpu(run: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float]:
    """``run(*args, **kwargs)`` and the CPU seconds it took."""
    t0 = time.process_time()
    result = run(*args, **kwargs)
    return result, time.process_time() - t0


def allocate(env: TaskAllocEnv, policy: Any, seed: int) -> Allocation:
    """The seed's allocation: ``taskalloc.policies.fast.solve`` on the seed's instance, or a whole episode without
    it."""
    if solve is None:
        return rollout(env, policy, seed=seed)
    env.reset(seed=seed)
    return solve(env.scenario, env.config, policy)


def scaling_sizes(max_agents: int, max_tasks: int) -> list[tuple[int, int]]:
    """N_SWEEP at M = 2N, then M = f · N for f in M_FACTORS at the largest N kept; all within the limits."""
    ns = [n for n in N_SWEEP if n <= max_agents and 2 * n <= max_tasks] or [min(max_agents, max_tasks // 2)]
    sizes = {(n, 2 * n) for n in ns} | {(ns[-1], f * ns[-1]) for f in M_FACTORS if f * ns[-1] <= max_tasks}
    return sorted(sizes)


def fit_exponents(sizes: Sequence[tuple[int, int]], values: Sequence[float]) -> tuple[float, float] | None:
    """(a, b) of log value = c + a log N + b log M by least squares, or None when N and M do not vary apart."""
    logs = np.log(np.asarray(sizes, dtype=float))
    design = np.column_stack([np.ones(len(logs)), logs])
    if np.linalg.matrix_rank(design) < 3:
        return None
    coef = np.linalg.lstsq(design, np.log(values), rcond=None)[0]
    return float(coef[1]), float(coef[2])


def exponent_cells(sizes: Sequence[tuple[int, int]], values: Sequence[float]) -> list[str]:
    """The fitted exponents of N and M as table cells ("n/a" when they cannot be told apart)."""
    fit = fit_exponents(sizes, values)
    return [f"{x:.2f}" for x in fit] if fit else ["n/a", "n/a"]


def bench_env(seconds: float, seeds: int, repeats: int = 1) -> str:
    """Agent-steps per CPU second (random masked policy) and scripted episodes, default scenario: each seed's
    episode and direct solve timed ``repeats`` times, the fastest kept (the least disturbed by other processes)."""
    policy = make_policy("random")
    env = TaskAllocEnv("default")
    rollout(env, policy, seed=0)                                 # warm-up: compiled kernels, caches
    steps = agent_steps = episodes = 0
    t0 = time.process_time()
    while time.process_time() - t0 < seconds:
        obs, infos = env.reset(seed=episodes)
        policy.start(env, episodes)
        while env.agents:
            actions = policy.act({a: obs[a] for a in env.agents}, {a: infos[a] for a in env.agents})
            obs, *_, infos = env.step(actions)
            steps, agent_steps = steps + 1, agent_steps + len(actions)
        episodes += 1
    elapsed = time.process_time() - t0
    throughput = markdown_table(["policy (default scenario)", "episodes", "env steps / CPU s", "agent-steps / CPU s"],
                                [["random (masked)", episodes, f"{steps / elapsed:,.0f}",
                                  f"{agent_steps / elapsed:,.0f}"]])
    body = []
    for name in ("cbga", "cbgabi"):
        policy = make_policy(name)
        env = TaskAllocEnv("default", **policy.env_overrides)
        rollout(env, policy, seed=0)                             # warm-up
        allocations = [rollout(env, policy, seed=s) for s in range(seeds)]
        episode = [min(cpu(rollout, env, policy, seed=s)[1] for _ in range(repeats)) for s in range(seeds)]
        direct = ([min(cpu(allocate, env, policy, s)[1] for _ in range(repeats)) for s in range(seeds)] if solve
                  else [])
        body.append([name.upper(), seeds, f"{1e3 * statistics.median(episode):.1f}",
                     f"{1e3 * statistics.median(direct):.1f}" if direct else "–",
                     f"{statistics.mean(a.counters.rounds for a in allocations):.2f}",
                     f"{statistics.mean(a.score for a in allocations):.4f}"])
    fastest = f"median over seeds of the fastest of {repeats}" if repeats > 1 else "median"
    episodes_table = markdown_table(["scripted, default scenario", "seeds", f"episode (env) CPU ms, {fastest}",
                                     f"direct solve CPU ms, {fastest}", "rounds, mean", "score, mean"], body)
    return f"{throughput}\n{episodes_table}"


def bench_scaling(sizes: Sequence[tuple[int, int]], seeds: int, memory: bool, solvers: Sequence[str]) -> str:
    """CPU seconds per solve and rounds (or, with ``memory``, tracemalloc peak MB) of each solver at each size."""
    chosen = {label: spec for label, spec in SOLVERS.items() if spec[0] in solvers}
    figures: dict[str, dict[tuple[int, int], tuple[float, float]]] = {label: {} for label in chosen}
    for name, agents_per_task in chosen.values():               # warm-up: compiled kernels, caches
        policy = make_policy(name)
        allocate(TaskAllocEnv(n_agents=10, n_tasks=20, agents_per_task=agents_per_task, **policy.env_overrides),
                 policy, 0)
    for n, m in sizes:
        for label, (name, agents_per_task) in chosen.items():
            policy = make_policy(name)
            env = TaskAllocEnv(n_agents=n, n_tasks=m, agents_per_task=agents_per_task, **policy.env_overrides)
            if memory:
                tracemalloc.start()
                allocation = allocate(env, policy, 0)
                figures[label][n, m] = (tracemalloc.get_traced_memory()[1] / 1e6, allocation.counters.rounds)
                tracemalloc.stop()
            else:
                runs = [cpu(allocate, env, policy, s) for s in range(seeds)]
                figures[label][n, m] = (statistics.median(t for _, t in runs),
                                        statistics.mean(a.counters.rounds for a, _ in runs))
    unit = "peak MB" if memory else "s"
    header = ["agents × tasks", *(f"{label} {unit}" for label in chosen)]
    sizes_l = sorted({spec[1] for spec in chosen.values()})
    if memory:
        header += [*(f"one N·M·L group table MB (L = {size})" for size in sizes_l), "one N·N·M float64 array MB"]
    else:
        header += [f"{label.split()[0]} rounds" for label in chosen]
    body = []
    for n, m in sizes:
        row = [f"{n} × {m}", *(f"{figures[label][n, m][0]:.4g}" for label in chosen)]
        row += ([*(f"{1e-6 * n * m * (16 * size + 16):.3g}" for size in sizes_l), f"{8e-6 * n * n * m:.3g}"] if memory
                else [f"{figures[label][n, m][1]:.1f}" for label in chosen])
        body.append(row)
    fits = []
    top = max(n for n, _ in sizes)
    large = [s for s in sizes if 2 * s[0] >= top]
    for subset, points in (("all", sizes), (f"N ≥ {top // 2}", large))[: 1 if large == list(sizes) else 2]:
        for label in chosen:        # small sizes carry fixed costs: the fit on the largest ones is the steeper
            values = [figures[label][size][0] for size in points]
            per_round = [v / max(figures[label][size][1], 1) for v, size in zip(values, points)]
            fits.append([label, subset, *exponent_cells(points, values),
                         *([] if memory else exponent_cells(points, per_round))])
    what = "peak memory" if memory else "CPU s per solve"
    fit_header = ["solver", "sizes fitted", f"{what}: exponent of N", "exponent of M"]
    if not memory:
        fit_header += ["per round: exponent of N", "per round: exponent of M"]
    return f"{markdown_table(header, body)}\n{markdown_table(fit_header, fits)}"


def bench_strategies(seeds: int, scenario: str = "default", solver: str = "cbga") -> dict[str, dict[str, float]]:
    """CPU time per episode, rounds and messages of every strategy on the same seeds; printed as ratios to perfect."""
    policy = make_policy(solver)
    envs = {name: TaskAllocEnv(scenario, **overrides, **policy.env_overrides) for name, overrides in STRATEGIES.items()}
    for env in envs.values():                  # warm-up: compiled kernels, caches
        rollout(env, policy, seed=0)
    runs: dict[str, list[tuple[Allocation, float]]] = {name: [] for name in STRATEGIES}
    for seed in range(seeds):
        for name, env in envs.items():         # interleaved: load changes hit every strategy alike
            runs[name].append(cpu(rollout, env, policy, seed=seed))
    figures = {name: {"seconds": statistics.mean(t for _, t in r),
                      "rounds": statistics.mean(a.counters.rounds for a, _ in r),
                      "messages": statistics.mean(a.counters.messages for a, _ in r)} for name, r in runs.items()}
    base = figures["perfect"]
    body = [[name, *(f"{f[k] * (1e3 if k == 'seconds' else 1):.1f} (x{f[k] / base[k]:.2f})"
                     for k in ("seconds", "rounds", "messages"))] for name, f in figures.items()]
    print(f"## Network strategies: scenario {scenario}, {solver.upper()}, {seeds} seeds (mean per episode; x = ratio "
          f"to perfect)\n\n{markdown_table(['strategy', 'CPU ms', 'rounds', 'messages'], body)}")
    return figures


def parse_size(text: str) -> tuple[int, int]:
    """'100x500' -> (100, 500)."""
    try:
        n, m = (int(x) for x in text.lower().replace("×", "x").split("x"))
    except ValueError:
        raise ConfigError(f"--max-size {text!r}: expected AGENTSxTASKS, e.g. 100x500") from None
    if n < 1 or m < 2:
        raise ConfigError(f"--max-size {text!r}: needs at least 1 agent and 2 tasks")
    return n, m


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line and exit status 2 (through ``run_cli``)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise ConfigError(message)


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="python -m benchmarks.bench_env", description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--reference", type=Path, help="path of a CBBA-Python checkout: adds the side-by-side section")
    parser.add_argument("--quick", action="store_true",
                        help="small defaults: " + ", ".join(f"{k.replace('_', '-')} {v}" for k, v in QUICK.items()))
    parser.add_argument("--max-size", help=f"largest AGENTSxTASKS of any section (default {FULL['max_size']})")
    parser.add_argument("--runs", type=int, help=f"instances per reference size (default {FULL['runs']})")
    parser.add_argument("--seeds", type=int,
                        help=f"instances per scaling point and scripted episode (default {FULL['seeds']})")
    parser.add_argument("--seconds", type=float, help=f"CPU seconds of random stepping (default {FULL['seconds']})")
    parser.add_argument("--repeats", type=int, help=f"timings of each scripted episode, the fastest kept (default "
                                                    f"{FULL['repeats']})")
    parser.add_argument("--strategy-seeds", type=int, help=f"seeds per network strategy (default "
                                                           f"{FULL['strategy_seeds']})")
    parser.add_argument("--solvers", default=",".join(spec[0] for spec in SOLVERS.values()),
                        help="comma-separated solvers of the scaling and memory sections (default cbba,cbga,cbgabi)")
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections to run, of {', '.join(SECTIONS)} (default all; reference "
                             "needs --reference)")
    args = parser.parse_args(argv)
    for key, value in (QUICK if args.quick else FULL).items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    max_agents, max_tasks = parse_size(args.max_size)
    sections = [s.strip() for s in args.only.split(",") if s.strip()]
    if unknown := [s for s in sections if s not in SECTIONS]:
        raise ConfigError(f"--only: unknown section {unknown[0]!r} (choose from {', '.join(SECTIONS)})")
    solvers = [s.strip() for s in args.solvers.split(",") if s.strip()]
    if not solvers or not set(solvers) <= {name for name, _ in SOLVERS.values()}:
        raise ConfigError(f"--solvers {args.solvers!r}: choose from cbba, cbga, cbgabi")
    if min(args.runs, args.seeds, args.strategy_seeds, args.repeats) < 1 or args.seconds <= 0:
        raise ConfigError("--runs, --seeds, --strategy-seeds and --repeats must be at least 1 and --seconds positive")
    reference = load_reference(args.reference) if args.reference and "reference" in sections else None

    print(f"machine: {machine()}; CPU time (time.process_time); fast path: "
          f"{'taskalloc.policies.fast.solve' if solve else 'none (env episodes)'}\n", flush=True)
    if reference:
        sizes = [s for s in SIZES if s[0] <= max_agents and s[1] <= max_tasks]
        print(f"## CBBA against CBBA-Python (median CPU s of {args.runs} instances)\n\n"
              f"{reference_table(reference, sizes, args.runs)}", flush=True)
    if "env" in sections:
        print(f"## Environment, default scenario\n\n{bench_env(args.seconds, args.seeds, args.repeats)}", flush=True)
    sizes = scaling_sizes(max_agents, max_tasks)
    if "scaling" in sections:
        print(f"## Scaling: CPU s per solve (median of {args.seeds}), rounds (mean)\n\n"
              f"{bench_scaling(sizes, args.seeds, memory=False, solvers=solvers)}", flush=True)
    if "memory" in sections:
        table = bench_scaling(sizes, 1, memory=True, solvers=solvers)
        high_water = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3        # kB on Linux
        print(f"## Peak memory of one solve (tracemalloc peak, seed 0)\n\n{table}\nprocess high-water mark "
              f"(ru_maxrss, whole run so far): {high_water:.0f} MB\n", flush=True)
    if "strategies" in sections:
        bench_strategies(args.strategy_seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
