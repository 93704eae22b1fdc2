"""Solve an instance with a scripted consensus policy through the protocol directly, without the environment.

``solve(scenario, config, "cbgabi")`` makes exactly the calls an episode of ``TaskAllocEnv`` makes — every step each
agent still in the bundle phase decides from the same bid view, bids and quits are applied in agent order, the round
ends when every agent has passed (``sync``) or after every step (``every_step``) — and the policy decides with the
same rule on the same values (``CBGAPolicy.choose`` on the observation's columns, in the env's ``dtype``). It skips
what an episode computes only for its caller: observations, rewards and infos. So it returns the same ``Allocation``,
counters included, as ``rollout``; the experiments use it for the scripted baselines (a test compares the two on many
seeds).
"""

from __future__ import annotations

import numpy as np

from taskalloc.policies.registry import make_policy
from taskalloc.policies.scripted import CBGAPolicy
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.observation import Scales
from taskalloc_env.protocol import Protocol
from taskalloc_env.scenario import Scenario

PASS = 0


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
    protocol = Protocol(scenario, config)
    unit, float_type = Scales.of(scenario).reward_unit, np.dtype(dtype)
    m = scenario.n_tasks
    passed = np.zeros(scenario.n_agents, dtype=bool)
    masks = np.zeros((scenario.n_agents, 1 + 2 * m), dtype=bool)     # row i: agent i's action mask
    masks[:, 0] = True
    steps = 0
    while True:
        view = protocol.view()
        masks[:, 1: m + 1] = view.can_bid
        if config.task_quitting:            # otherwise no quit is ever allowed and those columns stay False
            masks[:, m + 1:] = protocol.quit_options()
        acting = np.flatnonzero(~passed)
        mask = masks[acting]
        # the rule reads only its own columns, as the observation gives them: divided by the unit, in ``dtype``
        columns = [(getattr(view, name)[acting] / unit).astype(float_type) for name in policy.columns]
        for i, action in zip(acting.tolist(), policy.choose(mask, *columns).tolist()):
            if action == PASS:
                passed[i] = True
            elif action <= m:
                protocol.bid(i, action - 1, view=view)
            else:
                protocol.quit(i, action - m - 1)
        steps += 1
        if config.consensus == "every_step" or passed.all():
            protocol.end_round()
            passed = ~protocol.alive
        if protocol.converged or (max_cycles is not None and steps >= max_cycles) \
                or protocol.round >= protocol.max_rounds:
            break
    return protocol.allocation()
