"""Checkpoints of learned policies with no executable content: JSON for the architecture, safetensors for weights.

A checkpoint is two files with one stem, ``<stem>.json`` and ``<stem>.safetensors`` (``models/train_small/model``):

* the JSON names the actor class (one of ``taskalloc.policies.networks.NETWORKS``) and its integer sizes, the
observation
  features it was trained on (checked against the environment's layout before acting), the protocol options the
  policy needs from the environment (``env_overrides``) and free-form metadata (plain JSON values only). An actor
  with release logits (``kinds: 3``) goes with ``release_actions: true`` in ``env_overrides`` and one without them
  (``kinds: 2``, the default of a config that does not name it) without: both ``save`` and ``load`` check it;
* the safetensors file holds the actor's weights, tensors only.

Loading parses JSON and tensors, builds a known class from integers and loads the weights strictly; nothing in the
files is executed. A stable-baselines3 ``.zip`` is different: SB3's loader unpickles its ``data`` entries, so a
crafted zip runs code. ``load`` refuses zips unless ``allow_pickle=True`` (with a warning); ``sb3_zip_to_checkpoint``
turns a zip trained by this project into a checkpoint while reading only its JSON entries and its weights, which
torch reads with ``weights_only=True``.

    taskalloc checkpoint convert runs/old/model.zip models/mine/model
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import io
import json
import pickle
import struct
import warnings
import zipfile
from collections.abc import Mapping, Sequence
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

from taskalloc_env.config import FACTS, PROTOCOL_FIELDS
from taskalloc_env.errors import ConfigError, run_cli
from taskalloc_env.resources import check_file, read_bounded

FORMAT, VERSION = "taskalloc-checkpoint", 1
MAX_JSON_BYTES = 1 << 20
MAX_SIZE = 1 << 16              # largest integer size a network may be built with
MAX_PARAMETERS = 50_000_000     # largest actor a checkpoint may describe (refused before anything is allocated)
# what a checkpoint's env_overrides may set: the protocol options a policy plays by (ours). Never the network (range,
# loss, delays, failures), the instance (pop-up tasks), the round bound or the asynchronous clock: those are the run's
RUN_GROUPS = ("network", "popups")
RUN_FIELDS = ("max_rounds", "message_ticks", "build_ticks", "separation_time")
POLICY_OPTIONS = tuple(name for name in PROTOCOL_FIELDS
                       if FACTS[name].group not in RUN_GROUPS and name not in RUN_FIELDS)
MAX_WEIGHT_BYTES = 8 * MAX_PARAMETERS + MAX_JSON_BYTES      # a safetensors file of that many float64 weights
SAFETENSORS_DTYPES = {"float32": "F32", "float64": "F64", "int64": "I64"}    # what write_safetensors writes
MAX_ZIP_MEMBERS = 64            # an SB3 zip holds a handful of entries (data, policy.pth, optimizer, versions)


class CheckpointError(ConfigError):
    """A checkpoint is missing, malformed, or asks for something outside what may be loaded."""


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """A loaded checkpoint: the actor network and what the JSON says about it."""

    actor: Any                              # torch.nn.Module of a class in NETWORKS, in eval mode
    network: str
    own_features: tuple[str, ...]
    task_features: tuple[str, ...]
    env_overrides: dict[str, Any]
    meta: dict[str, Any]


def save(stem: str | Path, actor: Any, own_features: Sequence[str], task_features: Sequence[str],
         env_overrides: Mapping[str, Any], meta: Mapping[str, Any] | None = None) -> Path:
    """Write ``<stem>.json`` and ``<stem>.safetensors``; returns the JSON path."""
    try:
        from safetensors.torch import save_file
    except ModuleNotFoundError:             # an environment without safetensors (BenchMARL's, which exports here)
        save_file = write_safetensors
    from taskalloc.policies.networks import NETWORKS

    if type(actor) not in NETWORKS.values():
        raise CheckpointError(f"{type(actor).__name__} is not a known network class ({sorted(NETWORKS)})")
    unknown = sorted(set(env_overrides) - set(POLICY_OPTIONS))
    if unknown:
        raise CheckpointError(f"env_overrides {unknown} are not options a policy plays by "
                              f"({', '.join(POLICY_OPTIONS)})")
    check_release(actor, env_overrides, type(actor).__name__)
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    spec = {"format": FORMAT, "version": VERSION,
            "network": {"class": actor.name, "config": actor.config()},
            "observation": {"own_features": list(own_features), "task_features": list(task_features)},
            "env_overrides": dict(env_overrides), "meta": dict(meta or {})}
    text = json.dumps(spec, indent=1, sort_keys=False)     # fails on anything that is not plain JSON
    save_file({k: v.detach().cpu().contiguous() for k, v in actor.state_dict().items()},
              str(stem.with_suffix(".safetensors")))
    stem.with_suffix(".json").write_text(text + "\n")
    return stem.with_suffix(".json")


def write_safetensors(tensors: Mapping[str, Any], path: str) -> None:
    """CPU tensors in the safetensors format without the safetensors package: an 8-byte little-endian header length,
    the JSON header (dtype, shape, byte offsets of each tensor; padded with spaces to 8 bytes), then the raw
    little-endian data (the format's specification, huggingface/safetensors README)."""
    header, chunks, offset = {}, [], 0
    for name in sorted(tensors):
        array = tensors[name].numpy()
        dtype = SAFETENSORS_DTYPES.get(str(array.dtype))
        if dtype is None:
            raise CheckpointError(f"tensor {name!r}: dtype {array.dtype} is not one of {sorted(SAFETENSORS_DTYPES)}")
        data = array.astype(array.dtype.newbyteorder("<"), copy=False).tobytes(order="C")
        header[name] = {"dtype": dtype, "shape": list(array.shape), "data_offsets": [offset, offset + len(data)]}
        chunks.append(data)
        offset += len(data)
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)
    with open(path, "wb") as out:
        out.write(struct.pack("<Q", len(text)) + text)
        out.writelines(chunks)


