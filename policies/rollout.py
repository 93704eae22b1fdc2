"""Run one episode of a policy in the environment and return the allocation it reached."""

from __future__ import annotations

from typing import Any

from taskalloc.policies.base import Policy
from taskalloc_env.allocation import Allocation


def rollout(env: Any, policy: Policy, seed: int | None = None) -> Allocation:
    """Reset ``env`` with ``seed``, let ``policy`` act until the episode ends, return ``env.unwrapped.evaluate()``.

    ``env`` is a parallel ``TaskAllocEnv`` (or a wrapper of one); the episode return equals the allocation's score
    divided by the env's ``reward_scale``.
    """
    observations, infos = env.reset(seed=seed)
    policy.start(env, seed)
    while env.agents:
        live = env.agents            # agents that left (e.g. failed) are still in the last step's returns
        actions = policy.act({a: observations[a] for a in live}, {a: infos[a] for a in live})
        observations, _, _, _, infos = env.step(actions)
    return env.unwrapped.evaluate()
