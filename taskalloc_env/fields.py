"""The facts of every config field, and what is generated from them: validation, option values and the docs tables.

A :class:`Field` states one field once: its kind, bounds, choices, default, one-line meaning, source and group.
The groups are declared by concern in ``taskalloc_env/options/`` (generation, scoring, protocol, network, pop-ups,
asynchronous consensus, observation), each beside the modules that read them; ``taskalloc_env.config`` assembles
the flat ``TaskAllocConfig`` from them. The limits below are ours (docs/decisions.md "config limits"):

* ``MAX_MAGNITUDE``: every real value within ±1e9, so distances, times and their sums stay finite;
* ``MAX_HORIZON``: every time-like field (rounds or ticks) at most 10^5, so no accepted value makes an episode wait
  hours for a release or overflow an int64 tick; the default round bound is a few thousand;
* ``MAX_COUNT``: agent and task counts at most 10^6, so no count overflows an array size before the memory check;
* error messages print values through ``bounded_repr`` (at most ``MAX_REPR`` characters), so printing a value never
  costs more than the value's first few items.

Regenerate the tables of docs/configuration.md from the facts::

    python -m taskalloc_env.options --docs docs/configuration.md
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import reprlib
from collections.abc import Sequence
from typing import Any

from taskalloc_env.errors import ConfigError

MAX_MAGNITUDE = 1e9
MAX_HORIZON = 100_000
MAX_COUNT = 1_000_000
MAX_REPR = 80

KINDS = ("int", "number", "probability", "choice", "bool", "name", "ints", "numbers", "names", "record")
_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxstring, _REPR.maxother = 3, 6, 6, 4, 40, 40
_REPR.maxlong = 40


def bounded_repr(value: Any) -> str:
    """``repr(value)`` cut to at most ``MAX_REPR`` characters, without ever building the full text."""
    text = _REPR.repr(value)
    return text if len(text) <= MAX_REPR else text[: MAX_REPR - 3] + "..."


def fail(field: str, value: Any, allowed: str) -> None:
    """Raise the one-line ``ConfigError`` of a bad value (the value printed bounded)."""
    raise ConfigError(f"config field {field!r}: got {bounded_repr(value)}; allowed: {allowed}")


@dataclasses.dataclass(frozen=True)
class Field:
    """One config field: what it holds (``kind`` with its ``low``/``high`` bounds, ``choices``, sequence
    ``length``), its ``default``, its ``meaning`` and ``source`` (docs/configuration.md) and its ``group``.
    ``time_like`` fields count rounds or ticks and stay within ``MAX_HORIZON``; ``optional`` ones accept None;
    ``shape`` says what a sequence must look like. ``strict``/``strict_high`` exclude the bound itself."""

    name: str
    kind: str
    default: Any
    meaning: str
    source: str
    low: float = -math.inf
    high: float = math.inf
    strict: bool = False
    strict_high: bool = False
    choices: tuple[str, ...] = ()
    optional: bool = False
    length: int | None = None
    scalar: bool = False
    time_like: bool = False
    shape: str = ""
    group: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name}: unknown kind {self.kind!r}")
        if self.time_like and self.high == math.inf:
            object.__setattr__(self, "high", MAX_HORIZON)
        if self.kind in ("number", "numbers") and self.high == math.inf:
            object.__setattr__(self, "high", MAX_MAGNITUDE)

    def check(self, value: Any) -> None:
        """Raise ``ConfigError`` unless ``value`` is of this field's kind and within its bounds."""
        if value is None and self.optional:
            return
        if self.kind in ("ints", "numbers", "names"):
            self._check_sequence(value)
        elif self.kind == "choice" and value not in self.choices:
            fail(self.name, value, " | ".join(self.choices))
        elif self.kind == "bool" and not isinstance(value, bool):
            fail(self.name, value, "true | false")
        elif self.kind == "name" and not (isinstance(value, str) and value):
            fail(self.name, value, "a name")
        elif self.kind in ("int", "number", "probability"):
            self.check_item(value)

    def check_item(self, value: Any, name: str | None = None) -> None:
        """One number of this field (the field itself, or one entry of a sequence field)."""
        name = name or self.name
        if self.kind in ("int", "ints"):
            if isinstance(value, bool) or not isinstance(value, int) or not self.low <= value <= self.high:
                fail(name, value, f"an integer >= {self.low:g}{self._upper()}")
        elif self.kind == "probability":
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
                fail(name, value, "a probability in [0, 1]")
        else:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            ok = ok and (isinstance(value, int) or math.isfinite(value))      # math.isfinite(2**2000) overflows
            if ok:
                ok = ((value > self.low if self.strict else value >= self.low)
                      and (value < self.high if self.strict_high else abs(value) <= self.high))
            if not ok:
                low = "" if self.low == -math.inf else f"{'>' if self.strict else '>='} {self.low:g} and "
                high = f"< {self.high:g}" if self.strict_high else f"within ±{self.high:g}{self._why()}"
                fail(name, value, f"a number {low}{high}")

    def _check_sequence(self, value: Any) -> None:
        if self.scalar and not isinstance(value, tuple):
            self.check_item(value)
            return
        if not isinstance(value, tuple) or (self.length is not None and len(value) != self.length) or not value:
            fail(self.name, value, self.meaning_of_shape())
        for item in value:
            if self.kind == "names":
                if not (isinstance(item, str) and item):
                    fail(self.name, value, "a list of names")
            else:
                self.check_item(item)

    def meaning_of_shape(self) -> str:
        """What a sequence value must look like (for the error message)."""
        if self.shape:
            return self.shape
        item = {"ints": "integers", "numbers": "numbers", "names": "names"}[self.kind]
        count = f"{self.length} {item}" if self.length else f"a non-empty list of {item}"
        return f"an integer >= {self.low:g} or {count}" if self.scalar else count

    def _upper(self) -> str:
        return "" if self.high == math.inf else f" and <= {self.high:g}{self._why()}"

    def _why(self) -> str:
        if self.time_like:
            return " (the horizon limit)"
        return " (the count limit)" if self.high == MAX_COUNT else ""

    def doc_default(self) -> str:
        """The default as docs/configuration.md shows it (YAML spelling)."""
        return _yaml_text(self.default, code=self.kind in ("choice", "name"))

    def doc_row(self) -> str:
        """This field's row of its group's table."""
        return f"| `{self.name}` | {self.doc_default()} | {self.meaning} | {self.source} |"