def load(source: str | Path | Traversable, allow_pickle: bool = False) -> Checkpoint:
    """Load a checkpoint: ``<stem>.json`` (or its stem, or a folder holding ``model.json``).

    With ``allow_pickle=True`` an SB3 ``.zip`` is loaded through SB3's own loader, which unpickles and can run
    code from the file: only for files you trust.
    """
    if isinstance(source, (str, Path)):
        source = Path(source)
        if source.suffix == ".zip":
            if not source.is_file():
                raise CheckpointError(f"no stable-baselines3 zip at {str(source)!r}")
            return _load_sb3_zip(source, allow_pickle)
        if source.is_dir():
            source = source / "model.json"
        elif source.suffix != ".json":
            source = source.with_name(source.name + ".json")
    spec = _read_spec(source)
    _network(spec, str(source))             # the architecture's size, refused before the weights are read
    weights = source.parent / (source.name[: -len(".json")] + ".safetensors") if isinstance(source, Path) else \
        _sibling(source, ".safetensors")
    return _build(spec, _read_weights(weights), str(source))


def _sibling(source: Traversable, suffix: str) -> Traversable:
    name = source.name[: -len(".json")] + suffix
    parent = getattr(source, "parent", None)
    if parent is None:
        raise CheckpointError(f"cannot locate the weights next to {source}")
    return parent / name


def _read_spec(source: Path | Traversable) -> dict[str, Any]:
    if isinstance(source, Path) and not source.exists():
        raise CheckpointError(f"no checkpoint at {str(source)!r} (no such file)")
    raw = read_bounded(source, MAX_JSON_BYTES, "checkpoint description", CheckpointError)
    try:
        spec = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"{source}: not a JSON checkpoint description ({exc})") from None
    if not isinstance(spec, dict) or spec.get("format") != FORMAT:
        raise CheckpointError(f"{source}: not a {FORMAT} file")
    if spec.get("version") != VERSION:
        raise CheckpointError(f"{source}: checkpoint version {spec.get('version')!r}; this code reads {VERSION}")
    return spec


