"""Figures of single instances: agents, communication ranges, links and the assignment (thesis §4.3, Figs 4.2–4.5).

    taskalloc figures links --overwrite           # results/fig4_2_5_links/*.png, seed picked as below
    taskalloc figures links --seed 7 --out /tmp/links

The thesis shows one instance at a few communication ranges: 10 agents and 20 single-agent tasks (CBBA) at r = 1,
2 and 2.5 (Figs 4.2–4.4), and 10 agents with 10 tasks of L_j = 2 (CBGA) at r = 1 (Fig 4.5); left the agents with
their range circles and links, right the assignment. We draw the same for one generated instance. Two agents are
linked when their distance is at most r (``edge_rule = dist``), i.e. when circles of radius r/2 around them
overlap, so that is the radius drawn (``circles_overlap`` links at 2r: radius r); links are coloured by connected
group. The assignment panel draws each agent's path from its start through its tasks (the x–y plane); a task
with more members than L_j (a conflict between groups that cannot hear each other) is marked with a red ring, a
task nobody completes is grey. Without ``--seed`` the first seed whose network at r = 2 has exactly two groups and
at r = 2.5 is connected is taken (the situations the thesis's Figs 4.3 and 4.4 describe).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from taskalloc.evaluation.episodes import solve
from taskalloc.evaluation.report import refuse_existing
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv, resolve_config
from taskalloc_env.errors import run_cli, seed_argument
from taskalloc_env.network import CommGraph
from taskalloc_env.scenario import generate

# (file name, solver, config overrides, range): the thesis's Figs 4.2–4.5
PANELS = (("fig4_2_cbba_r1.png", "cbba", {"agents_per_task": 1, "n_tasks": 20}, 1.0),
          ("fig4_3_cbba_r2.png", "cbba", {"agents_per_task": 1, "n_tasks": 20}, 2.0),
          ("fig4_4_cbba_r2_5.png", "cbba", {"agents_per_task": 1, "n_tasks": 20}, 2.5),
          ("fig4_5_cbga_l2_r1.png", "cbga", {"agents_per_task": 2, "n_tasks": 10}, 1.0))
COLOURS = plt.get_cmap("tab10")


def pick_seed(base: str = "default", limit: int = 1000) -> int:
    """The first seed whose agents form exactly two groups at r = 2 and one at r = 2.5 (thesis Figs 4.3, 4.4)."""
    cfg = resolve_config(base, n_agents=10)
    for seed in range(limit):
        positions = generate(cfg, np.random.default_rng(seed)).agent_pos
        two = len(np.unique(CommGraph(positions, 2.0).component)) == 2
        if two and len(np.unique(CommGraph(positions, 2.5).component)) == 1:
            return seed
    raise RuntimeError(f"no seed below {limit} gives two groups at r = 2 and one at r = 2.5")


def links_figure(path: Path, solver: str, seed: int, comm_range: float, base: str = "default",
                 **overrides) -> dict[str, float]:
    """One PNG: agents, range circles and links (left), the assignment ``solver`` reaches (right).

    Returns the figures of the run (score, valid tasks, conflicts, groups) for the caption."""
    cfg = resolve_config(base, n_agents=10, comm_range=comm_range, require_known_capacity=True, **overrides)
    policy = make_policy(solver)
    env = TaskAllocEnv(cfg, **policy.env_overrides)
    allocation = solve(policy, env, seed)
    scenario = env.unwrapped.scenario
    graph = env.unwrapped.protocol.graph
    pos = scenario.agent_pos[:, :2]
    groups = {int(c): k for k, c in enumerate(np.unique(graph.component))}
    radius = comm_range / 2 if cfg.edge_rule == "dist" else comm_range
    fig, (left, right) = plt.subplots(1, 2, figsize=(11.5, 5.4))
    width, depth = cfg.arena[0], cfg.arena[1]
    for ax in (left, right):
        ax.set_xlim(-0.6, width + 0.6)
        ax.set_ylim(-0.6, depth + 0.6)
        ax.set_aspect("equal")
        ax.grid(alpha=0.25)
        ax.set_xlabel("x (km)")
        ax.set_ylabel("y (km)")
    for i, (x, y) in enumerate(pos):
        colour = COLOURS(groups[int(graph.component[i])] % 10)
        left.add_patch(plt.Circle((x, y), radius, color=colour, alpha=0.12, lw=0))
        left.add_patch(plt.Circle((x, y), radius, fill=False, color=colour, lw=0.8))
    for i, k in zip(*np.nonzero(np.triu(graph.adjacency))):
        colour = COLOURS(groups[int(graph.component[i])] % 10)
        left.plot(pos[[i, k], 0], pos[[i, k], 1], color=colour, lw=1.6)
    for i, (x, y) in enumerate(pos):
        colour = COLOURS(groups[int(graph.component[i])] % 10)
        left.scatter([x], [y], s=60, color=colour, edgecolor="k", zorder=3)
        left.annotate(str(i), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=8)
    left.set_title(f"r = {comm_range:g} km: {len(groups)} group{'s' if len(groups) > 1 else ''}, "
                   f"{int(graph.adjacency.sum() // 2)} links (circles of radius {radius:g}: overlap = link)",
                   fontsize=9)
    tasks = scenario.task_pos[:, :2]
    valid, conflicts = set(allocation.valid_tasks), set(allocation.conflicts)
    for j, (x, y) in enumerate(tasks):
        done = j in valid or j in conflicts
        right.scatter([x], [y], marker="s", s=36 + 18 * (scenario.task_agents[j] - 1),
                      color="k" if done else "lightgrey", zorder=3)
        if j in conflicts:
            right.scatter([x], [y], s=260, facecolor="none", edgecolor="tab:red", lw=1.8, zorder=4)
        right.annotate(f"T{j}", (x, y), xytext=(4, -9), textcoords="offset points", fontsize=7)
    for i, path_ in enumerate(allocation.paths):
        colour = COLOURS(groups[int(graph.component[i])] % 10)
        xy = np.vstack([pos[i], *(tasks[j] for j in path_)]) if path_ else pos[[i]]
        right.plot(xy[:, 0], xy[:, 1], color=colour, lw=1.2, alpha=0.85)
        right.scatter([pos[i, 0]], [pos[i, 1]], s=60, color=colour, edgecolor="k", zorder=3)
        right.annotate(str(i), pos[i], xytext=(4, 4), textcoords="offset points", fontsize=8)
    l_text = "L_j = 1" if scenario.task_agents.max() == 1 else f"L_j = {int(scenario.task_agents.max())}"
    right.set_title(f"{policy.name}, {scenario.n_tasks} tasks ({l_text}): score {allocation.score:.0f}, "
                    f"{len(valid)} valid, {len(conflicts)} in conflict (red rings)", fontsize=9)
    fig.suptitle(f"seed {seed}: 10 agents, communication range {comm_range:g} km (edge rule {cfg.edge_rule})",
                 fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return {"score": allocation.score, "valid": len(valid), "conflicts": len(conflicts), "groups": len(groups)}


def links(out: Path, seed: int | None = None, panels: Sequence[tuple] = PANELS) -> list[tuple[str, dict]]:
    """Every panel of ``panels`` for one seed (``pick_seed`` if None); returns (file, figures) per panel."""
    seed = pick_seed() if seed is None else seed
    made = []
    for name, solver, overrides, comm_range in panels:
        made.append((name, {"seed": seed, **links_figure(out / name, solver, seed, comm_range, **overrides)}))
    return made


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc figures", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    cmd = sub.add_parser("links", help="agents, ranges, links and assignments of one instance (Figs 4.2–4.5)")
    cmd.add_argument("--seed", type=seed_argument, default=None,
                     help="instance seed (default: the first that fits, above)")
    cmd.add_argument("--out", type=Path, default=Path("results") / "fig4_2_5_links",
                     help="folder for the PNGs (a folder that holds files is refused unless --overwrite)")
    cmd.add_argument("--overwrite", action="store_true", help="replace the files of an existing --out folder")
    args = parser.parse_args(argv)
    refuse_existing(args.out, args.overwrite)
    for name, figures in links(args.out, args.seed):
        print(f"{args.out / name}: " + ", ".join(f"{k} {v:.0f}" if isinstance(v, float) else f"{k} {v}"
                                                for k, v in figures.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
