"""Johnson's ACBBA experiments (Johnson §4.1.3, Figs 4-2 to 4-5) and ACBBA against synchronous CBBA.

    taskalloc acbba-experiments profiles --seeds 20     # Figs 4-2, 4-3, 4-4: message profiles
    taskalloc acbba-experiments sweep --seeds 10        # Fig 4-5: messages, convergence, separation time
    taskalloc acbba-experiments versus --seeds 50       # ACBBA vs CBBA, perfect and faulty links
    taskalloc acbba-experiments all --overwrite         # the three, into results/acbba/ (replacing them)

Johnson's setting (§4.1.3, extraction lines 916–939): "8 agents, with a maximum bundle size of 5, bidding on 35
tasks"; all tasks at the start (Fig 4-2), or "an initial allocation of 10 tasks ... then every 0.2 seconds after, a
single pop-up task" (Fig 4-3), or every 50 ms (Fig 4-4). One message is one broadcast, "no matter how many vehicles
hear" it (line 921). Units Johnson does not give, chosen here (docs/decisions.md): one tick is 1 ms, so 0.2 s is
200 ticks and the profiles are binned in 10 ms (a pop-up burst here lasts about 12 ms against Johnson's "a little
less than 0.1 seconds", so 50 ms arrivals are still slower than a burst; the fourth profile keeps Johnson's ratio of
arrival period to burst length instead, a release every 5 ms); the pop-up runs release the same 35 tasks (10 + 25
pop-ups); the task field is the repository's default scenario with single-agent tasks and DMG scores
(``marginal_gain="frozen"``, ``distance_cost="from_start"``; Johnson's scoring is CBBA's, line 908). Every run uses
the scripted ``acbba`` policy and ends when the network is quiet (``termination="global"``), so that the whole
profile is recorded. ``profiles`` also measures local convergence while the pop-ups are negotiated ("certain agents
can be in a converged state even though others are still actively engaging in a consensus phase", line 939): per
pop-up the agents that broadcast, that bid and whose bundle changed for good, and the ticks with broadcasts at which
some agent had declared itself converged, under each ``local_convergence`` (``CLOCKS``; the broadcasts are the same
under both, only the declarations move).

Each command prints markdown tables (pasted into docs/results.md) and writes them, the per-run CSV and the PNGs to
``--out`` (default ``results/acbba``).

Where the settings live: in this module, not in ``configs/experiments/``. ``JOHNSON`` is the config every run shares
(on top of the default scenario), ``PROFILES`` the pop-up schedules of Figs 4-2 to 4-4, ``CLOCKS`` the settings of
``local_convergence`` compared there, ``SWEEP_TASKS`` and ``SWEEP_AGENTS`` the points of Fig 4-5, ``FAULTS`` the
networks of the comparison with CBBA, ``DEFAULT_SEEDS`` the seeds per point, ``TICK_MS`` and ``BIN`` the units;
the 1,000 random scenarios are ``acbba_check.scenario(seed)``.
They are not experiment files because the experiment runner (``taskalloc.evaluation.experiments``) tabulates per-episode
scalar metrics paired across series, while these figures need the per-broadcast tick log binned into profiles,
bursts per pop-up, correlations across seeds, and a path-by-path comparison of two solvers' allocations on one seed;
expressing them there would mean new metric kinds in the runner for three figures.
"""

from __future__ import annotations

import argparse
import csv
import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.evaluation.report import markdown_table
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli

TICK_MS = 1.0                   # our unit: one tick is 1 ms of Johnson's wall clock
BIN = 10                        # profile bins of 10 ticks (Johnson: "a large spike within the first 10 ms")
JOHNSON = {"n_agents": 8, "n_tasks": 35, "agents_per_task": 1, "max_bundle": 5, "distance_cost": "from_start",
           "marginal_gain": "frozen", "consensus": "acbba", "termination": "global"}