def group(name: str, fields: Sequence[Field]) -> tuple[Field, ...]:
    """The fields of one concern, each marked with the group's name."""
    return tuple(dataclasses.replace(f, group=name) for f in fields)


def _yaml_text(value: Any, code: bool = False) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple):
        return "[" + ", ".join(_yaml_text(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}"
    return f"`{value}`" if code else str(value)


def did_you_mean(unknown: Sequence[str], known: Sequence[str], where: str = "") -> str:
    """The one-line message for unknown field names: the first few, each with its closest known name."""
    names = [str(u) for u in unknown]
    hints = []
    for name in names[:3]:
        close = difflib.get_close_matches(name, known, n=1)
        hints.append(f"{bounded_repr(name)}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    more = f" and {len(names) - 3} more" if len(names) > 3 else ""
    return (f"{where}unknown config field{'s' if len(names) > 1 else ''} {', '.join(hints)}{more}; "
            "the fields are listed in docs/configuration.md")


# -- the tables of docs/configuration.md ------------------------------------------------------------------------
HEADER = "| field | default | values | source |\n|---|---|---|---|"
_BLOCK = re.compile(r"(<!-- fields:(?P<group>[a-z_]+) -->\n)(.*?)(<!-- /fields:(?P=group) -->)", re.S)


def table(fields: Sequence[Field]) -> str:
    """The markdown table of ``fields``."""
    return "\n".join([HEADER, *(f.doc_row() for f in fields)]) + "\n"


def render_docs(text: str, groups: dict[str, Sequence[Field]]) -> str:
    """``text`` with every block between ``<!-- fields:GROUP -->`` and ``<!-- /fields:GROUP -->`` replaced by the
    table of that group (an unknown group is an error)."""
    def replace(match: re.Match[str]) -> str:
        name = match.group("group")
        if name not in groups:
            raise ConfigError(f"docs name an unknown field group {name!r}; groups: {', '.join(groups)}")
        return match.group(1) + table(groups[name]) + match.group(4)
    return _BLOCK.sub(replace, text)
