"""Where the compiled kernels are kept between processes, and the one line that says when they are compiled.

numba writes a kernel's machine code next to its source (``__pycache__``) unless told otherwise: inside
site-packages for an installed package, a folder that may not be writable and that every reinstall empties. Ours:
the kernels go to ``NUMBA_CACHE_DIR`` when the user sets it, else to the user's cache folder
(``$XDG_CACHE_HOME/taskalloc/numba``, by default ``~/.cache/taskalloc/numba``), so that every later process (an
evaluation worker, the next run) loads them instead of compiling. Inside it, one sub-folder per version of the
kernels' sources (``sources_digest``): numba checks only the file that defines a kernel, but a kernel carries the
machine code of the kernels it calls (the batched step holds the merge), so a change to any kernel file must start
a fresh cache. The first compile of a process prints one line on stderr; a process that finds every kernel in the
cache prints nothing.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any


def cache_dir() -> Path:
    """``NUMBA_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/taskalloc/numba`` (``~/.cache/taskalloc/numba``)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen:
        return Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "taskalloc" / "numba"


def sources_digest(folder: Path = Path(__file__).parent) -> str:
    """12 hex digits of the SHA-256 of every kernel source file (``*.py`` of ``folder``, in name order)."""
    digest = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:12]


def kernel_cache_dir() -> Path:
    """The folder this version of the kernels is cached in: ``cache_dir() / "src-<sources_digest()>"``."""
    return cache_dir() / f"src-{sources_digest()}"


@contextlib.contextmanager
def caching_in(numba: Any, folder: Path) -> Iterator[None]:
    """numba's cache folder set to ``folder`` while kernels are decorated (numba picks a kernel's cache folder when
    it is decorated), then restored: other numba code of the process keeps its own setting."""
    before = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(folder)
    try:
        yield
    finally:
        numba.config.CACHE_DIR = before


class CompileNotice:
    """Counts this process's compiles of our kernels (cache misses) and announces the first one on stderr."""

    def __init__(self) -> None:
        self.kernels: set[int] = set()          # ids of our dispatchers
        self.compiles = 0

    def watch(self, dispatcher: Any) -> Any:
        self.kernels.add(id(dispatcher))
        return dispatcher

    def on_start(self, event: Any) -> None:
        if id(event.data["dispatcher"]) not in self.kernels:
            return
        if self.compiles == 0:
            print(f"taskalloc: compiling the numba kernels, once (later processes load them from {cache_dir()})",
                  file=sys.stderr, flush=True)
        self.compiles += 1

    def listen(self) -> None:
        """Hear numba's ``numba:compile`` events (numba broadcasts one per compile, none for a cache load)."""
        from numba.core import event

        notice = self

        class Listener(event.Listener):
            def on_start(self, ev: event.Event) -> None:
                notice.on_start(ev)

            def on_end(self, ev: event.Event) -> None:
                """Nothing to do when a compile ends."""

        event.register("numba:compile", Listener())
