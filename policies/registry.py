"""Policies by name, as the command line and the experiment configs write them."""

from __future__ import annotations

from collections.abc import Callable

from policies.base import Policy
from policies.scripted import ACBBAPolicy, CBBAPolicy, CBGAPolicy, PassPolicy, RandomPolicy

FACTORIES: dict[str, Callable[..., Policy]] = {
    "random": RandomPolicy,
    "pass": PassPolicy,
    "cbba": CBBAPolicy,
    "acbba": ACBBAPolicy,
    "cbga": CBGAPolicy,
    "cbga+tq": lambda **kw: CBGAPolicy(task_quitting=True, **kw),
    "cbga+tb": lambda **kw: CBGAPolicy(team_bidding=True, **kw),
    "cbgabi": lambda **kw: CBGAPolicy(team_bidding=True, task_quitting=True, **kw),
}
POLICY_NAMES = (*FACTORIES, "learned:<checkpoint>")


def make_policy(name: str, **kwargs) -> Policy:
    """``random``, ``pass``, ``cbba``, ``acbba``, ``cbga``, ``cbga+tq``, ``cbga+tb``, ``cbgabi`` or
    ``learned:<checkpoint>``."""
    key = name.lower()
    if key.startswith("learned:"):
        from policies.learned import LearnedPolicy

        return LearnedPolicy.load(name.split(":", 1)[1], **kwargs)
    if key not in FACTORIES:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}")
    return FACTORIES[key](**kwargs)
