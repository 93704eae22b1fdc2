"""Throughput of the batched environment (``taskalloc_env.vector_env``) against the single env, in one run.

    python -m benchmarks.bench_vector                         # K = 1, 64, 256, 1024 on default and train_small
    python -m benchmarks.bench_vector --sizes 1 64 --seconds 2 --mappo-iterations 1     # a quick look
    python -m benchmarks.bench_vector --phases 1024           # where a step's time goes, K = 1024

Prints markdown tables:

- env: agent-steps per CPU second with a random masked policy whose actions are drawn with array operations (one
  uniform draw per action, the arg-max over the allowed ones), for the single env (its dict API, one draw per agent:
  the way a PettingZoo user steps it) and the batch at each K on both engines (``arrays``: the compiled step over the
  instance axis; ``instances``: each env in turn), each in a fresh subprocess so that its peak resident memory
  (``ru_maxrss``) is its own; the ratio to the single env is measured in the same run. VMAS's ``simple_spread`` at the
  same K when ``vmas`` is installed (``pip install vmas``).
- phases (``--phases K``): the arrays engine's CPU time per step by phase, on default and train_small: each compiled
  phase, the loss draws, the resets (a new instance drawn in Python and loaded) and the rest (checks, outputs).
- mappo: agent-steps per CPU second of the project's MAPPO loop (``training.mappo``: rollout collection and the PPO
  update with the pooling actor and the state critic, default config) with its copies stepped as separate envs and
  as one batched env, and the share of the time spent collecting rollouts (the rest is the PPO update).

Times are CPU time of the measuring process (``time.process_time``); they compare only within one machine.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.bench_allocation_time import machine
from taskalloc.evaluation.report import markdown_table
from taskalloc_env.errors import run_cli

SCENARIOS = ("default", "train_small")
SIZES = (1, 64, 256, 1024)
ENGINES = ("arrays", "instances")
PHASES = ("apply_actions", "end_rounds", "score_all", "observe_all")


def measure_phases(scenario: str, k: int, seconds: float) -> dict[str, float]:
    """The arrays engine's CPU seconds per step in each phase (the compiled calls of ``kernels.batch``, the loss draws
    in Python, the resets) and in the rest, over ``seconds`` of random masked steps."""
    import taskalloc_env
    from taskalloc_env import env as env_module
    from taskalloc_env import vector_arrays
    from taskalloc_env.kernels import batch

    spent = dict.fromkeys((*PHASES, "loss draws", "resets", "rest"), 0.0)

    def timed(name: str, function: Any) -> Any:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent[name] += time.process_time() - start
        return wrapper

    class Draws:
        """An instance's generator whose draws are timed."""

        def __init__(self, generator: np.random.Generator) -> None:
            self.random = timed("loss draws", generator.random)

    def load(batch_: Any, k_: int, env: Any) -> None:
        plain_load(batch_, k_, env)
        batch_.rngs[k_] = Draws(batch_.rngs[k_])

    name, _, loss = scenario.partition("+")
    venv = taskalloc_env.vector_env(k, scenario=name, engine="arrays", message_loss=0.2 if loss else 0.0)
    rng = np.random.default_rng(0)
    obs, _ = venv.reset(seed=0)
    venv._batch.rngs = [Draws(g) for g in venv._batch.rngs]
    for name in PHASES:
        setattr(batch, name, timed(name, getattr(batch, name)))
    begin, plain_load = env_module.TaskAllocEnv._begin, vector_arrays.ArrayBatch.load
    env_module.TaskAllocEnv._begin = timed("resets", begin)
    vector_arrays.ArrayBatch.load = timed("resets", load)
    steps, start = 0, time.process_time()
    try:
        while time.process_time() - start < seconds:
            mask = obs["action_mask"]
            obs, *_ = venv.step((rng.random(mask.shape) * mask).argmax(axis=2))
            steps += 1
    finally:
        env_module.TaskAllocEnv._begin, vector_arrays.ArrayBatch.load = begin, plain_load
    total = time.process_time() - start
    spent["rest"] = total - sum(spent.values())
    return {name: value / steps for name, value in spent.items()} | {"total": total / steps,
                                                                       "agent_steps": steps * k * venv.n_agents,
                                                                       "cpu": total}


