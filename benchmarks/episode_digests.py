"""One line per fuzzed episode: a digest of everything the episode returned, to check that a change kept them all.

    python -m benchmarks.episode_digests --episodes 1000 > after.txt
    # the same episodes on another tree (this file run by its path, the other tree's packages first on sys.path):
    (cd ../before && PYTHONPATH=$PWD python ../taskalloc/benchmarks/episode_digests.py --episodes 1000) > before.txt
    diff before.txt after.txt                   # no output: every episode is the same, bit for bit

Each episode draws a configuration with ``taskalloc.evaluation.fuzz.draw_config`` (every option: equipment,
prerequisites, message loss and delay, drop-outs, pop-up tasks, ACBBA) and runs a policy from ``--policies`` in turn
through the PettingZoo environment. The first digest covers every observation, action mask, reward, termination,
truncation, info and ``state()`` from ``reset`` to the end, the second the final ``Allocation`` (paths, start times,
groups, score, counters). A speed change that alters any value, in its last bit too, changes a line.
"""

from __future__ import annotations

import argparse
import hashlib
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.fuzz import draw_config
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, run_cli

POLICIES = ("random", "cbga", "cbgabi", "cbga+tq")


def update(digest: Any, value: Any) -> None:
    """Feed ``value`` (arrays with their dtype, dicts in key order, anything else by its repr) into ``digest``."""
    if isinstance(value, np.ndarray):
        digest.update(str(value.dtype).encode() + np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        for key in sorted(value):
            digest.update(str(key).encode())
            update(digest, value[key])
    else:
        digest.update(repr(value).encode())


def episode(kw: dict[str, Any], name: str, seed: int) -> tuple[str, str]:
    """The digests of one episode's returns and of its final allocation."""
    policy = make_policy(name)
    env = TaskAllocEnv(**kw, **policy.env_overrides, max_cycles=300)
    returns = hashlib.sha256()
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    for value in (observations, infos, env.state()):
        update(returns, value)
    while env.agents:
        step = env.step(policy.act({a: observations[a] for a in env.agents}, {a: infos[a] for a in env.agents}))
        observations, infos = step[0], step[4]
        for value in (*step, env.state()):
            update(returns, value)
    allocation = hashlib.sha256(repr(env.unwrapped.evaluate()).encode())
    return returns.hexdigest()[:16], allocation.hexdigest()[:16]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.episode_digests", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=200, help="fuzzed episodes (default 200)")
    parser.add_argument("--seed", type=int, default=7, help="seed of the draw of configurations (default 7)")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES),
                        help=f"policies taken in turn (default: {' '.join(POLICIES)})")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        raise ConfigError(f"--episodes must be at least 1, got {args.episodes}")
    for name in args.policies:              # an unknown name is refused before any episode runs
        try:
            make_policy(name)
        except ValueError as exc:
            raise ConfigError(f"--policies: {exc}") from None
    rng, extra = np.random.default_rng(args.seed), np.random.default_rng([args.seed, 2])
    with warnings.catch_warnings():         # the fuzzer's degenerate draws warn (e.g. identical tasks)
        warnings.simplefilter("ignore")
        for index in range(args.episodes):
            name = args.policies[index % len(args.policies)]
            print(index, name, *episode(draw_config(rng, extra), name, index), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
