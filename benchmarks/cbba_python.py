"""Side by side with the public CBBA-Python (zehuilu/CBBA-Python, MIT licence) on identical instances.

    python -m benchmarks.cbba_python --reference ../shared/anchors/CBBA-Python [--runs 5]

The reference is imported from the path given (it is not part of this project). For each size its own generator
draws an instance (``create_agents_and_tasks`` with time windows, ``..._homogeneous`` without); the instance becomes a
fixed ``Scenario`` (same positions, speeds, windows, durations, rewards; agent and task types as equipment), scored
as the reference scores it: reward · exp(−λ (start − window start)) with λ = 0.1, start times of planned tasks frozen
(``marginal_gain="frozen"``), no travel cost (γ = 0). Both solve it with CBBA: the reference's ``CBBA.solve``, and
this project's CBBA policy with the default consensus mode, both through the environment (``rollout``) and through
the protocol directly (``policies.fast.solve``, the experiments' path). Runs alternate (reference, env, direct, …)
and the medians are compared in the same run, so the ratios hold on a busy machine.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import statistics
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from policies import make_policy, rollout
from policies.fast import solve
from taskalloc_env import Agent, Scenario, Task, TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli

SIZES = ((5, 10, True), (10, 50, True), (20, 100, True), (10, 50, False), (20, 100, False))
TIME_DISCOUNT = 0.1


def load_reference(root: Path) -> tuple[Any, Any, Any, dict]:
    """The reference's CBBA class, WorldInfo, helper library and example config, imported from ``root``."""
    lib = root / "lib"
    if not (lib / "CBBA.py").is_file():
        raise ConfigError(f"--reference {str(root)!r}: no lib/CBBA.py there (the CBBA-Python checkout)")
    sys.path.insert(0, str(lib))
    import HelperLibrary
    from CBBA import CBBA
    from WorldInfo import WorldInfo

    config = json.loads((root / "config_example_01.json").read_text())
    return CBBA, WorldInfo, HelperLibrary, config


def reference_instance(helpers: Any, world_info: Any, config: dict, n_agents: int, n_tasks: int, windows: bool,
                       seed: int) -> tuple[Any, list, list]:
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - the reference draws from the legacy global generator
    world = world_info([-2.0, 2.5], [-1.5, 5.5], [0.0, 20.0])
    make = helpers.create_agents_and_tasks if windows else helpers.create_agents_and_tasks_homogeneous
    with contextlib.redirect_stdout(io.StringIO()):
        agents, tasks = make(n_agents, n_tasks, world, config)
    return world, agents, tasks


def to_scenario(agents: list, tasks: list, config: dict, windows: bool) -> Scenario:
    """The reference's instance as a fixed Scenario (its compatibility rule: quads track, cars rescue)."""
    agent_types, task_types = config["AGENT_TYPES"], config["TASK_TYPES"]
    needs = {task_types.index("track"): "quad", task_types.index("rescue"): "car"}
    a = [Agent((float(x.x), float(x.y), float(x.z)), float(x.nom_velocity),
               (agent_types[x.agent_type],) if windows else ()) for x in agents]
    t = [Task((float(x.x), float(x.y), float(x.z)), float(x.task_value), float(x.start_time),
              float(x.end_time) if windows else 1e9, float(x.duration), 1,
              (needs[x.task_type],) if windows else ()) for x in tasks]
    return Scenario.from_entities(a, t, time_discount=TIME_DISCOUNT, distance_discount=0.0,
                                  equipment_names=("quad", "car") if windows else ())


def measure(reference: tuple, n_agents: int, n_tasks: int, windows: bool, runs: int) -> dict[str, float]:
    cbba_class, world_info, helpers, config = reference
    times: dict[str, list[float]] = {"reference": [], "env": [], "direct": []}
    scores: dict[str, list[float]] = {"reference": [], "env": []}
    policy = make_policy("cbba")
    for seed in range(runs):
        world, agents, tasks = reference_instance(helpers, world_info, config, n_agents, n_tasks, windows, seed)
        scenario = to_scenario(agents, tasks, config, windows)
        env = TaskAllocEnv(scenario=scenario, marginal_gain="frozen")
        t0 = time.process_time()
        with contextlib.redirect_stdout(io.StringIO()):
            solver = cbba_class(config)
            solver.solve(agents, tasks, world, n_tasks, time_window_flag=windows)
        times["reference"].append(time.process_time() - t0)
        t0 = time.process_time()
        allocation = rollout(env, policy, seed=0)
        times["env"].append(time.process_time() - t0)
        t0 = time.process_time()
        direct = solve(scenario, env.config, "cbba")
        times["direct"].append(time.process_time() - t0)
        assert direct == allocation, "the direct path must reach the env's allocation"
        scores["env"].append(allocation.score)
        scores["reference"].append(reference_score(solver, scenario))
    out = {k: statistics.median(v) for k, v in times.items()}
    out["score_ratio"] = float(np.mean(scores["env"]) / np.mean(scores["reference"]))
    return out


def reference_score(solver: Any, scenario: Scenario) -> float:
    """The reference's allocation scored by this project's scorer (its own score has no travel cost either)."""
    from taskalloc_env.allocation import Allocation
    from taskalloc_env.scenario import scenario_config
    from taskalloc_env.scoring import ScoringModel

    paths = [[int(j) for j in path if j >= 0] for path in solver.path_list]
    model = ScoringModel.from_config(scenario, scenario_config(scenario, marginal_gain="frozen"))
    return Allocation.from_paths(model, paths).score


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.cbba_python", description=__doc__.split("\n\n")[0])
    parser.add_argument("--reference", type=Path, required=True, help="path of a CBBA-Python checkout")
    parser.add_argument("--runs", type=int, default=5, help="instances per size (default 5)")
    parser.add_argument("--sizes", default="all", help="all, or e.g. 10x50w,20x100 (w: time windows)")
    args = parser.parse_args(argv)
    reference = load_reference(args.reference)
    sizes = SIZES if args.sizes == "all" else [
        (int(s.rstrip("w").split("x")[0]), int(s.rstrip("w").split("x")[1]), s.endswith("w"))
        for s in args.sizes.split(",")]
    print(f"{'size':>14} {'reference':>10} {'env':>9} {'direct':>9} {'ref/env':>8} {'ref/direct':>10} "
          f"{'score ratio':>11}")
    for n, m, windows in sizes:
        r = measure(reference, n, m, windows, args.runs)
        label = f"{n} × {m}{', windows' if windows else ''}"
        print(f"{label:>14} {r['reference']:9.3f}s {r['env']:8.3f}s {r['direct']:8.3f}s "
              f"{r['reference'] / r['env']:7.1f}× {r['reference'] / r['direct']:9.1f}× {r['score_ratio']:11.3f}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
