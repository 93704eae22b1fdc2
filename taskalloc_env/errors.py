"""The errors the package raises for bad input, each naming the field or the action and what is allowed, and the
one way every command line reports them."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

import yaml


class ConfigError(ValueError):
    """A configuration field has a bad value or an unknown name, or a config file cannot be read."""


class InvalidActionError(ValueError):
    """An action outside the mask, a missing or unknown agent, or a step outside an episode."""


def run_cli(main: Callable[[], object]) -> int:
    """Run a command line's ``main``: bad input (a ``ConfigError``) is one line on stderr and exit status 2."""
    try:
        result = main()
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return result if isinstance(result, int) else 0


def seed_argument(text: str) -> int:
    """An argparse ``type`` for seeds: a non-negative integer (numpy's seeding refuses negative ones)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a seed is a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a non-negative integer, got {value}")
    return value


def mapping_argument(text: str) -> dict[str, Any]:
    """An argparse ``type`` for a YAML mapping on the command line (``'{task_quitting: true, delta: 1}'``)."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise argparse.ArgumentTypeError(f"not a plain YAML mapping ({str(exc).splitlines()[0]})") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a YAML mapping such as '{{task_quitting: true}}', got {text!r}")
    return value