PROFILES = {
    "Fig 4-2: all 35 tasks at the start": {},
    "Fig 4-3: 10 tasks, then one every 0.2 s": {"popup_tasks": 25, "popup_period": 200},
    "Fig 4-4: 10 tasks, then one every 0.05 s": {"popup_tasks": 25, "popup_period": 50},
    "Fig 4-4 regime: one every 5 ms (< a burst)": {"popup_tasks": 25, "popup_period": 5},
}
CLOCKS = ("bundle", "table")          # local_convergence: the default first
FAULTS = {"perfect links": {}, "20 % loss": {"message_loss": 0.2}, "delay 0–3 ticks": {"max_delay": 3},
          "20 % loss + delay 0–3": {"message_loss": 0.2, "max_delay": 3}}


# -- one episode ------------------------------------------------------------------------------------------------------
def episode(args: tuple[str, dict[str, Any], int]) -> dict[str, Any]:
    """Run ``policy`` on ``config`` with ``seed``; the figures and, for ACBBA, the broadcast ticks."""
    policy, config, seed = args
    env = TaskAllocEnv(**config)
    agent = make_policy(policy)
    obs, infos = env.reset(seed=seed)
    agent.start(env, seed)
    steps = changed_step = 0
    local = _LocalWatch(env) if env.config.asynchronous else None
    while env.agents:                       # env steps: the common unit (one decision per agent per step)
        last = env.protocol.counters.rounds_to_agreement
        if local:
            local.before()
        obs, _, _, _, infos = env.step(agent.act({a: obs[a] for a in env.agents}, infos))
        if local:
            local.after()
        steps += 1
        changed_step = steps if env.protocol.counters.rounds_to_agreement != last else changed_step
    alloc = env.evaluate()
    c, p = alloc.counters, env.protocol
    row = {"policy": policy, "seed": seed, "score": alloc.score, "converged": alloc.converged,
           "conflicts": len(alloc.conflicts), "agreement": alloc.agreement, "paths": alloc.paths,
           "link_messages": c.messages_sent, "received": c.messages, "changed": c.rounds_to_agreement,
           "time": c.rounds, "steps": steps, "changed_step": changed_step}
    if env.config.asynchronous:
        row.update(broadcasts=c.broadcasts, quiet=c.quiet_tick, local=c.local_tick, separation=c.separation_ticks,
                   records=sum(items for _, _, items in p.broadcast_log) / 4, time=c.quiet_tick,
                   ticks=[t for t, _, _ in p.broadcast_log], items=[n for _, _, n in p.broadcast_log],
                   senders=[k for _, k, _ in p.broadcast_log], releases=sorted(set(p.release_tick.tolist()) - {0}),
                   **local.summary())
    else:                       # every live agent broadcasts its table once per round
        row.update(broadcasts=c.rounds * env.config.n_agents)
    return row


