"""A trained bidding policy behind the same ``Policy`` interface as the scripted baselines.

``LearnedPolicy.load(source)`` reads a checkpoint (``taskalloc.policies.checkpoint``: JSON architecture + safetensors
weights, nothing executable): a committed model by name (``train_small``, from ``models/``), a checkpoint's
``.json`` or stem, or a run folder holding ``model.json``. Every agent acts from its own observation with the shared
weights (parameter sharing); the action is greedy (``deterministic=True``: the most likely kind of action — pass,
bid, quit or release — then the most likely action of that kind, see ``greedy_actions``) or a sample. The pooling
network has no weight tied to the number of tasks, so a checkpoint trained on ``train_small`` also runs on larger
scenarios. It also runs where the environment adds optional task features it never saw (``member_silence`` on a faulty
network, ``released`` with pop-up tasks, ``sooner_agents`` and ``nearest_other`` with ``team_features``): the
actor reads its own features, selected by name (``feature_columns``).

``env_overrides`` are the protocol options the policy was trained with (e.g. ``task_quitting=True, delta=1`` so it
can quit tasks as CBGABI does); runners build the environment with them. An actor with release logits (``kinds=3``,
``taskalloc.policies.networks``) is trained with ``release_actions=True``, which its checkpoint's ``env_overrides``
carry; it plays only where the environment has release actions, and an actor without them only where it has none.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, Self

import numpy as np

from taskalloc.policies.base import Policy, stack_observations
from taskalloc.policies.checkpoint import Checkpoint, CheckpointError, load
from taskalloc_env import resources
from taskalloc_env.actions import (
    PASS,
    bid_columns,
    encode_bid,
    encode_quit,
    encode_release,
    n_actions,
    quit_columns,
    release_columns,
)
from taskalloc_env.observation import FAULT_FEATURES, POPUP_FEATURES, TEAM_FEATURES, ObservationLayout

# task features the environment adds only in some modes (a faulty network, pop-up tasks, team_features): a
# checkpoint trained without them runs on such an environment with them dropped from its input
OPTIONAL_TASK_FEATURES = FAULT_FEATURES + POPUP_FEATURES + TEAM_FEATURES


# folders of named models beyond the committed ones (``register_model_folder``; research registers its own)
MODEL_FOLDERS: list[Path] = []


def register_model_folder(path: str | Path) -> None:
    """Let ``learned:<name>`` also find the models in ``path/<name>/model.json`` (after the committed ones)."""
    path = Path(path).resolve()
    if not path.is_dir():
        raise CheckpointError(f"model folder {str(path)!r} is not a folder")
    if path not in MODEL_FOLDERS:
        MODEL_FOLDERS.append(path)


def named_model(name: str) -> Any | None:
    """A named model's ``model.json``: a committed one first, then the registered folders; ``None`` if none."""
    if not resources.is_name(name):
        return None
    committed = resources.folder("models") / name / "model.json"
    if committed.is_file():
        return committed
    return next((folder / name / "model.json" for folder in MODEL_FOLDERS
                 if (folder / name / "model.json").is_file()), None)


def resolve(source: str | Path) -> Any:
    """A model's name (``train_small``) → its ``model.json``, the committed models first and never a folder of the
    working directory (a local folder is loaded by an explicit path: ``learned:./NAME``); anything else is a path."""
    if isinstance(source, str) and resources.is_name(source):
        found = named_model(source)
        if found is not None:
            return found
        known = ", ".join(resources.names("models", suffix="") + sorted(
            {p.name for folder in MODEL_FOLDERS for p in folder.iterdir() if (p / "model.json").is_file()}))
        local = f"; the folder {source!r} here is loaded by its path, learned:./{source}" if Path(source).exists() \
            else ""
        raise CheckpointError(f"no model named {source!r} (named models: {known}){local}. Committed models ship "
                              "with the package; a model you trained is loaded by its path (learned:runs/NAME)")
    return Path(source)


