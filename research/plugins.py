"""What research plugs into the product: its policies, its checkpoint loaders and its models folder.

* ``oracle`` and ``oracle-lns`` (``research.policies.oracle``), registered as privileged: no checkpoint may name them;
* checkpoints of a round-0 planner (meta ``algo`` ``round0-planner``, ``research.training.planner``): the planner
  handed over after round 0 to the policy its meta ``then`` names (not itself a planner);
* checkpoints of a bidder trained with a partner (meta ``algo`` ``mappo-partner``,
  ``research.training.partnered``): the pair it was trained in, after the planner its meta ``round_zero`` names or
  before the policy its meta ``then`` names;
* distilled bidders (meta ``algo`` ``distil``, ``research.training.distil``): plain ``LearnedPolicy``.

Names in a checkpoint's meta load through the product's ``LoadRequest.policy``: no privileged policy, no path outside
the checkpoint's folder, no checkpoint that names itself.
"""

from __future__ import annotations

from typing import Any

from research import MODELS
from research.policies.handover import Handover, with_partner
from research.policies.oracle import OraclePolicy
from research.policies.round_zero import PLANNER, RoundZeroPlanner, planner_meta
from taskalloc.policies.base import Policy
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc.policies.learned import LearnedPolicy, register_model_folder
from taskalloc.policies.registry import FACTORIES, LoadRequest, make_policy, register_checkpoint_loader, register_policy
from taskalloc_env.errors import ConfigError

PARTNERED = "mappo-partner"     # the checkpoint's meta["algo"] of a bidder trained with a partner
DISTILLED = "distil"


def is_planner(policy: Policy) -> bool:
    """Whether ``policy`` is a round-0 planner as ``learned:`` loads it (handed over after round 0)."""
    return isinstance(policy, Handover) and isinstance(policy.first, RoundZeroPlanner)


def load_planner(request: LoadRequest, **options: Any) -> Policy:
    """A planner's checkpoint: the planner for round 0, then the policy its meta ``then`` names."""
    if options:
        raise ValueError(f"{request.name} is a planner; options {sorted(options)} are not taken")
    _, threshold, replan = planner_meta(request.checkpoint, request.source)
    planner = RoundZeroPlanner.from_checkpoint(request.checkpoint, name=f"{request.name} (round-0 planner)",
                                               threshold=threshold, replan=replan)
    follower = request.policy("then")
    if is_planner(follower):
        raise CheckpointError(f"{request.source}: a planner's 'then' is itself a planner; it must be a bidding policy")
    policy = Handover(planner, follower, 1)
    policy.name = request.name
    return policy


def load_partnered(request: LoadRequest, **options: Any) -> Policy:
    """A bidder trained with a partner, as the pair it was trained in."""
    bidder = LearnedPolicy.from_checkpoint(request.checkpoint, name=request.name, **options)
    meta = request.checkpoint.meta
    named = [key for key in ("round_zero", "then") if meta.get(key) is not None]
    if len(named) != 1:
        raise CheckpointError(f"{request.source}: a partnered bidder's meta names the planner it was trained after "
                              f"('round_zero') or the policy that plays after its round 0 ('then'), one of them; got "
                              f"{ {k: meta.get(k) for k in ('round_zero', 'then')} }")
    partner = request.policy(named[0])
    if named[0] == "round_zero":
        if not is_planner(partner):
            raise CheckpointError(f"{request.source}: meta 'round_zero' {meta['round_zero']} is not a round-0 planner")
        policy = with_partner(bidder, partner.first, True)
    else:
        policy = with_partner(bidder, partner, False)
    policy.name = request.name
    return policy


def load_distilled(request: LoadRequest, **options: Any) -> Policy:
    return LearnedPolicy.from_checkpoint(request.checkpoint, name=request.name, **options)


def planner_pair(name: str, where: str) -> Handover:
    """The ``Handover`` a round-0 planner's name (``learned:<planner checkpoint>``) loads as: its planner
    (``first``) and the policy it hands over to (``then``); ``ConfigError`` naming ``where`` for any other name."""
    try:
        policy = make_policy(name)
    except ValueError as exc:       # a CheckpointError is a ConfigError already
        raise ConfigError(f"{where} {name}: {exc}") from None
    if not is_planner(policy):
        raise ConfigError(f"{where} {name}: not a round-0 planner (a checkpoint written by research.training.planner)")
    return policy


def register() -> None:
    """Register research's policies, loaders and models with the product (once; later calls do nothing)."""
    if "oracle" in FACTORIES:
        return
    register_policy("oracle", OraclePolicy, privileged=True)
    register_policy("oracle-lns", lambda **kw: OraclePolicy(solver="lns", **kw), privileged=True)
    register_checkpoint_loader(PLANNER, load_planner)
    register_checkpoint_loader(PARTNERED, load_partnered)
    register_checkpoint_loader(DISTILLED, load_distilled)
    register_model_folder(MODELS)