def _read_weights(source: Path | Traversable) -> dict[str, Any]:
    """The tensors of a safetensors file, its header read first: a file of more than ``MAX_PARAMETERS`` weights
    (counted from the header's shapes) or more than ``MAX_WEIGHT_BYTES`` bytes is refused before its data is read."""
    from safetensors import SafetensorError
    from safetensors.torch import load

    if isinstance(source, Path) and not source.exists():
        raise CheckpointError(f"no weights at {str(source)!r} (no such file)")
    check_file(source, MAX_WEIGHT_BYTES, "weights file", CheckpointError)
    try:
        with source.open("rb") as fh:
            head = fh.read(8)
            size = struct.unpack("<Q", head)[0] if len(head) == 8 else -1
            header = fh.read(size) if 0 <= size <= MAX_JSON_BYTES else b""
    except OSError as exc:
        raise CheckpointError(f"no weights at {str(source)!r} ({exc.strerror or exc})") from None
    weights = _header_weights(header, str(source))
    if weights > MAX_PARAMETERS:
        raise CheckpointError(f"{source}: {weights} weights exceed the limit of {MAX_PARAMETERS}")
    try:
        return load(read_bounded(source, MAX_WEIGHT_BYTES, "weights file", CheckpointError))
    except SafetensorError as exc:
        raise CheckpointError(f"{source}: not a safetensors file ({exc})") from None


def _header_weights(header: bytes, where: str) -> int:
    """The number of weights a safetensors header declares (its JSON: name → dtype, shape, offsets)."""
    try:
        entries = json.loads(header)
        shapes = [entry["shape"] for name, entry in entries.items() if name != "__metadata__"]
        if not all(isinstance(d, int) and d >= 0 for shape in shapes for d in shape):
            raise TypeError("a shape holds something other than sizes")
    except (UnicodeDecodeError, json.JSONDecodeError, AttributeError, KeyError, TypeError) as exc:
        raise CheckpointError(f"{where}: not a safetensors file (header: {exc})") from None
    total = 0
    for shape in shapes:
        count = 1
        for d in shape:
            count *= d
        total += count
    return total


def _network(spec: Mapping[str, Any], where: str) -> tuple[type, dict[str, int]]:
    """The network class and integer sizes a description asks for, refused when the network would exceed
    ``MAX_PARAMETERS`` weights: it is built on torch's ``meta`` device (shapes, no storage) and counted."""
    import torch as th

    from taskalloc.policies.networks import NETWORKS, count_parameters

    network = spec.get("network")
    if not isinstance(network, dict) or network.get("class") not in NETWORKS:
        raise CheckpointError(f"{where}: network class {network!r} is not one of {sorted(NETWORKS)}")
    cls = NETWORKS[network["class"]]
    config = network.get("config")
    accepted = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    if not isinstance(config, dict) or set(config) - set(accepted):
        raise CheckpointError(f"{where}: network config {config!r} must be a mapping with keys among {accepted}")
    for key, value in config.items():
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_SIZE:
            raise CheckpointError(f"{where}: network config {key}={value!r} is not an integer in 1..{MAX_SIZE}")
    try:
        with th.device("meta"):
            planned = count_parameters(cls(**config))
    except (ValueError, AssertionError, RuntimeError) as exc:
        raise CheckpointError(f"{where}: network {network['class']} {config} cannot be built ({exc})") from None
    if planned > MAX_PARAMETERS:
        raise CheckpointError(f"{where}: {network['class']} {config} would have {planned} weights, more than the "
                              f"limit of {MAX_PARAMETERS}")
    return cls, config


def _build(spec: Mapping[str, Any], weights: Mapping[str, Any], where: str) -> Checkpoint:
    cls, config = _network(spec, where)
    network = spec["network"]
    bad = sorted(k for k, v in weights.items() if v.is_floating_point() and not bool(v.isfinite().all()))
    if bad:
        raise CheckpointError(f"{where}: weights {bad} hold NaN or infinite values")
    expected = sum(int(v.numel()) for v in weights.values())
    if expected > MAX_PARAMETERS:
        raise CheckpointError(f"{where}: {expected} weights exceed the limit of {MAX_PARAMETERS}")
    actor = cls(**config)
    try:
        actor.load_state_dict(dict(weights), strict=True)
    except RuntimeError as exc:
        raise CheckpointError(f"{where}: the weights do not fit {network['class']} {config}: "
                              f"{str(exc).splitlines()[0]}") from None
    actor.eval()
    observation = spec.get("observation") or {}
    own, task = observation.get("own_features"), observation.get("task_features")
    if not (_names(own) and _names(task)):
        raise CheckpointError(f"{where}: observation.own_features and .task_features must be lists of names")
    overrides = spec.get("env_overrides") or {}
    if not isinstance(overrides, dict) or set(overrides) - set(POLICY_OPTIONS):
        raise CheckpointError(f"{where}: env_overrides {overrides!r} may only set the options a policy plays by: "
                              f"{', '.join(POLICY_OPTIONS)}")
    check_release(actor, overrides, where)
    meta = spec.get("meta") or {}
    if not isinstance(meta, dict):
        raise CheckpointError(f"{where}: meta must be a mapping")
    return Checkpoint(actor, network["class"], tuple(own), tuple(task), dict(overrides), meta)