class _LocalWatch:
    """Per tick of an asynchronous episode: the agents declared locally converged at the ticks with broadcasts (from
    the first pop-up on, when there are pop-ups); the agents whose bundle changed between two pop-up releases, at any
    tick (bidders) and for good (net); declarations, and those broken: the agent's bundle changed afterwards with no
    pop-up released in between (a premature declaration)."""

    def __init__(self, env: TaskAllocEnv) -> None:
        self.p = env.protocol
        self.releases = sorted(set(self.p.release_tick.tolist()) - {0})
        self.traffic = self.declared_traffic = self.declared_agents = 0
        self.series: list[int] = []                    # agents declared after each tick
        self.bundles = self._bundles()
        self.start = self.bundles                      # the bundles when the current pop-up was released
        self.moved: set[int] = set()
        self.bidders: list[int] = []
        self.net: list[int] = []
        self.armed = np.zeros(len(self.bundles), dtype=bool)   # declared since the last pop-up and bundle change
        self.declarations = self.broken = 0

    def _bundles(self) -> list[tuple[int, ...]]:
        return [tuple(b) for b in self.p.knowledge.bundles]

    def before(self) -> None:
        self.tick, self.declared = self.p.round, self.p.agents_locally_converged.copy()

    def after(self) -> None:
        p = self.p
        popups = self.tick >= (self.releases[0] if self.releases else 0)
        if popups and p.broadcast_log and p.broadcast_log[-1][0] == self.tick:    # broadcasts at this tick
            self.traffic += 1
            self.declared_traffic += bool(self.declared.any())
            self.declared_agents += int(self.declared.sum())
        self.series.append(int(p.agents_locally_converged.sum()))
        now = self._bundles()
        if p.round in self.releases:                   # a pop-up: close the interval of the previous one
            self._close(now)
            self.armed[:] = False                      # new information: a declaration may end
        changed = np.array([b != c for b, c in zip(self.bundles, now)])
        self.broken += int((changed & self.armed).sum())           # declared, then the bundle changed
        self.armed &= ~changed
        declared = p.agents_locally_converged
        self.declarations += int((declared & ~self.armed).sum())
        self.armed |= declared
        self.moved |= set(np.flatnonzero(changed).tolist())
        self.bundles = now

    def _close(self, now: list[tuple[int, ...]]) -> None:
        if self.p.round != self.releases[0]:
            self.bidders.append(len(self.moved))
            self.net.append(sum(b != c for b, c in zip(self.start, now)))
        self.start, self.moved = now, set()

    def summary(self) -> dict[str, Any]:
        if self.releases:
            self._close(self._bundles())
        return {"traffic": self.traffic, "declared_traffic": self.declared_traffic,
                "declared_agents": self.declared_agents, "declarations": self.declarations, "broken": self.broken,
                "declared_series": self.series,
                "popup_bidders": self.bidders, "popup_net": self.net}


def run_all(cases: list[tuple[str, dict[str, Any], int]], jobs: int) -> list[dict[str, Any]]:
    return list(parallel_map(episode, cases, jobs))


def mean_sd(values: Sequence[float], digits: int = 0) -> str:
    values = np.asarray(values, dtype=float)
    return f"{values.mean():.{digits}f} ± {values.std(ddof=1) if len(values) > 1 else 0.0:.{digits}f}"


LISTS = ("ticks", "senders", "releases", "paths", "declared_series", "popup_bidders", "popup_net")


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    keys = [k for k in rows[0] if k not in LISTS]
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)


# -- Figs 4-2, 4-3, 4-4 -----------------------------------------------------------------------------------------------
def bursts(row: dict[str, Any]) -> tuple[list[int], list[float], list[int]]:
    """Per pop-up release until the next one: broadcasts, task records broadcast, and how long the burst lasted."""
    ticks, records = np.asarray(row["ticks"]), np.asarray(row["items"]) / 4
    edges = [*row["releases"], np.inf]
    sizes, carried, lengths = [], [], []
    for start, nxt in itertools.pairwise(edges):
        inside = (ticks >= start) & (ticks < nxt)
        sizes.append(int(inside.sum()))
        carried.append(float(records[inside].sum()))
        lengths.append(int(ticks[inside].max() - start + 1) if inside.any() else 0)
    return sizes, carried, lengths


def popup_agents(row: dict[str, Any]) -> list[int]:
    """Per pop-up release until the next one: how many agents broadcast."""
    ticks, senders = np.asarray(row["ticks"]), np.asarray(row["senders"])
    edges = [*row["releases"], np.inf]
    return [len(set(senders[(ticks >= start) & (ticks < nxt)].tolist())) for start, nxt in itertools.pairwise(edges)]


