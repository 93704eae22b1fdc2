"""Fig 3.13: wall time to an allocation against problem size (CBBA, CBGA, the CBGA/CBBA mix, SGAMA).

    python -m benchmarks.bench_allocation_time                    # about 3 minutes; writes results/fig3_13_time/
    python -m benchmarks.bench_allocation_time --seeds 3 --quick  # a few seconds

The thesis plots the computation time of each experiment of Fig 3.11 (CBBA on single-agent tasks, CBGA on two-agent
tasks, a 10/10 mix; 20 tasks, 1–10 agents) and finds that CBGA takes longer (thesis §3.3.3, Fig 3.13). Here one
allocation is one whole episode through the PettingZoo environment with the scripted policy (reset, every bundle
step, every consensus round, observations and masks included), or one call of the centralised SGAMA; the figure is
the median wall time over ``--seeds`` instances, run in this one process one after another. Two sweeps: agents
(20 tasks) and tasks (10 agents). The output names the machine and its load, since timings are only comparable on
the same machine in the same run; they are not tested (a test would fail on a busy machine).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from taskalloc.evaluation.report import markdown_table
from taskalloc.policies import make_policy, rollout, sgama
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli

SOLVERS: dict[str, tuple[str, dict]] = {          # label: (solver, config overrides)
    "CBBA (L=1)": ("cbba", {"agents_per_task": 1}),
    "CBGA (L=2)": ("cbga", {"agents_per_task": 2}),
    "CBGA mix (half L=2)": ("cbga", {}),
    "SGAMA (L=2)": ("sgama", {"agents_per_task": 2}),
}


def machine() -> str:
    """CPU model, cores and the load average: timings only compare within one machine and one run."""
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            model = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), model)
    except OSError:
        pass
    return (f"{model}, {os.cpu_count()} cores, {platform.platform()}, Python {platform.python_version()}; "
            f"load average {os.getloadavg()[0]:.2f}")


def timer(solver: str, n_agents: int, n_tasks: int, overrides: dict) -> Callable[[int], float]:
    """A function of the seed returning the wall seconds of one allocation."""
    if not overrides:       # the mix: half the tasks need two agents (thesis Fig 3.11's third experiment)
        half = n_tasks // 2
        overrides = {"task_mix": [{"count": half, "agents": 2}, {"count": n_tasks - half, "agents": 1}]}
    env = TaskAllocEnv(n_agents=n_agents, n_tasks=n_tasks, **overrides)
    policy = None if solver == "sgama" else make_policy(solver)

    def run(seed: int) -> float:
        start = time.perf_counter()
        if policy is None:
            env.reset(seed=seed)
            sgama(env.scenario, env.config)
        else:
            rollout(env, policy, seed=seed)
        return time.perf_counter() - start
    return run


def sweep(points: list[tuple[int, int]], seeds: int) -> dict[str, list[float]]:
    """Median milliseconds per allocation of every solver at every (agents, tasks) point."""
    out: dict[str, list[float]] = {label: [] for label in SOLVERS}
    for n_agents, n_tasks in points:
        for label, (solver, overrides) in SOLVERS.items():
            if overrides.get("agents_per_task", 1) > n_agents:
                out[label].append(float("nan"))          # no team can form: nothing to allocate
                continue
            run = timer(solver, n_agents, n_tasks, overrides)
            run(seeds)                                   # warm-up: imports, caches, first allocations
            out[label].append(1000 * statistics.median(run(s) for s in range(seeds)))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_allocation_time",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="instances per point (default 20)")
    parser.add_argument("--quick", action="store_true", help="three points per sweep")
    parser.add_argument("--out", type=Path, default=Path("results") / "fig3_13_time",
                        help="folder for table.md and time.png (default results/fig3_13_time)")
    args = parser.parse_args(argv)
    agents = [2, 5, 10] if args.quick else list(range(1, 11))
    tasks = [10, 20, 40] if args.quick else [10, 20, 40, 60, 80]
    before = machine()
    print(f"machine: {before}")
    by_agents = sweep([(n, 20) for n in agents], args.seeds)
    by_tasks = sweep([(10, m) for m in tasks], args.seeds)
    after = os.getloadavg()[0]
    tables = []
    for title, xs, name, results in (("20 tasks, agents varied", agents, "N_n", by_agents),
                                     ("10 agents, tasks varied", tasks, "N_m", by_tasks)):
        body = [[x, *("–" if v != v else f"{v:.1f}" for v in (results[label][k] for label in SOLVERS))]
                for k, x in enumerate(xs)]
        table = markdown_table([name, *SOLVERS], body)
        print(f"\nms per allocation (median of {args.seeds}), {title}\n{table}")
        tables.append(f"### {title}: ms per allocation (median of {args.seeds} instances)\n\n{table}")
    args.out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, xs, name, results in ((axes[0], agents, "agents N_n (20 tasks)", by_agents),
                                  (axes[1], tasks, "tasks N_m (10 agents)", by_tasks)):
        for label in SOLVERS:
            ax.plot(xs, results[label], marker="o", ms=3, label=label)
        ax.set_xlabel(name)
        ax.set_ylabel("ms per allocation (median)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=8)
    fig.suptitle("Fig 3.13: time to an allocation (whole episode through the environment; SGAMA: one solve)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out / "time.png", dpi=110)
    plt.close(fig)
    command = "python -m benchmarks.bench_allocation_time " + " ".join(sys.argv[1:] if argv is None else argv)
    (args.out / "table.md").write_text(
        f"# Fig 3.13: time to an allocation\n\nWritten by `{command.strip()}`. Machine: {before}; load average "
        f"after: {after:.2f}.\n\n" + "\n".join(tables) + "\n![time.png](time.png)\n")
    print(f"\nload average after: {after:.2f}; wrote {args.out / 'table.md'} and {args.out / 'time.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
