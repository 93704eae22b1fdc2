"""Training configs as dataclasses: one YAML file (``--config NAME_OR_FILE``) plus ``--field value`` overrides.

Every field carries its help text (``opt``), so ``--help`` lists them all; a boolean field is a flag
(``--overwrite`` / ``--no-overwrite``, as in ``taskalloc compare``), other values on the command line are read as
YAML (``null``, ``1e-4``, ``{k: v}``, ``[a, b]``); a config file sets booleans as YAML (``overwrite: true``). Type
errors name the field and what is allowed; a config written for the other trainer names the command that reads it.
Used by ``taskalloc.training.train`` (SB3) and ``taskalloc.training.mappo`` (our own PPO loop).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

import yaml

from taskalloc.policies.checkpoint import POLICY_OPTIONS
from taskalloc_env import resources
from taskalloc_env.config import read_yaml
from taskalloc_env.errors import ConfigError

C = TypeVar("C")

# the commands that read configs/training: command -> (module, its config class, what it is)
TRAINERS = {"taskalloc train": ("taskalloc.training.train", "TrainConfig", "the SB3 trainer"),
            "taskalloc mappo": ("taskalloc.training.mappo", "MappoConfig", "the MAPPO trainer")}


def opt(default: Any, help: str) -> Any:
    """A config field with an immutable default and its help text (shown by ``--help``)."""
    return dataclasses.field(default=default, metadata={"help": help})


def default_of(field: dataclasses.Field) -> Any:
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def check_types(cfg: Any, what: str = "training") -> None:
    """Every field's value has its annotated type (``bool`` only where a bool is allowed)."""
    hints = typing.get_type_hints(type(cfg))
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        hint = hints[field.name]
        members = typing.get_args(hint) if typing.get_origin(hint) in (typing.Union, types.UnionType) else (hint,)
        kinds = tuple(typing.get_origin(t) or t for t in members)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            names = " | ".join("null" if k is type(None) else k.__name__ for k in kinds)
            raise ConfigError(f"{what} field {field.name!r}: got {value!r}; allowed: {names}")


def check_at_least(cfg: Any, names: Sequence[str], minimum: int, what: str = "training") -> None:
    for name in names:
        if getattr(cfg, name) < minimum:
            raise ConfigError(f"{what} field {name!r}: got {getattr(cfg, name)!r}; allowed: an integer >= {minimum}")


def check_protocol_options(cfg: Any, hint: str = "", what: str = "training") -> None:
    """``cfg.env_overrides`` names protocol options only (the options a policy plays with, saved in its
    checkpoint); ``hint`` is added to the error."""
    unknown = sorted(set(cfg.env_overrides) - set(POLICY_OPTIONS))
    if unknown:
        raise ConfigError(f"{what} field 'env_overrides': {unknown} are not options a policy plays by (the protocol "
                          f"options a checkpoint keeps, not the network, the round bound or the instance){hint}")


def coerce(cls: type, name: str, value: Any) -> Any:
    """YAML reads ``1e-3`` as a string and ``1`` as an int; float fields get floats (a field that also takes a
    string keeps a string that is no number: ``reward_scale: raw``)."""
    hint = typing.get_type_hints(cls)[name]
    wants_float = hint is float or float in typing.get_args(hint)
    if wants_float and isinstance(value, (str, int)) and not isinstance(value, bool):
        try:
            return float(value)
        except ValueError:
            if str in typing.get_args(hint):
                return value
            raise ConfigError(f"training field {name!r}: got {value!r}; allowed: a number") from None
    return value


def parse(cls: type[C], argv: Sequence[str] | None, prog: str, description: str | None,
          configs: Path | None = None) -> C:
    """``--config NAME_OR_FILE`` (a name from ``configs`` when it holds it, else from ``configs/training``, or a YAML
    path), then ``--field value`` (``--flag`` / ``--no-flag`` for a boolean field)."""
    parser = argparse.ArgumentParser(prog=prog, description=description,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", metavar="NAME_OR_FILE",
                        help="training config: a name from configs/training or a YAML file")
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        flag, text = f"--{field.name.replace('_', '-')}", f"{field.metadata['help']} (default: {default_of(field)})"
        if hints[field.name] is bool:
            parser.add_argument(flag, dest=field.name, action=argparse.BooleanOptionalAction,
                                default=argparse.SUPPRESS, help=text)
        else:
            parser.add_argument(flag, dest=field.name, type=yaml.safe_load, default=argparse.SUPPRESS,
                                metavar="VALUE", help=text)
    args = vars(parser.parse_args(argv))
    values: dict[str, Any] = {}
    source = args.pop("config", None)
    if source is not None:
        if not resources.is_name(source):
            path = Path(source)
        elif configs is not None and (configs / f"{source}.yaml").is_file():
            path = configs / f"{source}.yaml"
        else:
            path = resources.named("training", source)
        values = read_yaml(path, "training config") or {}
        if not isinstance(values, dict):
            raise ConfigError(f"training config {str(path)!r} must hold a mapping of {cls.__name__} fields")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(values) - set(known))
        if unknown:
            owner = trainer_for(values, prog)
            if owner:
                raise ConfigError(f"training config {str(path)!r} is for `{owner}` ({TRAINERS[owner][2]}), not "
                                  f"`{prog}`: run {owner} --config {source}")
            raise ConfigError(f"training config {str(path)!r}: unknown fields {unknown}; known: {known}")
    values.update(args)
    return cls(**{k: coerce(cls, k, v) for k, v in values.items()})


def trainer_for(values: dict[str, Any], prog: str) -> str | None:
    """The other command of ``TRAINERS`` whose config has every field of ``values`` (None if there is none)."""
    for command, (module, name, _) in TRAINERS.items():
        if command != prog:
            fields = {f.name for f in dataclasses.fields(getattr(importlib.import_module(module), name))}
            if set(values) <= fields:
                return command
    return None


def prepare_out_dir(out_dir: str | Path, overwrite: bool) -> Path:
    """Create ``out_dir``; refuse to replace a model already there unless ``overwrite`` (committed models stay)."""
    out_dir = Path(out_dir)
    existing = sorted(p.name for p in out_dir.glob("*.json")) if out_dir.is_dir() else []
    if existing and not overwrite:
        raise ConfigError(f"out_dir {str(out_dir)!r} already holds a model ({', '.join(existing)}); pass --overwrite "
                          "to replace it, or choose another --out-dir")
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "eval.csv").unlink(missing_ok=True)     # a new run starts a new learning curve
    return out_dir


def plain(value: Any) -> Any:
    """numpy scalars → Python numbers, tuples → lists, for YAML."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        return value.item()
    return value
