"""Loss models: which of a round's messages are lost. Each answers for itself whether it can lose a message.

``LOSS_MODELS`` names them for the config field ``loss_model`` (its choices are the registry's names); a new fault
model is one class here and one registry line. A model is set up from the config and the agents' positions (the
start positions the communication graph is drawn between, ``network.CommGraph.positions``), so a model may depend on
the distance between sender and receiver. Faults are ours: the sources assume every message arrives. Three follow
the channel models of the decentralised task-allocation benchmarks (Nayak et al., "Experimental Comparison of
Decentralized Task Allocation Algorithms Under Imperfect Communication", IEEE RA-L 5(2), 2020: Bernoulli,
Gilbert–Elliott and Rayleigh fading; and its 2026 successor, the public DCTA benchmark simulator, which adds the
stationary Gilbert–Elliott process with a fixed lag-1 correlation ρ = 0.8).
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
    def from_config(cls, cfg: Any, positions: np.ndarray) -> LossModel:
        """The model ``cfg`` describes, for agents at ``positions`` (N, 3)."""
        return NoLoss()


class NoLoss(LossModel):
    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return np.zeros(len(sender), dtype=bool)


class IndependentLoss(LossModel):
    """Each message is lost with probability ``p``, independently of every other (the benchmarks' Bernoulli
    model)."""

    def __init__(self, p: float) -> None:
        self.p = p

    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rng.random(len(sender)) < self.p

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        return cfg.message_loss > 0

    @classmethod
    def from_config(cls, cfg: Any, positions: np.ndarray) -> LossModel:
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
    def from_config(cls, cfg: Any, positions: np.ndarray) -> LossModel:
        return cls(len(positions), cfg.message_loss, cfg.burst_loss, cfg.burst_enter, cfg.burst_leave)


class StationaryGilbertElliott(LossModel):
    """Gilbert's channel set by its stationary loss rate ℓ and the lag-1 correlation ρ of its state.

    Every directed link is a two-state Markov chain: the good state delivers every message, the bad state loses
    every message, so a link's loss sequence *is* its state sequence. With a = P(good → bad) and b = P(bad → good)
    the chain's stationary P(bad) is a / (a + b) and its lag-1 autocorrelation is 1 − a − b (the second eigenvalue
    of the transition matrix). Setting P(bad) = ℓ and 1 − a − b = ρ gives

        a = ℓ (1 − ρ),  b = (1 − ℓ)(1 − ρ);  i.e.  p_GG = q + ρ (1 − q),  p_BB = (1 − q) + ρ q,  q = 1 − ℓ,

    the persistence probabilities of the DCTA benchmark's Gilbert–Elliott process (q its stationary delivery rate,
    ρ = 0.8 there). As there, a link starts in a state drawn from the stationary distribution (here when it carries
    its first message), a message's fate is decided by the link's state before the transition, and the chain steps
    once per message the link carries. ρ = 0 is the Bernoulli model; ρ → 1 freezes each link in its first state.
    """

    def __init__(self, n_agents: int, loss_rate: float, correlation: float) -> None:
        self.state = np.full((n_agents, n_agents), -1, dtype=np.int8)     # −1: not drawn yet, 0 good, 1 bad
        self.loss_rate = loss_rate
        self.enter_bad = loss_rate * (1.0 - correlation)
        self.leave_bad = (1.0 - loss_rate) * (1.0 - correlation)

    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        state = self.state[sender, receiver]
        fresh = state < 0
        if fresh.any():
            state[fresh] = rng.random(int(fresh.sum())) < self.loss_rate
        bad = state.astype(bool)
        flip = rng.random(len(sender)) < np.where(bad, self.leave_bad, self.enter_bad)
        self.state[sender, receiver] = bad ^ flip
        return bad

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        return cfg.message_loss > 0

    @classmethod
    def from_config(cls, cfg: Any, positions: np.ndarray) -> LossModel:
        """``message_loss`` is the stationary loss rate ℓ, ``burst_correlation`` ρ; ℓ = 0 is ``NoLoss``."""
        if not cls.loses_messages(cfg):
            return NoLoss()
        return cls(len(positions), cfg.message_loss, cfg.burst_correlation)


class RayleighFading(LossModel):
    """Distance-dependent loss: a message from i to k arrives with probability exp(−(d_ik / d0)^α).

    Under Rayleigh fading the received power is exponentially distributed about its path-loss mean
    P̄(d) ∝ d^−α, so the message clears a reception threshold θ with probability exp(−θ / P̄(d)) = exp(−(d/d0)^α),
    where d0 (``fading_distance``) is the distance at which the mean received power equals the threshold: the
    Rayleigh outage probability P_out = 1 − e^(−θ/P̄) (Goldsmith, *Wireless Communications*, 2005, ch. 3), with the
    path-loss exponent α (``fading_exponent``). The DCTA benchmark's ``rayleigh_style`` model (its README and change
    log: a transmit power, a reference path loss, the exponent, Rayleigh fading per message, delivery above a
    sensitivity) has this form with d0 = d_ref · 10^((P_t − PL_ref − sensitivity) / (10 α)); the RA-L 2020 paper's
    own equation was not available to us. Each message is drawn independently; d is the distance between the
    agents' start positions (agents do not move while they agree).
    """

    def __init__(self, positions: np.ndarray, reference: float, exponent: float) -> None:
        distance = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=2)
        with np.errstate(over="ignore"):
            self.delivery = np.exp(-((distance / reference) ** exponent))

    def lost(self, sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return rng.random(len(sender)) >= self.delivery[sender, receiver]

    @classmethod
    def loses_messages(cls, cfg: Any) -> bool:
        """Always counted as lossy (any two agents apart can lose a message)."""
        return True

    @classmethod
    def from_config(cls, cfg: Any, positions: np.ndarray) -> LossModel:
        return cls(np.asarray(positions, dtype=float), cfg.fading_distance, cfg.fading_exponent)


LOSS_MODELS: dict[str, type[LossModel]] = {
    "independent": IndependentLoss,
    "gilbert_elliott": GilbertElliott,
    "gilbert_elliott_rho": StationaryGilbertElliott,
    "rayleigh": RayleighFading,
}
