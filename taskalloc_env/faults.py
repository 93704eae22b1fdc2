"""Loss models: which of a round's messages are lost. Each answers for itself whether it can lose a message.

``LOSS_MODELS`` names them for the config field ``loss_model`` (its choices are the registry's names); a new fault
model is one class here and one registry line. Faults are ours: the sources assume every message arrives.
"""

from __future__ import annotations

import abc
from typing import Any

import numpy as np


class LossModel(abc.ABC):
    """Which of a round's messages (sender → receiver pairs) are lost."""

    @abc.abstractmethod
    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A boolean mask over the messages."""

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        """Whether this model, set up from ``cfg`` (a ``TaskAllocConfig``), can lose a message."""
        return False

    @classmethod
    def from_config(cls, cfg: Any, n_agents: int) -> LossModel:
        """The model ``cfg`` describes, for ``n_agents`` agents."""
        return NoLoss()


class NoLoss(LossModel):
    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return np.zeros(len(sender), dtype=bool)


class IndependentLoss(LossModel):
    """Each message is lost with probability ``p``, independently of every other."""

    def __init__(self, p: float) -> None:
        self.p = p

    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rng.random(len(sender)) < self.p

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        return cfg.message_loss > 0

    @classmethod
    def from_config(cls, cfg: Any, n_agents: int) -> LossModel:
        """``message_loss`` p; p = 0 is the perfect ``NoLoss`` (nothing is drawn)."""
        return cls(cfg.message_loss) if cls.loses_messages(cfg) else NoLoss()


class GilbertElliott(LossModel):
    """Bursty loss: every link is a two-state Markov channel, stepped once per round it carries a message."""

    def __init__(self, n_agents: int, loss_good: float, loss_bad: float, enter_bad: float, leave_bad: float) -> None:
        self.bad = np.zeros((n_agents, n_agents), dtype=bool)
        self.loss_good, self.loss_bad = loss_good, loss_bad
        self.enter_bad, self.leave_bad = enter_bad, leave_bad

    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        was_bad = self.bad[sender, receiver]
        flip = rng.random(len(sender)) < np.where(was_bad, self.leave_bad, self.enter_bad)
        bad = was_bad ^ flip
        self.bad[sender, receiver] = bad
        return rng.random(len(sender)) < np.where(bad, self.loss_bad, self.loss_good)

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        """Always counted as lossy (the channel draws every round, whatever its probabilities)."""
        return True

    @classmethod
    def from_config(cls, cfg: Any, n_agents: int) -> LossModel:
        return cls(n_agents, cfg.message_loss, cfg.burst_loss, cfg.burst_enter, cfg.burst_leave)


LOSS_MODELS: dict[str, type[LossModel]] = {"independent": IndependentLoss, "gilbert_elliott": GilbertElliott}
