"""Policies by name, as the command line and the experiment configs write them.

A name may carry parameters after a colon: ``cbga+tq:delta=3`` is CBGA with task quitting at the threshold δ = 3
(``quit_threshold``; its ``env_overrides`` then hold ``delta=3``), so an experiment can run one series per δ
(thesis Fig 5.10) without a policy object in the YAML. Parameters are ``key=integer`` pairs separated by commas;
``delta`` is the only one, for the policies that quit (``cbga+tq``, ``cbgabi``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from taskalloc.policies.base import Policy
from taskalloc.policies.handover import Handover, with_partner
from taskalloc.policies.oracle import OraclePolicy
from taskalloc.policies.scripted import ACBBAPolicy, CBBAPolicy, CBGAPolicy, PassPolicy, RandomPolicy

FACTORIES: dict[str, Callable[..., Policy]] = {
    "random": RandomPolicy,
    "pass": PassPolicy,
    "cbba": CBBAPolicy,
    "acbba": ACBBAPolicy,
    "cbga": CBGAPolicy,
    "cbga+tq": lambda **kw: CBGAPolicy(task_quitting=True, **kw),
    "cbga+tb": lambda **kw: CBGAPolicy(team_bidding=True, **kw),
    "cbgabi": lambda **kw: CBGAPolicy(team_bidding=True, task_quitting=True, **kw),
    "oracle": OraclePolicy,
    "oracle-lns": lambda **kw: OraclePolicy(solver="lns", **kw),
}
# name parameters: policy name -> {parameter in the name: keyword of its factory}
PARAMETERS: dict[str, dict[str, str]] = {"cbga+tq": {"delta": "quit_threshold"},
                                         "cbgabi": {"delta": "quit_threshold"}}
POLICY_NAMES = (*FACTORIES, "cbga+tq:delta=<δ>", "cbgabi:delta=<δ>", "learned:<checkpoint>")


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
    """``random``, ``pass``, ``cbba``, ``acbba``, ``cbga``, ``cbga+tq``, ``cbga+tb``, ``cbgabi`` (``cbga+tq:delta=3``,
    ``cbgabi:delta=3``: with the quit threshold δ), ``oracle`` (privileged: bids along the exact optimum),
    ``oracle-lns`` (the same along the group search's allocation) or
    ``learned:<checkpoint>`` (a trained bidder, or a round-0 planner handed over to the
    policy its checkpoint names, ``taskalloc.policies.round_zero``)."""
    if name.lower().startswith("learned:"):
        return load_learned(name.split(":", 1)[1], **kwargs)
    if ":" in name and name.split(":", 1)[0].lower() not in FACTORIES:      # a user's policy: mypkg.mymodule:MyPolicy
        from taskalloc.policies.plugins import load_plugin
        return load_plugin(name, **kwargs)
    key, params = parse_name(name)
    if key not in FACTORIES:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}")
    return FACTORIES[key](**params, **kwargs)


def load_learned(source: str, planner_allowed: bool = True, **kwargs: Any) -> Policy:
    """``learned:<source>``: a ``LearnedPolicy``, or for a round-0 planner's checkpoint
    (``taskalloc.policies.round_zero``) the planner handed over after round 0 to the policy its meta names, which may
    not be a planner itself (it would load without end). A bidder trained with a partner (``taskalloc.training.mappo``'s
    ``round_zero`` and ``later_rounds``) loads as the pair it was trained in: after the planner its meta names in
    ``round_zero``, or before the policy it
    names in ``then``. ``kwargs`` are ``LearnedPolicy.load``'s options; a planner takes none."""
    from taskalloc.policies.checkpoint import CheckpointError, load
    from taskalloc.policies.learned import LearnedPolicy, resolve
    from taskalloc.policies.round_zero import PLANNER, RoundZeroPlanner, planner_meta

    checkpoint = load(resolve(source), allow_pickle=kwargs.pop("allow_pickle", False))
    name = kwargs.pop("name", None) or f"learned:{source}"
    if checkpoint.meta.get("algo") != PLANNER:
        bidder = LearnedPolicy.from_checkpoint(checkpoint, name=name, **kwargs)
        partner = {key: checkpoint.meta[key] for key in ("round_zero", "then") if checkpoint.meta.get(key) is not None}
        if not partner:
            return bidder
        if len(partner) > 1 or not all(isinstance(v, str) for v in partner.values()):
            raise CheckpointError(f"{source}: a bidder's meta names the planner it was trained after ('round_zero') "
                                  f"or the policy that plays after its round 0 ('then'), one policy name; got "
                                  f"{partner}")
        if "round_zero" in partner:
            policy = with_partner(bidder, planner_pair(partner["round_zero"], f"{source}: meta 'round_zero'").first,
                                  True)
        else:
            try:
                policy = with_partner(bidder, make_policy(partner["then"]), False)
            except ValueError as exc:
                raise CheckpointError(f"{source}: meta 'then' {partner['then']}: {exc}") from None
        policy.name = name
        return policy
    if not planner_allowed:
        raise CheckpointError(f"{source}: a planner's 'then' is itself a planner; it must be a bidding policy")
    then, threshold, replan = planner_meta(checkpoint, source)
    if kwargs:
        raise ValueError(f"{name} is a planner; options {sorted(kwargs)} are not taken")
    planner = RoundZeroPlanner.from_checkpoint(checkpoint, name=f"{name} (round-0 planner)", threshold=threshold,
                                               replan=replan)
    follower = (load_learned(then.split(":", 1)[1], planner_allowed=False) if then.lower().startswith("learned:")
                else make_policy(then))
    policy = Handover(planner, follower, 1)
    policy.name = name
    return policy


def planner_pair(name: str, where: str) -> Handover:
    """The ``Handover`` a round-0 planner's policy name (``learned:<planner checkpoint>``,
    ``taskalloc.training.planner``) loads as: its planner (``first``) and the policy it hands over to (``then``);
    ``ConfigError`` naming ``where``
    for any other name."""
    from taskalloc.policies.round_zero import RoundZeroPlanner
    from taskalloc_env.errors import ConfigError

    try:
        policy = make_policy(name)
    except ValueError as exc:       # a CheckpointError is a ConfigError already
        raise ConfigError(f"{where} {name}: {exc}") from None
    if not (isinstance(policy, Handover) and isinstance(policy.first, RoundZeroPlanner)):
        raise ConfigError(f"{where} {name}: not a round-0 planner (a checkpoint written by training.planner)")
    return policy