def phases_table(k: int, seconds: float) -> str:
    rows = []
    for scenario in (*SCENARIOS, "default+loss"):
        r = in_subprocess("phases", scenario, k, seconds)
        rate = r["agent_steps"] / r["cpu"]
        cells = [f"{1e3 * r[name]:.2f} ({r[name] / r['total']:.0%})" for name in (*PHASES, "loss draws", "resets",
                                                                                   "rest")]
        rows.append([scenario, str(k), *cells, f"{1e3 * r['total']:.2f}", f"{rate:,.0f}"])
    return markdown_table(["scenario", "K", *[f"{name} ms" for name in PHASES], "loss draws ms", "resets ms",
                           "rest ms", "step ms", "agent-steps / CPU s"], rows)


def measure_single(scenario: str, seconds: float) -> dict[str, Any]:
    """The single env through its dict API, one random allowed action per agent."""
    from taskalloc_env import TaskAllocEnv

    env = TaskAllocEnv(scenario)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    steps, episode, start = 0, 0, time.process_time()
    while time.process_time() - start < seconds:
        actions = {a: int(np.argmax(rng.random(len(o["action_mask"])) * o["action_mask"])) for a, o in obs.items()}
        obs, *_ = env.step(actions)
        steps += len(actions)
        if not env.agents:
            episode += 1
            obs, _ = env.reset(seed=episode)
    return {"agent_steps": steps, "cpu": time.process_time() - start}


def measure_batch(scenario: str, k: int, seconds: float, engine: str = "arrays") -> dict[str, Any]:
    """The batch of K instances on ``engine``, actions drawn for all at once."""
    import taskalloc_env

    venv = taskalloc_env.vector_env(k, scenario=scenario, engine=engine)
    rng = np.random.default_rng(0)
    obs, _ = venv.reset(seed=0)
    steps, start = 0, time.process_time()
    while time.process_time() - start < seconds:
        mask = obs["action_mask"]
        obs, *_ = venv.step((rng.random(mask.shape) * mask).argmax(axis=2))
        steps += k * venv.n_agents
    return {"agent_steps": steps, "cpu": time.process_time() - start}


def measure_vmas(k: int, seconds: float) -> dict[str, Any] | None:
    """VMAS's simple_spread (3 agents) with K batched environments on the CPU, random actions; None without vmas."""
    try:
        import torch
        import vmas
    except ImportError:
        return None
    torch.set_num_threads(1)
    env = vmas.make_env("simple_spread", num_envs=k, device="cpu", continuous_actions=False, seed=0)
    env.reset()
    steps, start = 0, time.process_time()
    while time.process_time() - start < seconds:
        actions = [torch.randint(0, 5, (k,)) for _ in env.agents]
        env.step(actions)
        steps += k * len(env.agents)
    return {"agent_steps": steps, "cpu": time.process_time() - start}


def one(kind: str, scenario: str, k: int, seconds: float) -> dict[str, Any] | None:
    """One measurement (in the calling process) with its peak resident memory."""
    if kind == "phases":
        return measure_phases(scenario, k, seconds)
    if kind == "single":
        result = measure_single(scenario, seconds)
    elif kind.startswith("batch:"):
        result = measure_batch(scenario, k, seconds, kind.split(":")[1])
    else:
        result = measure_vmas(k, seconds)
    if result is not None:
        result["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return result


def in_subprocess(kind: str, scenario: str, k: int, seconds: float) -> dict[str, Any] | None:
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_vector", "--one", kind, scenario, str(k),
                          "--seconds", str(seconds)], check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def env_table(sizes: Sequence[int], seconds: float) -> str:
    rows = []
    for scenario in SCENARIOS:
        single = in_subprocess("single", scenario, 1, seconds)
        base = single["agent_steps"] / single["cpu"]
        rows.append([scenario, "single env (dict API)", "1", f"{base:,.0f}", "1.0", f"{single['peak_mb']:.0f}"])
        for engine in ENGINES:
            for k in sizes:
                r = in_subprocess(f"batch:{engine}", scenario, k, seconds)
                rate = r["agent_steps"] / r["cpu"]
                rows.append([scenario, f"vector_env ({engine})", str(k), f"{rate:,.0f}", f"{rate / base:.1f}",
                             f"{r['peak_mb']:.0f}"])
    for k in sizes:
        r = in_subprocess("vmas", "simple_spread", k, seconds)
        if r is None:
            rows.append(["VMAS simple_spread", "not installed (pip install vmas)", str(k), "", "", ""])
            break
        rows.append(["VMAS simple_spread", "vmas, CPU", str(k), f"{r['agent_steps'] / r['cpu']:,.0f}", "",
                     f"{r['peak_mb']:.0f}"])
    return markdown_table(["scenario", "environment", "K", "agent-steps / CPU s", "× single env", "peak MB"], rows)


