"""taskalloc: decentralised multi-agent task allocation (CBBA, CBGA, CBGABI) as a PettingZoo environment.

Importing the package registers ``taskalloc/TaskAlloc-v0`` and the task suite's ids (``taskalloc/Default-v0``, …,
``taskalloc_env.suite``) for ``pettingzoo.make("parallel", ...)`` and
``pettingzoo.make("aec", ...)``.
"""

from __future__ import annotations

import pettingzoo

from taskalloc_env.allocation import Allocation
from taskalloc_env.config import TaskAllocConfig, load_config, resolve_config
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, InvalidActionError
from taskalloc_env.observation import ObservationLayout
from taskalloc_env.scenario import Agent, Scenario, Task, generate
from taskalloc_env.suite import register_suite
from taskalloc_env.vector import TaskAllocVectorEnv, vector_env

ENV_ID = "taskalloc/TaskAlloc-v0"

if hasattr(pettingzoo, "register"):        # PettingZoo >= 1.27 has a registry; on older releases (AgileRL pins < 1.27)
    pettingzoo.register("parallel", ENV_ID, entry_point="taskalloc_env.taskalloc_v0:parallel_env")   # use
    pettingzoo.register("aec", ENV_ID, entry_point="taskalloc_env.taskalloc_v0:env")                 # taskalloc_v0
register_suite()                            # the benchmark's task suite: taskalloc/<Task>-v0 (taskalloc_env.suite)

__all__ = [
    "ENV_ID",
    "Agent",
    "Allocation",
    "ConfigError",
    "InvalidActionError",
    "ObservationLayout",
    "Scenario",
    "Task",
    "TaskAllocConfig",
    "TaskAllocEnv",
    "TaskAllocVectorEnv",
    "generate",
    "load_config",
    "resolve_config",
    "vector_env",
]
