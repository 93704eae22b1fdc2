"""Policies for the taskalloc environment: scripted consensus baselines, random, learned; centralised solvers."""

from __future__ import annotations

from policies.base import Policy
from policies.centralised import exact, sgama
from policies.local_search import local_search
from policies.oracle import OraclePolicy
from policies.registry import POLICY_NAMES, make_policy
from policies.rollout import rollout
from policies.scripted import ACBBAPolicy, CBBAPolicy, CBGAPolicy, PassPolicy, RandomPolicy

__all__ = [
    "POLICY_NAMES",
    "ACBBAPolicy",
    "CBBAPolicy",
    "CBGAPolicy",
    "OraclePolicy",
    "PassPolicy",
    "Policy",
    "RandomPolicy",
    "exact",
    "local_search",
    "make_policy",
    "rollout",
    "sgama",
]
