"""Named files that travel with the package: scenarios, experiments and training configs, committed models.

In a checkout they are the repository's own ``configs/`` and ``models/`` folders, the one copy a user reads and
edits. A built wheel carries the same folders inside the package as ``taskalloc_env/_data/`` (the build copies
them, see ``pyproject.toml``), read through ``importlib.resources``, so ``scenario="default"`` and
``learned:train_small`` work wherever the package is installed.

A *name* is a bare file name without a suffix (``default``, ``fig5_16_l4``); it resolves inside its folder only.
Anything else — a path with a folder or a suffix — is a path and must be given as one.
"""

from __future__ import annotations

import os
import re
import stat
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path

from taskalloc_env.errors import ConfigError

FOLDERS = {"scenarios": "configs/scenarios", "experiments": "configs/experiments", "training": "configs/training",
           "models": "models"}
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")
CHECKOUT = Path(__file__).resolve().parent.parent


def data_root() -> Traversable:
    """The folder holding ``configs/`` and ``models/``: inside the installed package, or the checkout."""
    packaged = resources.files("taskalloc_env") / "_data"
    return packaged if packaged.is_dir() else CHECKOUT


def folder(kind: str) -> Traversable:
    """The folder of one kind of named file (``scenarios``, ``experiments``, ``training``, ``models``)."""
    if kind not in FOLDERS:
        raise ValueError(f"unknown kind of named file {kind!r}; known: {sorted(FOLDERS)}")
    node = data_root()
    for part in FOLDERS[kind].split("/"):
        node = node / part
    return node


def is_name(text: str) -> bool:
    """Whether ``text`` is a bare name (letters, digits, ``_`` and ``-``; no folder, no suffix)."""
    return NAME.fullmatch(text) is not None


def names(kind: str, suffix: str = ".yaml") -> list[str]:
    """The names available in a folder, sorted."""
    node = folder(kind)
    if not node.is_dir():
        return []
    return sorted(entry.name[: -len(suffix)] if suffix else entry.name for entry in node.iterdir()
                  if (entry.name.endswith(suffix) if suffix else entry.is_dir()) and not entry.name.startswith("."))


def named(kind: str, name: str, suffix: str = ".yaml") -> Traversable:
    """The file (or, with ``suffix=""``, the folder) called ``name`` in the folder of ``kind``.

    Raises ``ConfigError`` for a string that is not a bare name, or a name that does not exist, listing what does.
    """
    what = kind.rstrip("s")
    if not is_name(name):
        raise ConfigError(f"{what} name {name!r} is not a bare name (letters, digits, _ and -); give a file as a "
                          f"path ending in {suffix or '/'} instead")
    node = folder(kind) / f"{name}{suffix}"
    if not (node.is_dir() if not suffix else node.is_file()):
        raise ConfigError(f"unknown {what} {name!r}; known: {names(kind, suffix)}")
    return node


def check_file(source: Path | Traversable, limit: int, what: str, error: type[ConfigError] = ConfigError) -> None:
    """Refuse, unopened, a path that is not a regular file (a device such as ``/dev/zero``, a named pipe, a socket,
    reached directly or through a symlink) or whose size (from ``stat``) exceeds ``limit`` bytes. A resource inside
    an installed package is not a path and is only bounded by the read (``read_bounded``)."""
    if not isinstance(source, Path):
        return
    name = str(source)
    try:
        info = os.stat(source)
    except OSError as exc:
        raise error(f"{what} {name!r} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder, not a file" if stat.S_ISDIR(info.st_mode) else "not a regular file (a device, pipe or socket)"
        raise error(f"{what} {name!r} is {kind}")
    if info.st_size > limit:
        raise error(f"{what} {name!r} is {info.st_size} bytes; the limit is {limit}")


def read_bounded(source: Path | Traversable, limit: int, what: str,
                 error: type[ConfigError] = ConfigError) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, checked before it is read (``check_file``).

    The read itself stops at ``limit + 1`` bytes, so a file that grows in between is refused too, never read whole.
    Raises ``error`` (a ``ConfigError``) naming ``what`` and the file.
    """
    check_file(source, limit, what, error)
    try:
        with source.open("rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"{what} {str(source)!r} cannot be read: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise error(f"{what} {str(source)!r} is more than {limit} bytes; the limit is {limit}")
    return data
