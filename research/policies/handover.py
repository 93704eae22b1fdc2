"""One policy for the first rounds of an episode, another for the rest (ours: for measurements and learned plans).

``research.evaluation.handover`` hands the privileged oracle over to a policy (or the reverse) to see where the policy
loses to the optimum; ``research.policies.round_zero`` plays a learned round-0 plan, then a bidding policy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.base import Policy


class Handover(Policy):
    """``first`` acts in the first ``rounds`` protocol rounds of each episode, ``then`` in the rest.

    The round is the one the environment reports in every agent's info (``info["round"]``; a synchronous round
    holds each agent's bids up to its pass, thesis Alg 5), so ``act`` needs the infos. Both policies are bound to the
    environment at ``start``; each reads its state from the observations of the step it acts on (every policy of
    ``policies`` does), so ``then`` needs nothing from the steps it did not play."""

    def __init__(self, first: Policy, then: Policy, rounds: int) -> None:
        super().__init__()
        if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 0:
            raise ValueError(f"rounds must be an integer >= 0, got {rounds!r}")
        a, b = first.env_overrides, then.env_overrides
        clash = sorted(k for k in a.keys() & b.keys() if a[k] != b[k])
        if clash:
            raise ValueError(f"{first.name} and {then.name} need different environments: "
                             + ", ".join(f"{k}={a[k]!r} against {b[k]!r}" for k in clash))
        self.first, self.then, self.rounds = first, then, rounds
        self.name = f"{first.name} for {rounds} round(s), then {then.name}"

    @property
    def env_overrides(self) -> dict[str, Any]:
        return {**self.first.env_overrides, **self.then.env_overrides}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.first.start(env, seed)
        self.then.start(env, seed)

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        if not observations:
            return {}
        if infos is None:
            raise ValueError(f"{self.name} hands over by the round in the agents' infos; pass them to act")
        current = infos[next(iter(observations))]["round"]
        return (self.first if current < self.rounds else self.then).act(observations, infos)


def with_partner(bidder: Policy, partner: Policy, partner_plays_round_zero: bool) -> Handover:
    """A bidder trained with a fixed partner (``taskalloc.training.mappo``'s ``round_zero`` / ``later_rounds``), as it
    plays:
    the partner in round 0 and the bidder after it, or the bidder in round 0 and the partner after it."""
    return Handover(partner, bidder, 1) if partner_plays_round_zero else Handover(bidder, partner, 1)
