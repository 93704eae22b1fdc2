"""Side by side with the public CBBA-Python (zehuilu/CBBA-Python, MIT licence) on identical instances.

    python -m benchmarks.cbba_python --reference ../shared/anchors/CBBA-Python [--runs 5]

The reference is imported from the path given (it is not part of this project). For each size its own generator
draws an instance (``create_agents_and_tasks`` with time windows, ``..._homogeneous`` without); the instance becomes a
fixed ``Scenario`` (same positions, speeds, windows, durations, rewards; agent and task types as equipment), scored
as the reference scores it: reward · exp(−λ (start − window start)) with λ = 0.1, start times of planned tasks frozen
(``marginal_gain="frozen"``), no travel cost (γ = 0). Both solve it with CBBA: the reference's ``CBBA.solve``, and
this project's CBBA policy in each consensus mode (``sync``, the default, and ``every_step``), both through the
environment (``rollout``) and through the protocol directly (``taskalloc.policies.fast.solve``, the experiments' path).
Runs alternate (reference, env, direct, …) and the medians of CPU time (``time.process_time``) are compared in the same
run, so the ratios hold on a busy machine. The allocations are not always equal: the reference breaks ties within ε and
towards lower ids and prunes infeasible tasks its own way, so the table counts the instances whose paths are equal,
those whose scores are equal, and the mean score ratio (ours / reference, both scored by this project's scorer).
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

from taskalloc.evaluation.report import markdown_table
from taskalloc.policies import make_policy, rollout
from taskalloc_env import Agent, Scenario, Task, TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli

try:
    from taskalloc.policies.fast import solve
except ImportError:         # the tree before the speed work (for before/after figures): env rollouts only
    solve = None

SIZES = ((5, 10, True), (10, 50, True), (20, 100, True), (10, 50, False), (20, 100, False))
TIME_DISCOUNT = 0.1
MODES = ("sync", "every_step")


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
    """Median CPU seconds of the reference and of ours (env rollout, direct solve) in each consensus mode, the number
    of instances whose paths (and whose scores) equal the reference's, and the mean score ratio, per mode."""
    cbba_class, world_info, helpers, config = reference
    times: dict[str, list[float]] = {"reference": []}
    out: dict[str, float] = {}
    policy = make_policy("cbba")
    for seed in range(runs):
        world, agents, tasks = reference_instance(helpers, world_info, config, n_agents, n_tasks, windows, seed)
        scenario = to_scenario(agents, tasks, config, windows)
        t0 = time.process_time()
        with contextlib.redirect_stdout(io.StringIO()):
            solver = cbba_class(config)
            solver.solve(agents, tasks, world, n_tasks, time_window_flag=windows)
        times["reference"].append(time.process_time() - t0)
        ref_paths = tuple(tuple(int(j) for j in path if j >= 0) for path in solver.path_list)
        ref_score = reference_score(solver, scenario)
        for mode in MODES:      # interleaved with the reference: a change of load hits every column alike
            env = TaskAllocEnv(scenario=scenario, marginal_gain="frozen", consensus=mode)
            t0 = time.process_time()
            allocation = rollout(env, policy, seed=0)
            times.setdefault(f"{mode} env", []).append(time.process_time() - t0)
            if solve is not None:
                t0 = time.process_time()
                direct = solve(scenario, env.config, "cbba")
                times.setdefault(f"{mode} direct", []).append(time.process_time() - t0)
                assert direct == allocation, "the direct path must reach the env's allocation"
            out[f"{mode} equal"] = out.get(f"{mode} equal", 0) + (allocation.paths == ref_paths)
            out[f"{mode} same score"] = out.get(f"{mode} same score", 0) + bool(np.isclose(allocation.score, ref_score))
            out[f"{mode} score"] = out.get(f"{mode} score", 0.0) + allocation.score / ref_score / runs
    return out | {k: statistics.median(v) for k, v in times.items()}


def reference_table(reference: tuple, sizes: Sequence[tuple[int, int, bool]], runs: int) -> str:
    """The side-by-side table in markdown: CPU seconds (medians over ``runs`` instances), ratios reference / ours,
    instances whose paths (and whose scores) equal the reference's, mean score ratio ours / reference."""
    def ratio(r: dict[str, float], key: str) -> str:
        return f"{r['reference'] / r[key]:.1f}×" if key in r else "–"

    def secs(r: dict[str, float], key: str) -> str:
        return f"{r[key]:.4f}" if key in r else "–"

    measure(reference, 5, 10, True, 1)         # warm-up: imports, compiled kernels, caches
    body = []
    for n, m, windows in sizes:
        r = measure(reference, n, m, windows, runs)
        body.append([f"{n} × {m}{', windows' if windows else ''}", f"{r['reference']:.4f}",
                     *(secs(r, f"{mode} {path}") for mode in MODES for path in ("env", "direct")),
                     *(ratio(r, f"{mode} {path}") for mode in MODES for path in ("env", "direct")),
                     " / ".join(f"{int(r[f'{mode} equal'])}/{runs}" for mode in MODES),
                     " / ".join(f"{int(r[f'{mode} same score'])}/{runs}" for mode in MODES),
                     " / ".join(f"{r[f'{mode} score']:.3f}" for mode in MODES)])
    header = ["size (agents × tasks)", "CBBA-Python s",
              *(f"{mode} {path} s" for mode in MODES for path in ("env", "direct")),
              *(f"ratio {mode} {path}" for mode in MODES for path in ("env", "direct")),
              "equal paths sync / every_step", "equal score sync / every_step", "score ratio sync / every_step"]
    return markdown_table(header, body)


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
    print(reference_table(reference, sizes, args.runs), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
