"""Policies by name, as the command line and the experiment configs write them, and the plug-in points for more.

A name may carry parameters after a colon: ``cbga+tq:delta=3`` is CBGA with task quitting at the threshold δ = 3
(``quit_threshold``; its ``env_overrides`` then hold ``delta=3``), so an experiment can run one series per δ
(thesis Fig 5.10) without a policy object in the YAML. Parameters are ``key=integer`` pairs separated by commas;
``delta`` is the only one, for the policies that quit (``cbga+tq``, ``cbgabi``).

Two registries (ours) let code outside the product add policies without the product importing it:
``register_policy(name, factory)`` adds a named policy (the baselines below are registered the same way), and
``register_checkpoint_loader(algo, loader)`` adds how ``learned:<checkpoint>`` loads a checkpoint whose meta
``algo`` is ``algo`` (the product loads plain bidders; ``research`` registers its planners and partnered bidders).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from taskalloc.policies.base import Policy
from taskalloc.policies.cbaa import CBAAPolicy
from taskalloc.policies.checkpoint import Checkpoint, CheckpointError
from taskalloc.policies.pi import PIPolicy
from taskalloc.policies.replan import AsyncReplanPolicy
from taskalloc.policies.scripted import ACBBAPolicy, CBBAPolicy, CBGAPolicy, PassPolicy, RandomPolicy

FACTORIES: dict[str, Callable[..., Policy]] = {}
PRIVILEGED: set[str] = set()        # policies that read the scenario itself: never named by a checkpoint
NAME = re.compile(r"[a-z][a-z0-9_+-]*")
# name parameters: policy name -> {parameter in the name: keyword of its factory}
PARAMETERS: dict[str, dict[str, str]] = {"cbga+tq": {"delta": "quit_threshold"},
                                         "cbgabi": {"delta": "quit_threshold"}}
MAX_DEPTH = 4                       # checkpoints a checkpoint's meta may chain through (planner → bidder → …)


def register_policy(name: str, factory: Callable[..., Policy], privileged: bool = False) -> None:
    """Make ``make_policy(name)`` build ``factory(**kwargs)``; ``privileged``: it reads the scenario (no checkpoint
    may name it). A name is lower case (letters, digits, ``_+-``), not ``learned``, and registered once."""
    if not isinstance(name, str) or not NAME.fullmatch(name) or name == "learned":
        raise ValueError(f"policy name {name!r}: lower-case letters, digits and _+- starting with a letter, "
                         "not 'learned'")
    if name in FACTORIES:
        raise ValueError(f"policy {name!r} is already registered")
    if not callable(factory):
        raise ValueError(f"policy {name!r}: the factory {factory!r} is not callable")
    FACTORIES[name] = factory
    if privileged:
        PRIVILEGED.add(name)


for _name, _factory in (("random", RandomPolicy), ("pass", PassPolicy), ("cbba", CBBAPolicy), ("acbba", ACBBAPolicy),
                        ("acbba+replan", AsyncReplanPolicy), ("cbaa", CBAAPolicy), ("pi", PIPolicy),
                        ("cbga", CBGAPolicy),
                        ("cbga+tq", lambda **kw: CBGAPolicy(task_quitting=True, **kw)),
                        ("cbga+tb", lambda **kw: CBGAPolicy(team_bidding=True, **kw)),
                        ("cbgabi", lambda **kw: CBGAPolicy(team_bidding=True, task_quitting=True, **kw))):
    register_policy(_name, _factory)


def policy_names() -> tuple[str, ...]:
    """Every name ``make_policy`` takes, the parameterised and learned forms written out."""
    return (*FACTORIES, *(f"{k}:delta=<δ>" for k in PARAMETERS), "learned:<checkpoint>")


POLICY_NAMES = policy_names()       # the product's own names (a registered plug-in shows in policy_names())


def parse_name(name: str) -> tuple[str, dict[str, int]]:
    """``cbga+tq:delta=3`` → (``cbga+tq``, {``quit_threshold``: 3}); a name without parameters → (name, {})."""
    key, _, params = name.lower().partition(":")
    if not params:
        return key, {}
    allowed = PARAMETERS.get(key, {})
    if not allowed:
        raise ValueError(f"policy {key!r} takes no parameters (got {name!r}); parameters: "
                         + ", ".join(f"{k}:{'|'.join(v)}" for k, v in PARAMETERS.items()))
    kwargs: dict[str, int] = {}
    for item in params.split(","):
        field, eq, value = item.partition("=")
        field = field.strip()
        if not eq or field not in allowed:
            raise ValueError(f"policy {name!r}: {item!r} is not one of {sorted(allowed)} written as key=value")
        try:
            kwargs[allowed[field]] = int(value)
        except ValueError:
            raise ValueError(f"policy {name!r}: {field} must be an integer, got {value!r}") from None
    return key, kwargs


def make_policy(name: str, **kwargs) -> Policy:
    """``random``, ``pass``, ``cbba``, ``acbba``, ``acbba+replan``, ``cbaa``, ``pi``, ``cbga``, ``cbga+tq``,
    ``cbga+tb``, ``cbgabi`` (``cbga+tq:delta=3``, ``cbgabi:delta=3``: with the quit threshold δ), a registered
    plug-in, or ``learned:<checkpoint>`` (a trained policy, loaded by the loader its checkpoint's meta selects)."""
    if name.lower().startswith("learned:"):
        return load_learned(name.split(":", 1)[1], **kwargs)
    if ":" in name and name.split(":", 1)[0].lower() not in FACTORIES:      # a user's policy: mypkg.mymodule:MyPolicy
        from taskalloc.policies.plugins import load_plugin
        return load_plugin(name, **kwargs)
    key, params = parse_name(name)
    if key not in FACTORIES:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(policy_names())}")
    return FACTORIES[key](**params, **kwargs)


