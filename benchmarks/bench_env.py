"""Environment benchmarks: the marginal-gain kernel, env steps per second, time to converge, network strategies.

    python -m benchmarks.bench_env            # full run (about a minute)
    python -m benchmarks.bench_env --quick    # a few seconds

Machines are noisy, so the kernel is compared with a naive per-insertion loop *in the same run* (the ratio is the
figure to quote). Convergence times are medians over seeds of a whole episode through the PettingZoo env with
the scripted CBGA policy (observations, masks, rewards included); they are printed next to the reference figures
quoted in the project's issue for a public pure-Python CBBA on these machines (0.16 s for 10 × 50, 1.4 s for
20 × 100, time windows), with the load average so a busy machine is visible. The network strategies
(``network.Network``: loss, bursts, delay, range, drop-outs) run the default scenario with CBGA on the same seeds,
interleaved seed by seed so that a change in the machine's load hits every strategy alike, and are printed as ratios
to ``perfect`` links: time per episode, rounds and messages.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli
from taskalloc_env.scoring import ScoringModel

REFERENCE_SECONDS = {(10, 50): 0.16, (20, 100): 1.4}
# the communication strategies of the default scenario: name -> config overrides (perfect first: the reference)
STRATEGIES = {
    "perfect": {},
    "loss 20 %": {"message_loss": 0.2},
    "bursts": {"loss_model": "gilbert_elliott"},
    "delay 2": {"max_delay": 2},
    "loss+delay": {"message_loss": 0.2, "max_delay": 2},
    "range 2.5": {"comm_range": 2.5},
    "2 drop-outs": {"dropouts": 2},
}


def naive_gains(model: ScoringModel, agent: int, path: list[int]) -> np.ndarray:
    """(3.11) by brute force: re-time the whole path for every task and every slot."""
    base = model.schedule(agent, path).score
    gains = np.zeros(model.scenario.n_tasks)
    for j in range(model.scenario.n_tasks):
        if j in path:
            continue
        for n in range(len(path) + 1):
            trial = model.schedule(agent, [*path[:n], j, *path[n:]])
            if trial.feasible:
                gains[j] = max(gains[j], trial.score - base)
    return gains


def bench_kernel(repeats: int) -> None:
    env = TaskAllocEnv(n_agents=10, n_tasks=50, agents_per_task=1)
    policy = make_policy("cbga")
    rollout(env, policy, seed=0)
    protocol = env.unwrapped.protocol
    paths = [list(p) for p in protocol.knowledge.paths]
    model = protocol.model
    agent = int(np.argmax([len(p) for p in paths]))
    assert np.allclose(naive_gains(model, agent, paths[agent]), model.insertion_gains(agent, paths[agent])[0])
    t0 = time.perf_counter()
    for _ in range(repeats):
        naive_gains(model, agent, paths[agent])
    naive = (time.perf_counter() - t0) / repeats
    t0 = time.perf_counter()
    for _ in range(repeats * 20):
        model.plan([agent], [paths[agent]])
    one = (time.perf_counter() - t0) / (repeats * 20)
    t0 = time.perf_counter()
    for _ in range(repeats * 20):
        model.plan(range(len(paths)), paths)
    batch = (time.perf_counter() - t0) / (repeats * 20)
    print(f"marginal gains, 50 tasks, path of {len(paths[agent])}: naive loop {naive * 1e3:.2f} ms, "
          f"vectorised {one * 1e3:.3f} ms (x{naive / one:.0f}); all 10 agents batched {batch * 1e3:.3f} ms "
          f"(x{10 * naive / batch:.0f} per agent)")


def bench_steps(seconds: float) -> None:
    for scenario in ("default", "train_small"):
        for name in ("random", "cbga"):
            policy = make_policy(name)
            env = TaskAllocEnv(scenario)
            steps, episodes = 0, 0
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < seconds:
                obs, infos = env.reset(seed=episodes)
                policy.start(env, episodes)
                while env.agents:
                    obs, *_ , infos = env.step(policy.act(obs, infos))
                    steps += 1
                episodes += 1
            elapsed = time.perf_counter() - t0
            print(f"env steps/s  {scenario:12s} {name:7s} {steps / elapsed:8.0f}  "
                  f"({steps} steps, {episodes} episodes, {env.config.n_agents} agents per step)")


def bench_convergence(sizes: list[tuple[int, int, int]]) -> None:
    policy = make_policy("cbga")
    for n_agents, n_tasks, seeds in sizes:
        env = TaskAllocEnv(n_agents=n_agents, n_tasks=n_tasks, agents_per_task=1)
        times, rounds = [], []
        for seed in range(seeds):
            t0 = time.perf_counter()
            allocation = rollout(env, policy, seed=seed)
            times.append(time.perf_counter() - t0)
            rounds.append(allocation.counters.rounds)
            if not allocation.converged:
                print(f"  seed {seed} did not converge")
        median = statistics.median(times)
        ref = REFERENCE_SECONDS.get((n_agents, n_tasks))
        versus = f", reference {ref:.2f} s -> x{ref / median:.1f}" if ref else ""
        print(f"time to converge {n_agents:3d} x {n_tasks:3d} (L=1, windows): median {median:.3f} s over {seeds} "
              f"seeds, {statistics.median(rounds):.0f} rounds{versus}")


def bench_strategies(seeds: int, scenario: str = "default", solver: str = "cbga") -> dict[str, dict[str, float]]:
    """Time per episode, rounds and messages of every strategy on the same seeds; printed as ratios to perfect."""
    policy = make_policy(solver)
    envs = {name: TaskAllocEnv(scenario, **overrides, **policy.env_overrides) for name, overrides in STRATEGIES.items()}
    times = {name: [] for name in STRATEGIES}
    rounds = {name: [] for name in STRATEGIES}
    messages = {name: [] for name in STRATEGIES}
    for seed in range(seeds):
        for name, env in envs.items():         # interleaved: load changes hit every strategy alike
            t0 = time.perf_counter()
            allocation = rollout(env, policy, seed=seed)
            times[name].append(time.perf_counter() - t0)
            rounds[name].append(allocation.counters.rounds)
            messages[name].append(allocation.counters.messages)
    figures = {name: {"seconds": statistics.mean(times[name]), "rounds": statistics.mean(rounds[name]),
                      "messages": statistics.mean(messages[name])} for name in STRATEGIES}
    base = figures["perfect"]
    print(f"network strategies, scenario {scenario}, {solver.upper()}, {seeds} seeds (mean per episode; x = ratio "
          "to perfect):")
    for name, f in figures.items():
        print(f"  {name:12s} {1e3 * f['seconds']:7.1f} ms (x{f['seconds'] / base['seconds']:.2f})  "
              f"{f['rounds']:5.1f} rounds (x{f['rounds'] / base['rounds']:.2f})  "
              f"{f['messages']:6.0f} messages (x{f['messages'] / base['messages']:.2f})")
    return figures


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="a few seconds: fewer repeats, no 100 x 500")
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    bench_kernel(repeats=2 if args.quick else 10)
    bench_steps(seconds=1.0 if args.quick else 5.0)
    sizes = [(10, 50, 5), (20, 100, 2)] if args.quick else [(10, 50, 50), (20, 100, 10), (100, 500, 2)]
    bench_convergence(sizes)
    bench_strategies(seeds=5 if args.quick else 40)


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