def check_release(actor: Any, env_overrides: Mapping[str, Any], where: str) -> None:
    """An actor with release logits (``kinds=3``) needs ``release_actions: true`` in its ``env_overrides``, one
    without them must not have it (so that ``learned:<name>`` builds the environment it acts in)."""
    kinds = getattr(actor, "kinds", None)
    release = bool(env_overrides.get("release_actions", False))
    if kinds is not None and (kinds == 3) != release:
        raise CheckpointError(f"{where}: a {actor.name} actor with kinds={kinds} goes with release_actions "
                              f"{'true' if kinds == 3 else 'false'} in env_overrides, got {env_overrides!r}")


def _names(value: Any) -> bool:
    return isinstance(value, list) and all(isinstance(v, str) for v in value)


# -- stable-baselines3 zips ------------------------------------------------------------------------------------------
def _zip_json_and_weights(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``data`` JSON (as text, nothing unpickled) and the ``policy.pth`` state dict (``weights_only``); the zip
    (its size, its number of entries and the unpacked size of the two it reads) is checked before anything is
    unpacked."""
    import torch as th

    check_file(path, MAX_WEIGHT_BYTES + MAX_JSON_BYTES, "stable-baselines3 zip", CheckpointError)
    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(_zip_member(archive, "data", MAX_JSON_BYTES, path))
            weights = _zip_member(archive, "policy.pth", MAX_WEIGHT_BYTES, path)
    except (OSError, KeyError, zipfile.BadZipFile, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path}: not a stable-baselines3 checkpoint ({exc})") from None
    try:
        state = th.load(io.BytesIO(weights), map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, ValueError) as exc:   # torch's refusals of policy.pth
        raise CheckpointError(f"{path}: policy.pth is not a state dict of tensors (torch's weights-only reader "
                              f"refused it: {type(exc).__name__})") from None
    if not isinstance(data, dict) or not isinstance(state, dict):
        raise CheckpointError(f"{path}: not a stable-baselines3 checkpoint (data must be a JSON object and "
                              "policy.pth a state dict)")
    return data, state


def _zip_member(archive: zipfile.ZipFile, name: str, limit: int, path: Path) -> bytes:
    """One entry of a zip of at most ``MAX_ZIP_MEMBERS`` entries, refused when it unpacks to more than ``limit``
    bytes (its size from the zip's directory; the read stops there too)."""
    members = archive.infolist()
    if len(members) > MAX_ZIP_MEMBERS:
        raise CheckpointError(f"{path}: {len(members)} entries; a stable-baselines3 zip has at most "
                              f"{MAX_ZIP_MEMBERS}")
    info = archive.getinfo(name)
    if info.file_size > limit:
        raise CheckpointError(f"{path}: entry {name!r} unpacks to {info.file_size} bytes; the limit is {limit}")
    with archive.open(info) as fh:
        return fh.read(limit + 1)


def sb3_zip_to_checkpoint(path: Path) -> Checkpoint:
    """Read a zip written by this project's SB3 training without unpickling anything (see the module docstring)."""
    data, state = _zip_json_and_weights(path)
    return _from_sb3(data.get("policy_kwargs"), state, data.get("taskalloc"), str(path))


def _from_sb3(policy_kwargs: Any, state: Mapping[str, Any], taskalloc: Any, where: str) -> Checkpoint:
    """The actor of an SB3 policy of this project (``taskalloc.training.sb3_policy``) from its kwargs and state dict."""
    from taskalloc.policies.networks import MlpActor, PoolingActor
    from taskalloc_env.observation import OWN_FEATURES, TASK_FEATURES

    kwargs = policy_kwargs if isinstance(policy_kwargs, dict) else {}
    body, hidden = kwargs.get("body", "pooling"), kwargs.get("hidden", 64)
    prefix = "mlp_extractor."
    actor_state = {k[len(prefix):].removeprefix("pi."): v for k, v in state.items()
                   if k.startswith(prefix) and not k.startswith(prefix + "critic.")}
    try:
        if body == "pooling":
            task_size = int(kwargs.get("task_size", len(TASK_FEATURES)))
            own_size = int(actor_state["actor.encode.0.weight"].shape[1]) - task_size
            config = {"own_size": own_size, "task_size": task_size, "hidden": int(hidden),
                      "kinds": int(kwargs.get("kinds", 2))}
            network, n_equipment = PoolingActor.name, own_size - len(OWN_FEATURES)
        elif body == "mlp":
            first, last = actor_state["actor.0.weight"], actor_state["actor.4.weight"]
            config = {"obs_size": int(first.shape[1]), "n_actions": int(last.shape[0]), "hidden": int(hidden)}
            network = MlpActor.name
            n_tasks = (int(last.shape[0]) - 1) // int(kwargs.get("kinds", 2))
            n_equipment = int(first.shape[1]) - len(OWN_FEATURES) - n_tasks * len(TASK_FEATURES)
        else:
            raise CheckpointError(f"{where}: unknown body {body!r} in policy_kwargs")
    except KeyError as exc:
        raise CheckpointError(f"{where}: not a policy of this project (no weight {exc})") from None
    meta = taskalloc if isinstance(taskalloc, dict) else {}
    overrides = dict(meta.get("env_overrides") or {})
    spec = {"network": {"class": network, "config": config},
            "observation": {"own_features": [*OWN_FEATURES, *(f"equipment_{e}" for e in range(n_equipment))],
                            "task_features": list(TASK_FEATURES)},
            "env_overrides": overrides,
            "meta": {k: v for k, v in meta.items() if k != "env_overrides"}}
    return _build(spec, actor_state, where)


def _load_sb3_zip(path: Path, allow_pickle: bool) -> Checkpoint:
    if not allow_pickle:
        raise CheckpointError(
            f"{path} is a stable-baselines3 zip: its entries are pickles, and SB3's loader runs whatever code they "
            f"name. Convert it without unpickling (`taskalloc checkpoint convert {path} OUT`), or, if you "
            "trust the file, load it with SB3's loader from Python: LearnedPolicy.load(path, allow_pickle=True) "
            "(make_policy('learned:PATH', allow_pickle=True)); no command line loads pickles")
    from stable_baselines3.common.save_util import load_from_zip_file

    warnings.warn(f"allow_pickle=True: SB3's loader unpickles {path}, which runs any code the file names; "
                  "load only files you trust, and convert them with `taskalloc checkpoint convert`",
                  stacklevel=3)
    data, params, _ = load_from_zip_file(path, device="cpu")
    return _from_sb3(data.get("policy_kwargs"), params["policy"], data.get("taskalloc"), str(path))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc checkpoint", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    convert = sub.add_parser("convert", help="an SB3 zip of this project → a checkpoint (no unpickling)")
    convert.add_argument("zip", type=Path, help="the stable-baselines3 .zip")
    convert.add_argument("out", type=Path, help="the checkpoint stem to write (OUT.json, OUT.safetensors)")
    convert.add_argument("--overwrite", action="store_true", help="replace an existing checkpoint at OUT")
    show = sub.add_parser("show", help="print a checkpoint's description")
    show.add_argument("path", type=Path, help="the checkpoint (.json, stem or folder)")
    args = parser.parse_args(argv)
    if args.command == "convert":
        existing = [str(f) for f in (args.out.with_suffix(s) for s in (".json", ".safetensors")) if f.exists()]
        if existing and not args.overwrite:
            raise CheckpointError(f"{' and '.join(existing)} already exist(s); pass --overwrite to replace the "
                                  "checkpoint")
        if not args.zip.is_file():
            raise CheckpointError(f"no stable-baselines3 zip at {str(args.zip)!r}")
        ckpt = sb3_zip_to_checkpoint(args.zip)
        written = save(args.out, ckpt.actor, ckpt.own_features, ckpt.task_features, ckpt.env_overrides,
                       {**ckpt.meta, "converted_from": args.zip.name})
        print(f"written: {written} and {written.with_suffix('.safetensors')}")
    else:
        ckpt = load(args.path)
        print(json.dumps({"network": ckpt.network, "config": ckpt.actor.config(),
                          "env_overrides": ckpt.env_overrides, "meta": ckpt.meta}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
