"""Views of an allocation: a text table (``ansi``) and the thesis's figure (``rgb_array``, ``human``).

The figure follows the thesis's plots (e.g. Fig 3.4–3.12): time on the horizontal axis, x position on the
vertical one; each task is a bar spanning its start window at its x position (coloured by the agents it needs,
hatched when it is not valid), each agent a line through the tasks on its own path.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.allocation import Allocation
from taskalloc_env.scenario import Scenario


def ansi_table(scenario: Scenario, allocation: Allocation) -> str:
    """One line per task: window, L_j, members, validity; then per agent its path; then the figures."""
    lines = [f"{'task':>5} {'window':>15} {'L':>3} {'valid':>5}  members"]
    valid = set(allocation.valid_tasks)
    for j in range(scenario.n_tasks):
        window = f"{scenario.task_start[j]:6.1f}-{scenario.task_end[j]:6.1f}"
        members = ", ".join(f"uav_{i}" for i in allocation.members[j]) or "-"
        lines.append(f"{j:>5} {window:>15} {scenario.task_agents[j]:>3} {'yes' if j in valid else 'no':>5}  {members}")
    lines.append("")
    for i, (path, starts) in enumerate(zip(allocation.paths, allocation.start_times)):
        steps = " -> ".join(f"T{j}@{t:.1f}" for j, t in zip(path, starts)) or "(idle)"
        lines.append(f"uav_{i}: {steps}")
    figures = allocation.summary()
    lines.append("")
    lines.append("  ".join(f"{k}={v:.2f}" if isinstance(v, float) else f"{k}={v}" for k, v in figures.items()))
    return "\n".join(lines)


def figure(scenario: Scenario, allocation: Allocation, title: str = ""):
    """A matplotlib Figure of x position against time (Agg canvas, no display needed)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 5), dpi=80)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    levels = sorted(set(int(v) for v in scenario.task_agents))
    colours = {lv: f"C{k % 10}" for k, lv in enumerate(levels)}
    valid = set(allocation.valid_tasks)
    finite_end = np.where(np.isfinite(scenario.task_end), scenario.task_end,
                          scenario.task_start + scenario.task_duration)
    for j in range(scenario.n_tasks):
        x = scenario.task_pos[j, 0]
        ax.barh(x, finite_end[j] - scenario.task_start[j], left=scenario.task_start[j], height=0.08,
                color=colours[int(scenario.task_agents[j])], alpha=0.8 if j in valid else 0.3,
                hatch=None if j in valid else "//", edgecolor="k", linewidth=0.3)
        ax.annotate(f"T{j}", (scenario.task_start[j], x), fontsize=6, xytext=(0, 4), textcoords="offset points")
    for i, (path, starts) in enumerate(zip(allocation.paths, allocation.start_times)):
        if not path:
            continue
        times = [0.0]
        xs = [scenario.agent_pos[i, 0]]
        for j, t in zip(path, starts):
            times += [t, t + scenario.task_duration[j]]
            xs += [scenario.task_pos[j, 0]] * 2
        ax.plot(times, xs, "-", lw=0.8, color=f"C{(i + 3) % 10}", alpha=0.9)
    for lv in levels:
        ax.barh([], [], color=colours[lv], label=f"L={lv}")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_xlabel("time")
    ax.set_ylabel("x position")
    ax.set_title(title or f"score {allocation.score:.1f}, {allocation.n_valid} valid tasks, "
                          f"round {allocation.counters.rounds}")
    fig.tight_layout()
    return fig


def rgb_array(scenario: Scenario, allocation: Allocation) -> np.ndarray:
    """The figure as an H × W × 3 uint8 array."""
    fig = figure(scenario, allocation)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()
