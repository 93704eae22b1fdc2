"""Ray RLlib (tested with 2.60, new API stack): the env creator, and observation keys for its action-masking module.

``ray.rllib.examples.rl_modules.classes.action_masking_rlm.ActionMaskingTorchRLModule`` reads the keys
``observations`` and ``action_mask``; this env names the first ``observation`` (PettingZoo's convention), which
``RLlibObservations`` renames. ``env_creator`` is what ``register_env`` takes: its ``env_config`` holds
``parallel_env``'s keywords, or ``{"task": "taskalloc/Small-v0"}`` for a task of the suite (more keywords override
the task's)::

    from ray.tune.registry import register_env
    from taskalloc_env.wrappers.rllib import env_creator

    register_env("taskalloc", env_creator)
    PPOConfig().environment("taskalloc", env_config={"task": "taskalloc/Small-v0"})
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from gymnasium import spaces

from taskalloc_env import suite, taskalloc_v0
from taskalloc_env.config import to_mapping
from taskalloc_env.wrappers._obs import ObservationWrapper


def make_env(env_config: Mapping[str, Any] | None = None) -> RLlibObservations:
    """The parallel env of ``env_config`` (``parallel_env``'s keywords; ``task``: a suite id) with RLlib's keys."""
    config = dict(env_config or {})
    task_id = config.pop("task", None)
    if task_id is not None:
        config = {"scenario": to_mapping(suite.task(task_id).config()), **config}
    return RLlibObservations(taskalloc_v0.parallel_env(**config))


def env_creator(env_config: Mapping[str, Any] | None = None) -> Any:
    """RLlib's env creator (``register_env("taskalloc", env_creator)``): ``make_env`` in ``ParallelPettingZooEnv``."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    return ParallelPettingZooEnv(make_env(env_config))


class RLlibObservations(ObservationWrapper):
    """``{"observation", "action_mask"}`` → ``{"observations", "action_mask"}``."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        inner = env.observation_space(env.possible_agents[0])
        self.space = spaces.Dict({"observations": inner["observation"], "action_mask": inner["action_mask"]})

    def observation(self, obs: dict[str, Any], info: dict[str, Any]) -> dict[str, Any]:
        return {"observations": obs["observation"], "action_mask": obs["action_mask"]}