def profiles(seeds: int, jobs: int, out: Path) -> str:
    runs = [(name, clock) for name, extra in PROFILES.items() for clock in CLOCKS
            if clock == CLOCKS[0] or extra]           # the other clocks only where pop-ups are negotiated
    cases = [("acbba", {**JOHNSON, **PROFILES[name], "local_convergence": clock}, s)
             for name, clock in runs for s in range(seeds)]
    rows = run_all(cases, jobs)
    for row, (name, clock) in zip(rows, [run for run in runs for _ in range(seeds)]):
        row["experiment"], row["local_convergence"] = name, clock
    write_csv(out / "profiles.csv", rows)
    body = []
    for name in PROFILES:
        cell = [r for r in rows if r["experiment"] == name and r["local_convergence"] == CLOCKS[0]]
        second = [np.asarray(r["ticks"]) < 1000 / TICK_MS for r in cell]
        line = [name, f"{sum(r['converged'] for r in cell)}/{len(cell)}",
                f"{mean_sd([r['broadcasts'] for r in cell])} ({mean_sd([r['records'] for r in cell])})",
                f"{mean_sd([s.sum() for s in second])} "
                f"({mean_sd([np.asarray(r['items'])[s].sum() / 4 for r, s in zip(cell, second)])})",
                mean_sd([r["quiet"] * TICK_MS for r in cell])]
        if cell[0]["releases"]:
            per = [bursts(r) for r in cell]
            sizes = [n for b in per for n in b[0]]
            carried = [n for b in per for n in b[1]]
            lengths = [n for b in per for n in b[2]]
            quiet_between = np.mean([max(b[2]) < r["releases"][1] - r["releases"][0] for b, r in zip(per, cell)])
            line += [f"{mean_sd(sizes, 1)} ({mean_sd(carried, 1)})", mean_sd(np.asarray(lengths) * TICK_MS, 1),
                     f"{100 * quiet_between:.0f} %"]
        else:
            line += ["–", "–", "–"]
        body.append(line)
    _plot_profiles([r for r in rows if r["local_convergence"] == CLOCKS[0]], out)
    header = ["experiment (8 agents, L = 5, 35 tasks)", "quiet", "broadcasts (task records)",
              "in the first second", "quiet at (ms)", "per pop-up", "pop-up burst (ms)",
              "runs quiet before each next pop-up"]
    return markdown_table(header, body) + "\n\n" + _local_table(rows, runs)


def _local_table(rows: list[dict[str, Any]], runs: list[tuple[str, str]]) -> str:
    """Local convergence while the pop-ups are negotiated (Johnson l. 939), per pop-up profile and clock."""
    body = []
    for name, clock in runs:
        cell = [r for r in rows if r["experiment"] == name and r["local_convergence"] == clock]
        if not cell[0]["releases"]:
            continue
        traffic = sum(r["traffic"] for r in cell)
        declared = sum(r["declared_traffic"] for r in cell)
        body.append([name, clock, mean_sd([n for r in cell for n in popup_agents(r)], 1),
                     mean_sd([n for r in cell for n in r["popup_bidders"]], 1),
                     mean_sd([n for r in cell for n in r["popup_net"]], 1), str(traffic),
                     f"{declared} ({100 * declared / max(traffic, 1):.1f} %)",
                     f"{sum(r['declared_agents'] for r in cell) / max(traffic, 1):.2f}",
                     f"{sum(r['broken'] for r in cell)} of {sum(r['declarations'] for r in cell)}"])
    return markdown_table(["pop-ups (8 agents, L = 5, 35 tasks)", "local_convergence", "agents broadcasting per "
                           "pop-up", "agents bidding per pop-up", "bundles changed for good per pop-up",
                           "ticks with broadcasts from the first pop-up", "… with an agent locally converged",
                           "agents converged at those ticks (mean)",
                           "declarations broken by a bundle change before the next pop-up"], body)


