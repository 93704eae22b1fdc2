"""What a learned run cost to train: agent steps, wall and CPU seconds, read from its training ``summary.yaml``.

Every training stack of the project writes ``summary.yaml`` beside the checkpoint it saves (``taskalloc mappo``,
``taskalloc train``, ``taskalloc rllib train``, ``taskalloc benchmarl train``); the benchmark copies the cost of each
``learned:`` run into its summary so the leaderboard can print it beside the scores. The stacks name the figures
differently; ``STEP_KEYS`` lists where each keeps its agent steps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from taskalloc.policies.learned import resolve

# where a stack's summary.yaml keeps the agent steps it trained for (MAPPO: steps; SB3: ppo.steps; others: agent_steps)
STEP_KEYS = (("agent_steps",), ("steps",), ("ppo", "steps"))


def _lookup(data: dict[str, Any], path: tuple[str, ...]) -> Any:
    for key in path:
        if not isinstance(data, dict) or key not in data:
            return None
        data = data[key]
    return data


def training_cost(policy: str) -> dict[str, Any] | None:
    """``learned:<name or path>`` → ``{"agent_steps", "wall_seconds", "cpu_seconds", "command"}`` from the summary
    beside its checkpoint; ``None`` for other policies or a checkpoint saved without one."""
    if not policy.lower().startswith("learned:"):
        return None
    source = Path(resolve(policy.split(":", 1)[1]))
    folder = source.parent if source.suffix == ".json" else source
    path = folder / "summary.yaml"
    if not path.is_file():
        return None
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    steps = next((v for keys in STEP_KEYS if (v := _lookup(data, keys)) is not None), None)
    return {"agent_steps": steps, "wall_seconds": data.get("wall_seconds"), "cpu_seconds": data.get("cpu_seconds"),
            "command": data.get("command")}
