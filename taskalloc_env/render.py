"""Views of an allocation: a text table (``ansi``) and the thesis's figure (``rgb_array``, ``human``).

The figure follows the thesis's plots (e.g. Fig 3.4–3.12): time on the horizontal axis, x position on the
vertical one; each task is a bar spanning its start window at its x position (coloured by the agents it needs,
hatched when it is not valid), each agent a line through the tasks on its own path.
"""

from __future__ import annotations

import matplotlib
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


UNITS = {"km_min": ("min", "km"), "raw": ("time units", "distance units")}   # per TaskAllocConfig.units
LABEL_STEP = 9          # points between stacked task labels
MAX_AGENT_KEYS = 12     # agents listed in the legend; more are summarised in one entry


def figure(scenario: Scenario, allocation: Allocation, title: str = "", units: str = "km_min"):
    """A matplotlib Figure of x position against time (Agg canvas, no display needed).

    Each task is a bar over its start window at its x position, coloured by L_j; a valid task is solid, a task
    that is not valid (too few members, missing equipment or prerequisites) is faded and hatched. Each agent is a
    line from its start through the tasks on its own path.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    time_unit, distance_unit = UNITS[units]
    fig = Figure(figsize=(10, 6), dpi=90, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    levels = sorted(set(int(v) for v in scenario.task_agents))
    shades = np.linspace(0.45, 0.8, len(levels)) if len(levels) > 1 else [0.6]
    colours = {lv: matplotlib.colormaps["Greys"](float(shade)) for lv, shade in zip(levels, shades)}
    valid = set(allocation.valid_tasks)
    finite_end = np.where(np.isfinite(scenario.task_end), scenario.task_end,
                          scenario.task_start + scenario.task_duration)
    height = 0.02 * float(np.ptp(np.r_[scenario.task_pos[:, 0], scenario.agent_pos[:, 0]]) or 1.0)
    placed: list[tuple[float, float, int]] = []
    span = float(np.ptp(np.r_[scenario.task_start, finite_end]) or 1.0)
    for j in np.argsort(scenario.task_start, kind="stable"):
        x = scenario.task_pos[j, 0]
        ax.barh(x, finite_end[j] - scenario.task_start[j], left=scenario.task_start[j], height=height,
                color=colours[int(scenario.task_agents[j])], alpha=0.85 if j in valid else 0.3,
                hatch=None if j in valid else "///", edgecolor="k", linewidth=0.4)
        # stack labels that would overlap an earlier one (close in both time and position)
        level = sum(1 for t, y, _ in placed
                    if abs(t - scenario.task_start[j]) < 0.04 * span and abs(y - x) < 3 * height)
        placed.append((scenario.task_start[j], x, level))
        ax.annotate(f"T{j}", (scenario.task_start[j], x), fontsize=7, xytext=(0, 4 + LABEL_STEP * level),
                    textcoords="offset points")
    for i, (path, starts) in enumerate(zip(allocation.paths, allocation.start_times)):
        times, xs = [0.0], [scenario.agent_pos[i, 0]]
        for j, t in zip(path, starts):
            times += [t, t + scenario.task_duration[j]]
            xs += [scenario.task_pos[j, 0]] * 2
        ax.plot(times, xs, "-", lw=1.0, color=_agent_colour(i), alpha=0.9)
        ax.plot(times[:1], xs[:1], "o", ms=3, color=_agent_colour(i))
    task_keys = [Patch(facecolor=colours[lv], edgecolor="k", label=f"task, L_j = {lv}") for lv in levels]
    task_keys += [Patch(facecolor="white", edgecolor="k", label="valid (solid)"),
                  Patch(facecolor="white", edgecolor="k", hatch="///", alpha=0.5, label="not valid (faded, hatched)")]
    n = scenario.n_agents
    agent_keys = [Line2D([], [], color=_agent_colour(i), label=f"uav_{i}") for i in range(min(n, MAX_AGENT_KEYS))]
    if n > MAX_AGENT_KEYS:
        agent_keys.append(Line2D([], [], color="grey", label=f"… {n - MAX_AGENT_KEYS} more agents"))
    fig.legend(handles=task_keys, loc="outside right upper", fontsize=8, title="tasks")
    fig.legend(handles=agent_keys, loc="outside right lower", fontsize=8, title="agents (paths)")
    ax.set_xlabel(f"time ({time_unit})")
    ax.set_ylabel(f"x position ({distance_unit})")
    ax.set_title(title or f"score {allocation.score:.1f}, {allocation.n_valid} of {scenario.n_tasks} tasks valid, "
                          f"round {allocation.counters.rounds}")
    ax.grid(alpha=0.2)
    return fig


def _agent_colour(i: int) -> tuple[float, ...]:
    """Agents take qualitative colours (tab10, then tab20 beyond ten agents); tasks are shades of grey."""
    return matplotlib.colormaps["tab10" if i < 10 else "tab20"](i % (10 if i < 10 else 20))


def rgb_array(scenario: Scenario, allocation: Allocation, units: str = "km_min") -> np.ndarray:
    """The figure as an H × W × 3 uint8 array."""
    fig = figure(scenario, allocation, units=units)
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()
