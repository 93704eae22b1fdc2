"""The errors the package raises for bad input: each names the field or the action and what is allowed."""

from __future__ import annotations


class ConfigError(ValueError):
    """A configuration field has a bad value or an unknown name, or a config file cannot be read."""


class InvalidActionError(ValueError):
    """An action outside the mask, a missing or unknown agent, or a step outside an episode."""
