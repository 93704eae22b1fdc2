"""Solve an instance with a scripted consensus policy through the protocol directly, without the environment.

``solve(scenario, config, "cbgabi")`` makes exactly the calls an episode of ``TaskAllocEnv`` makes — the same
``taskalloc_env.engine.StepEngine`` steps the protocol, with the same action masks, from the decisions of every agent
still in the bundle phase — and the policy decides with the same rule on the same values (``CBGAPolicy.choose`` on
the observation's columns, in the env's ``dtype``). It skips what an episode computes only for its caller:
observations, rewards and infos. So it returns the same ``Allocation``, counters included, as ``rollout``; the
experiments use it for the scripted baselines (a test compares the two on many seeds).
"""

from __future__ import annotations

import numpy as np

from taskalloc.policies.registry import make_policy
from taskalloc.policies.scripted import CBGAPolicy
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.engine import StepEngine
from taskalloc_env.observation import Scales
from taskalloc_env.protocol import Protocol
from taskalloc_env.scenario import Scenario


def solvable(config: TaskAllocConfig) -> bool:
    """Whether ``solve`` reproduces an episode of ``config``: the synchronous protocol drawing no random numbers."""
    return not (config.asynchronous or config.stochastic)


def solve(scenario: Scenario, config: TaskAllocConfig, policy: str | CBGAPolicy, *, dtype: str = "float32",
          max_cycles: int | None = None) -> Allocation:
    """The allocation ``rollout`` reaches with ``policy`` on ``scenario`` in an env of ``config`` (and ``dtype``,
    ``max_cycles``), with the policy's ``env_overrides`` applied as a runner applies them."""
    policy = make_policy(policy) if isinstance(policy, str) else policy
    if not isinstance(policy, CBGAPolicy):
        raise ValueError(f"the direct solver runs the scripted consensus policies (CBBA, CBGA and variants), "
                         f"not {policy!r}")
    config = config.replace(**policy.env_overrides) if policy.env_overrides else config
    if config.asynchronous:
        raise ValueError("the direct solver runs the synchronous protocol; the asynchronous consensus (acbba) runs "
                         "through the env")
    if config.stochastic:
        raise ValueError("the direct solver needs a protocol that draws nothing (perfect links, no Poisson pop-ups): "
                         "random draws come from the env's generator")
    engine = StepEngine(Protocol(scenario, config))          # the env's step, without observations and rewards
    protocol = engine.protocol
    unit, float_type = Scales.of(scenario).reward_unit, np.dtype(dtype)
    while True:
        view = protocol.view()
        acting = engine.acting()
        mask = engine.masks()[acting].view(bool)
        # the rule reads only its own columns, as the observation gives them: divided by the unit, in ``dtype``
        columns = [(getattr(view, name)[acting] / unit).astype(float_type) for name in policy.columns]
        engine.apply(zip(acting.tolist(), policy.choose(mask, *columns).tolist()))
        if any(engine.ended(max_cycles)):
            break
    return protocol.allocation()
