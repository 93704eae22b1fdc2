"""Seed ranges: which instances are for training, validation, demonstrations and held-out tests.

Seed s draws the same instance for every policy (``reset(seed=s)`` generates it before any policy acts), so a range
of seeds is a fixed set of problems. Held-out test seeds ``10_000 …`` (the tables in ``docs/learning.md``) are never
seen in training; training's periodic evaluation uses validation seeds ``20_000 …``; training instances come from
the env copies' seeding (copy c of an SB3 run with seed s starts from ``s + c``, of a MAPPO run from
``1000 · s + c``) and behaviour cloning's demonstrations
from ``100_000 …``. Comparisons and experiments use seeds ``0 … N − 1``.
"""

from __future__ import annotations

import argparse

from taskalloc_env.errors import ConfigError

TEST_SEEDS = range(10_000, 10_200)
VALIDATION_SEED_START = 20_000
DEMO_SEED_START = 100_000


def add_heldout_arguments(parser: argparse.ArgumentParser) -> None:
    """``--seed-start`` and ``--episodes``: the held-out seeds a command plays (default: all of ``TEST_SEEDS``)."""
    parser.add_argument("--seed-start", type=int, default=TEST_SEEDS.start,
                        help=f"first held-out seed (default {TEST_SEEDS.start})")
    parser.add_argument("--episodes", type=int, default=len(TEST_SEEDS),
                        help=f"number of held-out seeds (default {len(TEST_SEEDS)})")


def heldout_seeds(args: argparse.Namespace) -> list[int]:
    """The seeds of ``add_heldout_arguments``' options; fewer than one episode is an error naming the option."""
    if args.episodes < 1:
        raise ConfigError(f"--episodes: got {args.episodes}; allowed: an integer >= 1")
    return list(range(args.seed_start, args.seed_start + args.episodes))
