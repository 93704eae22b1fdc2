"""MAPPO with a partner (ours): ``taskalloc.training.mappo``'s loop with a fixed policy playing round 0 or the rounds
after it, through the loop's ``PartnerHook``.

    python -m research.training.partnered --config mappo_after_planner_small --seed 0 --out-dir runs/x/seed0
    python -m research.training.partnered --config mappo_round_zero_small --seed 0 --out-dir runs/y/seed0

A bidder for after a planned round 0 (``round_zero``): a round-0 planner (``research.training.planner``) plays
round 0 of every training episode for every agent, as part of the environment's dynamics, and the actor learns the
rounds after it, from the states the planner leaves (a bidder trained from its own round 0 never sees those). The team
score gained in round 0 is the planner's, so it is no part of the actor's return. The checkpoint (meta ``algo``
``mappo-partner``) names the planner in meta ``round_zero`` and ``learned:<run>`` loads as the pair, as the
evaluation plays it. The mirror, ``later_rounds``: a fixed policy plays every round after round 0 and the actor learns
round 0 alone, its return the team score the whole episode ends with (meta ``then``). Started from a round-0 planner's
checkpoint (``init_from``, its pass logit set to 0 so that the policy's arg-max is the planner's rule), this fine-tunes
the planner on the team score itself instead of on the solver's labels. Config names resolve in ``research/configs``
first.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import torch as th
from torch import nn

from research import CONFIGS
from research.plugins import PARTNERED, planner_pair
from research.policies.handover import with_partner
from research.policies.round_zero import PLANNER
from taskalloc.policies.base import Policy
from taskalloc.policies.registry import make_policy
from taskalloc.training import mappo
from taskalloc.training.config import opt
from taskalloc_env.errors import ConfigError, run_cli


@dataclasses.dataclass
class PartneredConfig(mappo.MappoConfig):
    """``MappoConfig`` and the partner: at most one of ``round_zero`` and ``later_rounds``."""

    round_zero: str | None = opt(None, "a round-0 planner (learned:<planner checkpoint>, research.training.planner) "
                                       "that plays round 0 for every agent; the actor learns the rounds after it")
    later_rounds: str | None = opt(None, "a policy that plays every round after round 0; the actor learns round 0 "
                                         "alone (e.g. a round-0 planner, init_from its checkpoint)")

    def check(self) -> None:
        super().check()
        if self.round_zero is not None and self.later_rounds is not None:
            raise ConfigError("training fields 'round_zero' and 'later_rounds': give at most one (the actor learns "
                              "the rounds after round 0, or round 0 alone)")


@dataclasses.dataclass(frozen=True)
class FixedPartner:
    """The policy that plays round 0 (``round_zero``) or every round after it, as ``mappo.Partner`` asks."""

    policy: Policy
    round_zero: bool
    meta: Mapping[str, Any]

    def plays(self, round_: int) -> bool:
        return (round_ == 0) == self.round_zero

    def with_actor(self, bidder: Policy) -> Policy:
        return with_partner(bidder, self.policy, self.round_zero)


def load_partner(cfg: PartneredConfig) -> FixedPartner | None:
    """The policy of ``round_zero`` (a round-0 planner) or ``later_rounds`` (any policy), checked: it plays with
    the run's protocol options."""
    if cfg.round_zero is not None:
        field, policy = "round_zero", planner_pair(cfg.round_zero, "training field 'round_zero':").first
    elif cfg.later_rounds is not None:
        field = "later_rounds"
        try:
            policy = make_policy(cfg.later_rounds)
        except ValueError as exc:       # a CheckpointError is a ConfigError already
            raise ConfigError(f"training field 'later_rounds': {exc}") from None
    else:
        return None
    clash = {k: v for k, v in policy.env_overrides.items() if k not in cfg.env_overrides or cfg.env_overrides[k] != v}
    if clash:
        raise ConfigError(f"training field '{field}': {getattr(cfg, field)} plays with {clash}; the run's "
                          f"env_overrides {cfg.env_overrides} must hold them")
    meta = {"algo": PARTNERED, "round_zero" if field == "round_zero" else "then": getattr(cfg, field)}
    return FixedPartner(policy, field == "round_zero", meta)


class Hook:
    """``mappo.PartnerHook``: the config with the partner's fields, research's configs, the partner, and a planner's
    pass logit set to 0 when the actor starts from a planner."""

    config = PartneredConfig
    configs = CONFIGS
    prog = "python -m research.training.partnered"

    def partner(self, cfg: PartneredConfig) -> FixedPartner | None:
        return load_partner(cfg)

    def init_actor(self, actor: nn.Module, meta: Mapping[str, Any]) -> None:
        if meta.get("algo") == PLANNER:
            # a planner fitted its bid logits as log-odds and never its pass logit: with the pass logit at 0 the
            # arg-max of the actor's policy is the planner's rule at threshold ½ (bid the likeliest task while p ≥ ½)
            pass_layer = actor.output_layers()[-1]
            with th.no_grad():
                pass_layer.weight.zero_()
                pass_layer.bias.zero_()


def main(argv: Sequence[str] | None = None) -> dict[str, Any]:
    return mappo.main(argv, Hook())


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