def _plot_profiles(rows: list[dict[str, Any]], out: Path) -> None:
    """Broadcasts per 10-ms bin for seed 0: Fig 4-2 (whole run), 4-3 and 4-4 (first second, and the whole run), with
    the number of agents locally converged after each tick (green)."""
    names = list(PROFILES)
    fig, axes = plt.subplots(len(names), 2, figsize=(12, 3 * len(names)))
    for ax_row, name in zip(axes, names):
        row = next(r for r in rows if r["experiment"] == name and r["seed"] == 0)
        ticks = np.asarray(row["ticks"])
        end = max(int(ticks.max(initial=0)) + BIN, 100)
        for ax, limit in zip(ax_row, (min(end, 1000), end)):
            width = 2 if limit <= 200 else BIN           # short runs: 2-ms bins
            counts, edges = np.histogram(ticks, bins=np.arange(0, limit + width, width))
            ax.bar(edges[:-1] * TICK_MS / 1000, counts, width=width * TICK_MS / 1000, align="edge", color="tab:blue")
            for release in row["releases"]:
                if release <= limit:
                    ax.axvline(release * TICK_MS / 1000, color="tab:red", lw=0.5, alpha=0.5)
            ax.set_xlabel("time (s; 1 tick = 1 ms)")
            ax.set_ylabel(f"broadcasts per {width} ms")
            declared = np.asarray(row["declared_series"][:limit])      # after ticks 1, 2, ...
            twin = ax.twinx()
            twin.step(np.arange(1, declared.size + 1) * TICK_MS / 1000, declared, where="post", color="tab:green",
                      lw=0.8)
            twin.set_ylim(0, JOHNSON["n_agents"] + 0.5)
            twin.set_ylabel("agents locally converged", color="tab:green", fontsize=8)
        ax_row[0].set_title(f"{name}: first second", fontsize=9)
        ax_row[1].set_title(f"{name}: whole run ({row['broadcasts']} broadcasts)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "profiles.png", dpi=110)
    plt.close(fig)


# -- Fig 4-5 ----------------------------------------------------------------------------------------------------------
SWEEP_TASKS = (10, 20, 35, 50, 70)
SWEEP_AGENTS = (4, 6, 8, 10, 14)


def sweep(seeds: int, jobs: int, out: Path) -> str:
    points = [("tasks", n, {"n_agents": 10, "n_tasks": n}) for n in SWEEP_TASKS] + \
             [("agents", n, {"n_agents": n, "n_tasks": 35}) for n in SWEEP_AGENTS]
    cases = [("acbba", {**JOHNSON, **extra}, s) for _, _, extra in points for s in range(seeds)]
    rows = run_all(cases, jobs)
    for row, (axis, n) in zip(rows, [(a, n) for a, n, _ in points for _ in range(seeds)]):
        row["varied"], row["value"] = axis, n
    write_csv(out / "sweep.csv", rows)
    body = []
    for axis, n, _ in points:
        cell = [r for r in rows if r["varied"] == axis and r["value"] == n]
        body.append([f"{axis} = {n}" + (" (10 agents)" if axis == "tasks" else " (35 tasks)"),
                     f"{sum(r['converged'] for r in cell)}/{len(cell)}", mean_sd([r["broadcasts"] for r in cell]),
                     mean_sd([r["quiet"] * TICK_MS for r in cell]), mean_sd([r["separation"] * TICK_MS for r in cell]),
                     f"{_correlation([r['broadcasts'] for r in cell], [r['quiet'] for r in cell]):.2f}"])
    _plot_sweep(rows, out)
    return markdown_table(["point (L = 5)", "quiet", "broadcasts", "convergence (ms)", "separation time (ms)",
                           "corr(broadcasts, time)"], body)


def _correlation(a: Sequence[float], b: Sequence[float]) -> float:
    with np.errstate(invalid="ignore", divide="ignore"):
        return float(np.corrcoef(a, b)[0, 1]) if len(a) > 1 else float("nan")


def _plot_sweep(rows: list[dict[str, Any]], out: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for ax, axis, metric, label in ((axes[0], "tasks", "broadcasts", "broadcasts"),
                                    (axes[1], "tasks", "quiet", "convergence time (ms)"),
                                    (axes[2], "agents", "quiet", "convergence time (ms)")):
        values = SWEEP_TASKS if axis == "tasks" else SWEEP_AGENTS
        for name, key, style in ((label, metric, "o-"), ("separation time (ms)", "separation", "s--")):
            if metric == "broadcasts" and key == "separation":
                continue
            means = [np.mean([r[key] for r in rows if r["varied"] == axis and r["value"] == v]) for v in values]
            sds = [np.std([r[key] for r in rows if r["varied"] == axis and r["value"] == v]) for v in values]
            ax.errorbar(values, means, yerr=sds, fmt=style, capsize=3, label=name)
        ax.set_xlabel(f"number of {axis}" + (" (10 agents)" if axis == "tasks" else " (35 tasks)"))
        ax.legend()
    axes[0].set_title("(a) messages")
    axes[1].set_title("(b) convergence time, tasks varied")
    axes[2].set_title("(c) convergence time, agents varied")
    fig.tight_layout()
    fig.savefig(out / "sweep.png", dpi=110)
    plt.close(fig)


# -- ACBBA against synchronous CBBA -----------------------------------------------------------------------------------
def versus(seeds: int, jobs: int, out: Path) -> str:
    static = {k: v for k, v in JOHNSON.items() if k not in ("consensus", "termination")}
    cases = [(policy, {**static, **faults, **({"consensus": "acbba"} if policy == "acbba" else {})}, s)
             for faults in FAULTS.values() for policy in ("cbba", "acbba") for s in range(seeds)]
    rows = run_all(cases, jobs)
    for row, name in zip(rows, [n for n in FAULTS for _ in range(2 * seeds)]):
        row["network"] = name
    write_csv(out / "versus.csv", rows)
    body = []
    for name in FAULTS:
        cbba = [r for r in rows if r["network"] == name and r["policy"] == "cbba"]
        acbba = [r for r in rows if r["network"] == name and r["policy"] == "acbba"]
        same = sum(a["paths"] == b["paths"] for a, b in zip(acbba, cbba))
        for label, cell in (("CBBA (sync)", cbba), ("ACBBA", acbba)):
            unit = "rounds" if cell is cbba else "ticks"
            body.append([name, label, f"{sum(r['converged'] for r in cell)}/{len(cell)}",
                         f"{sum(r['conflicts'] == 0 and r['agreement'] for r in cell)}/{len(cell)}",
                         mean_sd([r["score"] for r in cell]), f"{same}/{len(cell)}" if cell is acbba else "–",
                         mean_sd([r["broadcasts"] for r in cell]), mean_sd([r["link_messages"] for r in cell]),
                         f"{mean_sd([r['changed'] for r in cell], 1)} {unit}",
                         f"{mean_sd([r['time'] for r in cell], 1)} {unit}",
                         f"{mean_sd([r['changed_step'] for r in cell], 1)} / {mean_sd([r['steps'] for r in cell], 1)}"])
    return markdown_table(["network", "algorithm", "converged", "conflict-free, agreeing", "score",
                           "same allocation as CBBA", "broadcasts", "link messages", "last change", "declared",
                           "env steps: last change / end"], body)


COMMANDS = {"profiles": profiles, "sweep": sweep, "versus": versus}
DEFAULT_SEEDS = {"profiles": 20, "sweep": 10, "versus": 50}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc acbba-experiments",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("command", choices=[*COMMANDS, "all"])
    parser.add_argument("--seeds", type=int, default=None, help="seeds per point (defaults: 20, 10, 50)")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    parser.add_argument("--out", type=Path, default=Path("results/acbba"),
                        help="output folder (a command whose table is there already is refused unless --overwrite)")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of commands run before")
    args = parser.parse_args(argv)
    names = list(COMMANDS) if args.command == "all" else [args.command]
    done = [name for name in names if (args.out / f"{name}.md").exists()]
    if done and not args.overwrite:
        raise ConfigError(f"--out {args.out}: already holds the results of {', '.join(done)}; pass --overwrite to "
                          "replace them, or choose another folder")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in names:
        table = COMMANDS[name](args.seeds or DEFAULT_SEEDS[name], args.jobs, args.out)
        (args.out / f"{name}.md").write_text(table + "\n")
        print(f"## {name}\n\n{table}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
