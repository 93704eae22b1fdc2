"""Training throughput: environment steps per second while MaskablePPO trains (rollouts and updates together).

    python -m benchmarks.bench_train                          # 40 960 steps, 8 copies, in-process and 2 subprocesses
    python -m benchmarks.bench_train --steps 20480 --n-procs 0

Two figures per setting: *agent steps/s* (vector-env transitions: one per learned agent per step, what SB3 counts as
timesteps) and *env steps/s* (parallel-env steps, all agents at once = agent steps / agents per copy), for the whole
``learn()`` call (collection + PPO updates) and for collection alone (the same policy acting, no updates). The load
average is printed because the machine is shared.
"""

from __future__ import annotations

import argparse
import os
import time

import torch as th
from sb3_contrib import MaskablePPO

from taskalloc_env.errors import run_cli
from training.train import build_model, load_config
from training.vec_env import TaskAllocVecEnv, make_env_fns


def collection_rate(model: MaskablePPO, venv: TaskAllocVecEnv, steps: int) -> float:
    """Agent steps per second of acting only (masked policy forward + env step)."""
    obs = venv.reset()
    n = max(1, steps // venv.num_envs)
    t0 = time.perf_counter()
    for _ in range(n):
        kwargs = {"action_masks": venv.action_masks()} if isinstance(model, MaskablePPO) else {}
        actions, _ = model.predict(obs, **kwargs)
        obs, _, _, _ = venv.step(actions)
    return n * venv.num_envs / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> list[dict[str, float]]:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default="configs/training/train_small.yaml")
    parser.add_argument("--steps", type=int, default=40_960)
    parser.add_argument("--n-envs", type=int, default=None, help="env copies (default: the config's)")
    parser.add_argument("--n-procs", type=int, nargs="+", default=[0, 2])
    args = parser.parse_args(argv)
    results = []
    print(f"load average before: {os.getloadavg()[0]:.2f}  (cores: {os.cpu_count()})")
    print(f"{'n_procs':>7} {'slots':>5} {'learn agent-steps/s':>20} {'learn env-steps/s':>18} "
          f"{'collect agent-steps/s':>22}")
    for n_procs in args.n_procs:
        overrides = ["--n-procs", str(n_procs), "--tensorboard", "false", "--progress-bar", "false",
                     "--bc-episodes", "0", "--init-from", "null"]
        if args.n_envs:
            overrides += ["--n-envs", str(args.n_envs)]
        cfg = load_config(["--config", args.config, *overrides])
        th.set_num_threads(cfg.torch_threads)
        venv = TaskAllocVecEnv(make_env_fns(cfg.n_envs, **cfg.env_kwargs()), scripted_agents=cfg.scripted_agents,
                               n_procs=n_procs)
        model = build_model(cfg, venv)
        t0 = time.perf_counter()
        model.learn(args.steps)
        learn_rate = model.num_timesteps / (time.perf_counter() - t0)
        collect = collection_rate(model, venv, args.steps // 2)
        venv.close()
        row = {"n_procs": n_procs, "slots": venv.num_envs, "learn_agent_steps_per_s": learn_rate,
               "learn_env_steps_per_s": learn_rate / venv.agents_per_copy, "collect_agent_steps_per_s": collect}
        results.append(row)
        print(f"{n_procs:>7} {venv.num_envs:>5} {learn_rate:>20.0f} {learn_rate / venv.agents_per_copy:>18.0f} "
              f"{collect:>22.0f}", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return results


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
