"""A trained bidding policy behind the same ``Policy`` interface as the scripted baselines.

``LearnedPolicy.load(path)`` reads a checkpoint written by ``python -m training.train`` (an SB3 ``.zip``, or a run
directory holding ``model.zip``) and rebuilds only its torch policy, so PPO, MaskablePPO and behaviour-cloned
checkpoints all load the same way. Every agent acts from its own observation with the shared weights (parameter
sharing); the action is greedy (``deterministic=True``: the most likely kind of action — pass, bid or quit — then
the most likely action of that kind, see ``greedy_actions``) or a sample. The pooling network
has no weight tied to the number of tasks, so a checkpoint trained on ``train_small`` also runs on larger scenarios.

``env_overrides`` are the protocol options the policy was trained with (e.g. ``task_quitting=True, delta=1`` so it
can quit tasks as CBGABI does); runners build the environment with them.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from policies.base import Policy

REPO_ROOT = Path(__file__).resolve().parent.parent

# config fields that describe the consensus protocol rather than the scenario (taskalloc_env.config docstring)
PROTOCOL_FIELDS = ("cbba_table", "prereq_mode", "release_order", "task_quitting", "delta", "reset_on", "quit_block",
                   "require_known_capacity", "consensus", "max_bundle", "max_rounds")


class LearnedPolicy(Policy):
    """Acts with a trained SB3 actor-critic policy (``training.network``) for every agent it is given."""

    def __init__(self, policy: Any, meta: Mapping[str, Any] | None = None, deterministic: bool = True,
                 name: str = "learned") -> None:
        super().__init__()
        self.policy = policy
        self.meta = dict(meta or {})
        self.deterministic = deterministic
        self.name = name
        self.rng = np.random.default_rng()

    @classmethod
    def load(cls, path: str | Path, deterministic: bool = True, device: str = "cpu",
             name: str | None = None) -> LearnedPolicy:
        """Load ``path`` (a ``.zip`` checkpoint, or a directory with ``model.zip``)."""
        import torch as th
        from stable_baselines3.common.save_util import load_from_zip_file

        path = Path(path)
        if not path.is_absolute() and not path.exists() and (REPO_ROOT / path).exists():
            path = REPO_ROOT / path           # committed checkpoints are named relative to the repository
        if path.is_dir():
            path = path / "model.zip"
        if not path.exists():
            raise FileNotFoundError(f"no checkpoint at {str(path)!r}; train one with `python -m training.train`")
        data, params, _ = load_from_zip_file(path, device=device)
        policy = data["policy_class"](data["observation_space"], data["action_space"], lambda _: 0.0,
                                      **data.get("policy_kwargs", {}))
        policy.load_state_dict(params["policy"])
        policy.to(th.device(device))
        policy.set_training_mode(False)
        return cls(policy, data.get("taskalloc", {}), deterministic=deterministic, name=name or f"learned:{path}")

    @property
    def env_overrides(self) -> dict[str, Any]:
        overrides = self.meta.get("env_overrides", {})
        return {k: v for k, v in overrides.items() if k in PROTOCOL_FIELDS}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        body = self.policy.mlp_extractor
        layout = self.layout
        if hasattr(body, "own_size"):   # pooling network: any number of tasks, same per-task and own features
            fits = (body.own_size, body.task_size) == (layout.own_size, layout.task_size)
            need = f"own_size={body.own_size}, task_size={body.task_size}"
        else:
            fits = body.obs_size == layout.size
            need = f"observations of size {body.obs_size} (a plain MLP is tied to the number of tasks)"
        if not fits:
            raise ValueError(f"{self.name} needs {need}; this environment has own_size={layout.own_size}, "
                             f"task_size={layout.task_size}, size={layout.size}")
        self.rng = np.random.default_rng(seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        from training.network import masked_logits

        if not observations:
            return {}
        agents = list(observations)
        obs = np.stack([observations[a]["observation"] for a in agents])
        masks = np.stack([observations[a]["action_mask"] for a in agents])
        logits = masked_logits(self.policy, obs, masks).cpu().numpy().astype(np.float64)
        logits[masks == 0] = -np.inf
        probs = np.exp(logits - logits.max(axis=1, keepdims=True))
        probs /= probs.sum(axis=1, keepdims=True)
        if self.deterministic:
            choice = greedy_actions(logits, probs)
        else:
            choice = np.array([self.rng.choice(len(p), p=p) for p in probs])
        return {a: int(c) for a, c in zip(agents, choice)}


def greedy_actions(logits: np.ndarray, probs: np.ndarray) -> np.ndarray:
    """The most likely kind of action (pass, bid, quit: summed probabilities), then its most likely action.

    A plain arg-max compares the pass action with each single bid; early in training, when the probability of
    bidding is spread over several tasks, it passes although bidding is far more likely, and a team whose agents
    all pass ends the episode with nothing. Grouping first removes that failure; for a trained, confident policy
    the two rules agree.
    """
    m = (logits.shape[1] - 1) // 2
    kinds = np.stack([probs[:, 0], probs[:, 1: m + 1].sum(axis=1), probs[:, m + 1:].sum(axis=1)], axis=1)
    kind = kinds.argmax(axis=1)
    bid = 1 + logits[:, 1: m + 1].argmax(axis=1)
    quit_ = m + 1 + logits[:, m + 1:].argmax(axis=1)
    return np.select([kind == 0, kind == 1], [0, bid], quit_)
