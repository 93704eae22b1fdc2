"""A user's own policy by import path: ``make_policy("mypkg.mymodule:MyPolicy")``, ``taskalloc compare --policy``.

The module is imported with ``importlib`` (from ``sys.path``, then from the current directory, as ``python -m`` would
find it) and the attribute after the colon looked up (dots walk nested attributes). What it names becomes a policy:

- a class is instantiated (with the keyword arguments given to ``make_policy``, usually none);
- a ``Policy`` is used as is; any other object with an ``act(observations, infos)`` method is wrapped, its optional
  ``start(env, seed)``, ``env_overrides`` and ``name`` kept;
- a plain callable ``fn(observations) -> actions`` is wrapped as the policy's ``act``.

Anything else, or a path that does not import, is a ``ConfigError`` naming the path and what is wrong.
"""

from __future__ import annotations

import importlib
import inspect
import os
import re
import sys
from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy
from taskalloc_env.errors import ConfigError

IMPORT_PATH = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")


def is_import_path(name: str) -> bool:
    """``pkg.module:Attribute`` (module and attribute dotted Python names)."""
    return IMPORT_PATH.fullmatch(name) is not None


class PluginPolicy(Policy):
    """A user's object with ``act`` (or a function of the observations) behind the ``Policy`` interface."""

    def __init__(self, target: Any, name: str) -> None:
        super().__init__()
        self.target = target
        own = getattr(target, "name", None)
        self.name = own if isinstance(own, str) and own else name

    @property
    def env_overrides(self) -> dict[str, Any]:
        return dict(getattr(self.target, "env_overrides", None) or {})

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        start = getattr(self.target, "start", None)
        if callable(start):
            start(env, seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        act = getattr(self.target, "act", None)
        return act(observations, infos) if callable(act) else self.target(observations)


def resolve(path: str) -> Any:
    """The object ``path`` (``module:attribute``) names; ``ConfigError`` if it does not import or has no such name."""
    if not is_import_path(path):
        raise ConfigError(f"policy {path!r}: an import path is written module:attribute, e.g. mypkg.mymodule:MyPolicy")
    module_name, _, attribute = path.partition(":")
    module = _import(module_name, path)
    target: Any = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise ConfigError(f"policy {path!r}: module {module_name!r} has no attribute {attribute!r}")
        target = getattr(target, part)
    return target


def load_plugin(path: str, **kwargs: Any) -> Policy:
    """The policy ``path`` names (see the module docstring); ``kwargs`` go to a class's constructor."""
    target = resolve(path)
    if inspect.isclass(target):
        try:
            target = target(**kwargs)
        except TypeError as exc:
            raise ConfigError(f"policy {path!r}: the class cannot be built with {kwargs or 'no arguments'} ({exc})"
                              ) from None
    elif kwargs:
        raise ConfigError(f"policy {path!r}: options {sorted(kwargs)} are only taken by a class")
    if isinstance(target, Policy):
        if target.name == Policy.name:          # the base class's placeholder: name the row by its path
            target.name = path
        return target
    if callable(getattr(target, "act", None)) or _observations_function(target):
        return PluginPolicy(target, path)
    raise ConfigError(f"policy {path!r}: names a {type(target).__name__}; expected a policy class, an object with "
                      "act(observations, infos), or a function of the observations")


def _observations_function(target: Any) -> bool:
    """A function (not a class) taking the observations as its one positional argument."""
    if not callable(target):
        return False
    try:
        inspect.signature(target).bind(None)
    except (TypeError, ValueError):
        return False
    return True


def _import(module_name: str, path: str) -> Any:
    """Import ``module_name``; if it is not found on ``sys.path``, the current directory is appended to ``sys.path``
    (after the installed packages, so a user's file never shadows them) and the import tried again."""
    here = os.getcwd()
    try:
        return _import_once(module_name, path)
    except ModuleNotFoundError as exc:
        if exc.name != module_name.split(".")[0] or "" in sys.path or here in sys.path:
            raise ConfigError(f"policy {path!r}: module {module_name!r} cannot be imported ({exc})") from None
    sys.path.append(here)
    try:
        return _import_once(module_name, path)
    except ModuleNotFoundError as exc:
        raise ConfigError(f"policy {path!r}: module {module_name!r} is neither on sys.path nor in the current "
                          f"directory ({exc})") from None


def _import_once(module_name: str, path: str) -> Any:
    """``importlib.import_module``; an error the user's module raises while importing becomes a ``ConfigError``."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError:
        raise
    except Exception as exc:
        raise ConfigError(f"policy {path!r}: importing {module_name!r} failed: {type(exc).__name__}: {exc}") from None