def mappo_rate(batched: bool, copies: int, iterations: int) -> float:
    """Agent-steps per CPU second of MAPPO iterations (collect + update) on train_small with ``copies`` copies."""
    import torch as th

    from taskalloc.training import mappo
    from taskalloc_env import TaskAllocEnv

    th.set_num_threads(1)
    cfg = mappo.MappoConfig()
    group = mappo.Group({"scenario": "train_small", "copies": copies}, cfg.env_overrides, cfg.max_cycles, 0)
    if not batched:                               # the copies as separate envs (the loop before the batched env)
        group.batch = None
        group.envs = [TaskAllocEnv(**group.env_kwargs, max_cycles=cfg.max_cycles, reward_scale=group.reward_scale)
                      for _ in range(copies)]
    group.reset()
    actor = mappo.make_actor(cfg, group.layout.own_size, group.layout.task_size)
    model = mappo.ActorCritic(actor, mappo.StateCritic(group.layout.n_equipment, cfg.hidden, cfg.heads))
    optimizer = th.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5)
    rng = np.random.default_rng(0)
    collecting = updating = 0.0
    for _ in range(iterations):
        start = time.process_time()
        rollout = mappo.collect(model, group, cfg.n_steps, cfg.gamma, cfg.gae_lambda)
        middle = time.process_time()
        mappo.update(model, optimizer, [rollout], cfg, rng)
        collecting, updating = collecting + middle - start, updating + time.process_time() - middle
    steps = iterations * cfg.n_steps * copies * group.n_agents
    return steps / (collecting + updating), collecting / (collecting + updating)


def mappo_table(copies: int, iterations: int) -> str:
    separate, separate_share = mappo_rate(False, copies, iterations)
    batched, batched_share = mappo_rate(True, copies, iterations)
    return markdown_table(["MAPPO on train_small", "copies", "agent-steps / CPU s", "× separate envs",
                           "share of time collecting"],
                          [["separate envs", str(copies), f"{separate:,.0f}", "1.0", f"{separate_share:.0%}"],
                           ["vector_env", str(copies), f"{batched:,.0f}", f"{batched / separate:.2f}",
                            f"{batched_share:.0%}"]])


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_vector", description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), help="batch sizes K")
    parser.add_argument("--seconds", type=float, default=5.0, help="CPU seconds per measurement")
    parser.add_argument("--mappo-copies", type=int, default=64)
    parser.add_argument("--mappo-iterations", type=int, default=3)
    parser.add_argument("--phases", type=int, metavar="K", help="only the arrays engine's time by phase at K")
    parser.add_argument("--one", nargs=3, metavar=("KIND", "SCENARIO", "K"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        kind, scenario, k = args.one
        print(json.dumps(one(kind, scenario, int(k), args.seconds)))
        return
    print(f"machine: {machine()}\n")
    if args.phases:
        print(phases_table(args.phases, args.seconds))
        return
    print(env_table(args.sizes, args.seconds), "\n", flush=True)
    print(mappo_table(args.mappo_copies, args.mappo_iterations))


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
