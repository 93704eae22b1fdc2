"""Policies for the taskalloc environment: scripted consensus baselines, random, learned; centralised solvers."""

from __future__ import annotations

from taskalloc.policies.base import Policy
from taskalloc.policies.cbaa import CBAAPolicy
from taskalloc.policies.centralised import exact, sgama
from taskalloc.policies.local_search import local_search
from taskalloc.policies.pi import PIPolicy
from taskalloc.policies.registry import POLICY_NAMES, make_policy, register_checkpoint_loader, register_policy
from taskalloc.policies.replan import AsyncReplanPolicy
from taskalloc.policies.rollout import rollout
from taskalloc.policies.scripted import ACBBAPolicy, CBBAPolicy, CBGAPolicy, PassPolicy, RandomPolicy

__all__ = [
    "POLICY_NAMES",
    "ACBBAPolicy",
    "AsyncReplanPolicy",
    "CBAAPolicy",
    "CBBAPolicy",
    "CBGAPolicy",
    "PIPolicy",
    "PassPolicy",
    "Policy",
    "RandomPolicy",
    "exact",
    "local_search",
    "make_policy",
    "register_checkpoint_loader",
    "register_policy",
    "rollout",
    "sgama",
]