class LearnedPolicy(Policy):
    """Acts with a trained actor network (``taskalloc.policies.networks``) for every agent it is given."""

    def __init__(self, actor: Any, own_features: tuple[str, ...], task_features: tuple[str, ...],
                 env_overrides: Mapping[str, Any] | None = None, meta: Mapping[str, Any] | None = None,
                 deterministic: bool = True, name: str = "learned") -> None:
        super().__init__()
        self.actor = actor
        self.own_features, self.task_features = tuple(own_features), tuple(task_features)
        self._env_overrides = dict(env_overrides or {})
        self.meta = dict(meta or {})
        self.deterministic = deterministic
        self.name = name
        self.rng = np.random.default_rng()
        self.columns: np.ndarray | None = None     # observation columns the actor reads (None: all of them)

    @classmethod
    def from_checkpoint(cls, checkpoint: Checkpoint, deterministic: bool = True, name: str = "learned",
                        **kwargs: Any) -> Self:
        return cls(checkpoint.actor, checkpoint.own_features, checkpoint.task_features, checkpoint.env_overrides,
                   checkpoint.meta, deterministic=deterministic, name=name, **kwargs)

    @classmethod
    def load(cls, source: str | Path, deterministic: bool = True, name: str | None = None,
             allow_pickle: bool = False) -> LearnedPolicy:
        """Load a committed model by name, or a checkpoint by path (see the module docstring)."""
        return cls.from_checkpoint(load(resolve(source), allow_pickle=allow_pickle), deterministic=deterministic,
                                   name=name or f"learned:{source}")

    @property
    def env_overrides(self) -> dict[str, Any]:
        return dict(self._env_overrides)

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        layout = self.layout
        columns = feature_columns(layout, self.own_features, self.task_features)
        if columns is False:
            raise ValueError(f"{self.name} was trained on other observation features: own {self.own_features}, "
                             f"per task {self.task_features}; this environment has own {layout.own_names}, per task "
                             f"{layout.task_names} (only the optional task features {OPTIONAL_TASK_FEATURES} "
                             "may be added by the environment and are then dropped)")
        self.columns = None if columns is True else columns
        if not self.actor.fits(len(self.own_features), len(self.task_features), layout.n_tasks):
            raise ValueError(f"{self.name} ({type(self.actor).__name__} {self.actor.config()}) does not fit "
                             f"{layout.n_tasks} tasks (a plain MLP is tied to the number of tasks it was trained on)")
        release = bool(self.env.config.release_actions)
        if self.actor.action_width(layout.n_tasks) != n_actions(layout.n_tasks, release):
            raise ValueError(f"{self.name} acts in the {'1 + 2M' if release else '1 + 3M'} layout (pass, bids, quits"
                             f"{'' if release else ', releases'}); this environment has "
                             f"{'' if release else 'no '}release actions: build it "
                             f"{'without' if release else 'with'} release_actions (the checkpoint's env_overrides)")
        self.rng = np.random.default_rng(seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        if not observations:
            return {}
        agents = list(observations)
        obs, masks = stack_observations(observations, agents)
        return {a: int(c) for a, c in zip(agents, self.decide(self.actor_input(obs), masks))}

    def actor_input(self, obs: np.ndarray) -> np.ndarray:
        """The columns of the environment's observations (B, D) that the actor reads, in its order."""
        return obs if self.columns is None else obs[:, self.columns]

    def decide(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """One action per row: the actor's observation (its own features only) and the action mask."""
        from taskalloc.policies.networks import masked_logits

        logits = masked_logits(self.actor, obs, masks).cpu().numpy().astype(np.float64)
        logits[masks == 0] = -np.inf
        probs = np.exp(logits - logits.max(axis=1, keepdims=True))
        probs /= probs.sum(axis=1, keepdims=True)
        if self.deterministic:
            return greedy_actions(logits, probs, (obs.shape[1] - len(self.own_features)) // len(self.task_features))
        return np.array([self.rng.choice(len(p), p=p) for p in probs])


def greedy_actions(logits: np.ndarray, probs: np.ndarray, n_tasks: int) -> np.ndarray:
    """The most likely kind of action (pass, bid, quit, release: summed probabilities), then its most likely action.

    A plain arg-max compares the pass action with each single bid; early in training, when the probability of
    bidding is spread over several tasks, it passes although bidding is far more likely, and a team whose agents
    all pass ends the episode with nothing. Grouping first removes that failure; for a trained, confident policy
    the two rules agree. The logits are (B, 1 + 2M), or (B, 1 + 3M) with release actions.
    """
    m = n_tasks
    groups = [(bid_columns(m), encode_bid), (quit_columns(m), lambda j: encode_quit(j, m))]
    if logits.shape[1] == n_actions(m, release=True):
        groups.append((release_columns(m), lambda j: encode_release(j, m)))
    kinds = np.stack([probs[:, PASS], *(probs[:, cols].sum(axis=1) for cols, _ in groups)], axis=1)
    kind = kinds.argmax(axis=1)
    choices = [np.full(len(logits), PASS), *(encode(logits[:, cols].argmax(axis=1)) for cols, encode in groups)]
    return np.choose(kind, choices)


def feature_columns(layout: ObservationLayout, own_features: tuple[str, ...], task_features: tuple[str, ...]
                    ) -> np.ndarray | bool:
    """The columns of ``layout``'s observation that hold a checkpoint's features, in the checkpoint's order.

    ``True`` when the layout is exactly the checkpoint's (the observation is used as it is); ``False`` when the
    checkpoint cannot run on it: the own features differ, or the environment lacks a task feature the checkpoint
    reads, or it has an extra task feature that is not one of ``OPTIONAL_TASK_FEATURES`` (``member_silence`` on a
    faulty network, ``released`` with pop-up tasks, the ``team_features``; see ``taskalloc_env.observation``). Those
    extras are dropped: the actor sees the features it was trained on, computed the same way, under the new
    network, task release or observation option.
    """
    if (own_features, task_features) == (layout.own_names, layout.task_names):
        return True
    extra = set(layout.task_names) - set(task_features)
    if (own_features != layout.own_names or not set(task_features) <= set(layout.task_names)
            or not extra <= set(OPTIONAL_TASK_FEATURES) or len(set(task_features)) != len(task_features)):
        return False
    picked = np.array([layout.task_column(name) for name in task_features])
    tasks = layout.own_size + np.arange(layout.n_tasks)[:, None] * layout.task_size + picked[None, :]
    return np.concatenate([np.arange(layout.own_size), tasks.ravel()])