# -- learned policies -------------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class LoadRequest:
    """What a checkpoint loader gets: the checkpoint, the ``learned:`` source and name, and what the load passed
    through (the folder its meta may name checkpoints in, and the checkpoints loaded above it)."""

    checkpoint: Checkpoint
    source: str
    name: str
    folder: Path | None
    seen: tuple[str, ...]

    def policy(self, field: str) -> Policy:
        """The policy the checkpoint's meta ``field`` names: a policy name that is not privileged, a named model,
        or ``learned:<path>`` inside the checkpoint's own folder; never the checkpoint itself nor one above it."""
        where = f"{self.source}: meta {field!r}"
        name = self.checkpoint.meta.get(field)
        if not isinstance(name, str) or not name:
            raise CheckpointError(f"{where} must name a policy, got {name!r}")
        if not name.lower().startswith("learned:"):
            key = parse_name(name)[0] if ":" in name else name.lower()
            if key in PRIVILEGED:
                raise CheckpointError(f"{where} names the privileged policy {name!r}; a checkpoint may not")
            try:
                return make_policy(name)
            except ValueError as exc:
                raise CheckpointError(f"{where} {name}: {exc}") from None
        source = name.split(":", 1)[1]
        from taskalloc.policies.learned import named_model

        if named_model(source) is None:
            inside = self.folder is not None and not Path(source).is_absolute() and \
                (self.folder / source).resolve().is_relative_to(self.folder.resolve())
            if not inside:
                raise CheckpointError(f"{where} {name}: a checkpoint names a named model or a checkpoint inside its "
                                      f"own folder ({self.folder}), not another path")
            source = str(self.folder / source)
        return load_learned(source, _seen=self.seen)


CheckpointLoader = Callable[..., Policy]        # (LoadRequest, **options) -> Policy
LOADERS: dict[str | None, CheckpointLoader] = {}


def register_checkpoint_loader(algo: str | None, loader: CheckpointLoader) -> None:
    """Load checkpoints whose meta ``algo`` is ``algo`` (``None``: no ``algo``) with ``loader(request, **options)``,
    ``request`` a ``LoadRequest``; each ``algo`` once."""
    if algo is not None and (not isinstance(algo, str) or not algo):
        raise ValueError(f"checkpoint algo {algo!r}: a non-empty string or None")
    if algo in LOADERS:
        raise ValueError(f"a checkpoint loader for algo {algo!r} is already registered")
    if not callable(loader):
        raise ValueError(f"checkpoint loader for {algo!r}: {loader!r} is not callable")
    LOADERS[algo] = loader


def _plain(request: LoadRequest, **options: Any) -> Policy:
    """A bidder: a ``LearnedPolicy`` on the checkpoint's actor."""
    from taskalloc.policies.learned import LearnedPolicy

    return LearnedPolicy.from_checkpoint(request.checkpoint, name=request.name, **options)


# what the product trains: SB3 (no algo in converted checkpoints; maskable_ppo, ppo), RLlib, MAPPO and BenchMARL
# MAPPO bidders
for _algo in (None, "maskable_ppo", "ppo", "rllib_ppo", "mappo", "benchmarl_mappo"):
    register_checkpoint_loader(_algo, _plain)


def _json_of(path: Any) -> Any:
    """The ``model.json`` a source loads (a folder's, a stem's), absolute: one key per checkpoint."""
    if not isinstance(path, Path):
        return path
    if path.is_dir():
        path = path / "model.json"
    elif path.suffix not in (".json", ".zip"):
        path = path.with_name(path.name + ".json")
    return path.resolve()


def load_learned(source: str, _seen: tuple[str, ...] = (), **kwargs: Any) -> Policy:
    """``learned:<source>``: the checkpoint, loaded by the loader its meta ``algo`` selects; ``kwargs`` are that
    loader's options (``LearnedPolicy``'s: ``deterministic``, ``allow_pickle``)."""
    from taskalloc.policies.checkpoint import load
    from taskalloc.policies.learned import resolve

    path = resolve(source)
    key = str(_json_of(path))
    if key in _seen:
        raise CheckpointError(f"{source}: its meta names a checkpoint that names it again ({' → '.join(_seen)} → "
                              f"{key})")
    if len(_seen) >= MAX_DEPTH:
        raise CheckpointError(f"{source}: more than {MAX_DEPTH} checkpoints named one by another")
    checkpoint = load(path, allow_pickle=kwargs.pop("allow_pickle", False))
    algo = checkpoint.meta.get("algo")
    if algo not in LOADERS:
        raise CheckpointError(f"{source}: no loader for checkpoints of algo {algo!r} (registered: "
                              f"{sorted(map(str, LOADERS))}); a research checkpoint loads after `import research`")
    folder = (path if path.is_dir() else path.parent) if isinstance(path, Path) else None
    request = LoadRequest(checkpoint, source, kwargs.pop("name", None) or f"learned:{source}", folder,
                          (*_seen, key))
    return LOADERS[algo](request, **kwargs)
