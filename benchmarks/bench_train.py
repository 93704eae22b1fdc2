"""Training throughput per algorithm: agent steps per second while PPO trains (rollouts and updates together).

    python -m benchmarks.bench_train                              # SB3 MaskablePPO and our MAPPO loop
    python -m benchmarks.bench_train --algos sb3 mappo rllib      # RLlib too (pip install taskalloc[ray])
    python -m benchmarks.bench_train --algos sb3 --n-procs 0 2    # SB3 with its copies in 0 and 2 subprocesses
    python -m benchmarks.bench_train --algos sb3 --torch-threads 1 2   # SB3 updates on one core and on two

Every algorithm trains on ``train_small`` (4 agents) for about ``--steps`` agent steps from a fresh network, one
torch thread unless ``--torch-threads`` says otherwise (SB3):

* ``sb3``: ``taskalloc.training.train`` with ``configs/training/train_small.yaml`` (MaskablePPO, pooling actor and a
critic
  on the local observation, 8 copies = 32 slots, 10 epochs);
* ``mappo``: ``taskalloc.training.mappo`` with ``configs/training/mappo_small.yaml`` (attention actor, critic on
  ``env.state()``, 16 copies, 8 epochs), and with ``mappo_small_pooling.yaml`` (pooling actor);
* ``rllib``: ``taskalloc.training.rllib_ppo`` (RLlib PPO, new API stack, attention actor, sampling in the driver process
  with 4 env copies, 4 epochs), including its own framework overhead but not Ray's start.

An *agent step* is one decision of one agent in one env step (what SB3 and RLlib count as agent timesteps); *env
steps* = agent steps / 4. The figures cover the whole training call (collection and updates). The load average is
printed before and after because the machine may be shared: the figures are only comparable within one run.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable, Sequence

import torch as th

from taskalloc_env.errors import ConfigError, run_cli

ALGOS = ("sb3", "mappo", "rllib")
AGENTS = 4      # train_small


def bench_sb3(steps: int, n_procs: int, out_dir: str, torch_threads: int = 1) -> dict[str, float]:
    from taskalloc.training.train import build_model, load_config
    from taskalloc.training.vec_env import TaskAllocVecEnv, make_env_fns

    cfg = load_config(["--config", "train_small", "--n-procs", str(n_procs), "--no-tensorboard",
                       "--no-progress-bar", "--out-dir", out_dir, "--torch-threads", str(torch_threads)])
    th.set_num_threads(cfg.torch_threads)
    venv = TaskAllocVecEnv(make_env_fns(cfg.n_envs, **cfg.env_kwargs()), n_procs=n_procs)
    model = build_model(cfg, venv)
    t0 = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - t0
    venv.close()
    return {"agent_steps": model.num_timesteps, "seconds": seconds}


def bench_mappo(steps: int, config: str, out_dir: str) -> dict[str, float]:
    from taskalloc.training import mappo

    summary = mappo.main(["--config", config, "--total-steps", str(steps), "--eval-freq", "0", "--eval-episodes",
                          "1", "--out-dir", out_dir])
    return {"agent_steps": summary["steps"], "seconds": summary["train_seconds"]}


def bench_rllib(steps: int, out_dir: str) -> dict[str, float]:
    from taskalloc.training import rllib_ppo

    batch = 1024                            # env steps per iteration = 4096 agent steps
    summary = rllib_ppo.main(["train", "--out-dir", out_dir, "--iterations",
                              str(max(1, steps // (batch * AGENTS))), "--train-batch", str(batch),
                              "--eval-episodes", "1"])
    return {"agent_steps": summary["iterations"][-1]["agent_steps"], "seconds": summary["train_seconds"]}


def main(argv: Sequence[str] | None = None) -> list[dict[str, float | str]]:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bench_train", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--algos", nargs="+", choices=ALGOS, default=["sb3", "mappo"],
                        help="algorithms to measure (default: sb3 mappo; rllib needs pip install taskalloc[ray])")
    parser.add_argument("--steps", type=int, default=40_960, help="agent steps per measurement (default 40 960)")
    parser.add_argument("--n-procs", type=int, nargs="+", default=[0],
                        help="sb3 only: subprocesses for the env copies, one measurement each (default 0)")
    parser.add_argument("--torch-threads", type=int, nargs="+", default=[1],
                        help="sb3 only: torch threads, one measurement each (default 1; 2 uses both cores in the "
                             "updates)")
    args = parser.parse_args(argv)
    if args.steps < 4096:
        raise ConfigError(f"--steps: got {args.steps}; allowed: an integer >= 4096 (one rollout of every algorithm)")
    cases: list[tuple[str, Callable[[str], dict[str, float]]]] = []
    for algo in args.algos:
        if algo == "sb3":
            cases += [(f"SB3 MaskablePPO, pooling, n_procs {k}, torch threads {t}",
                       lambda out, k=k, t=t: bench_sb3(args.steps, k, out, t))
                      for k in args.n_procs for t in args.torch_threads]
        elif algo == "mappo":
            cases += [("MAPPO (training.mappo), attention", lambda out: bench_mappo(args.steps, "mappo_small", out)),
                      ("MAPPO (training.mappo), pooling",
                       lambda out: bench_mappo(args.steps, "mappo_small_pooling", out))]
        else:
            cases.append(("RLlib PPO, attention", lambda out: bench_rllib(args.steps, out)))
    print(f"load average before: {os.getloadavg()[0]:.2f}  (cores: {os.cpu_count()})", flush=True)
    results = []
    for label, run in cases:
        before = os.times()
        with tempfile.TemporaryDirectory() as out:
            measured = run(out)
        after = os.times()
        cpu = sum(after[:4]) - sum(before[:4])      # user + system, this process and its waited-for children
        rate = measured["agent_steps"] / measured["seconds"]
        results.append({"algorithm": label, **measured, "agent_steps_per_s": rate, "cpu_seconds": cpu,
                        "agent_steps_per_cpu_s": measured["agent_steps"] / cpu})
        print(f"{label:<40} {measured['agent_steps']:>8} agent steps {measured['seconds']:>8.1f} s "
              f"{rate:>8.0f} agent steps/s {rate / AGENTS:>7.0f} env steps/s  (whole call: {cpu:.1f} CPU s, "
              f"{measured['agent_steps'] / cpu:.0f} agent steps per CPU s)", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return results


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
