"""BenchMARL (tested with 1.5.2 and torchrl 0.11): the task suite as a BenchMARL task, ready to train.

``TaskAllocTask`` has one member per task of the suite (``taskalloc_env.suite``: ``SMALL`` is
``taskalloc/Small-v0``, ``LADDER6X12`` is ``taskalloc/Ladder6x12-v0``, …); ``get_task()`` without a config gives the
suite task's own configuration, ``get_task(config={...})`` any keyword arguments of ``parallel_env``. The env comes
through TorchRL's ``PettingZooWrapper`` with the global state, which MAPPO's critic reads::

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig
    from taskalloc_env.wrappers.benchmarl import TaskAllocTask

    Experiment(task=TaskAllocTask.SMALL.get_task(), algorithm_config=MappoConfig.get_from_yaml(),
               model_config=MlpConfig.get_from_yaml(), critic_model_config=MlpConfig.get_from_yaml(), seed=0,
               config=ExperimentConfig.get_from_yaml()).run()

BenchMARL pickles the task into its save folder; the class lives in this module, so it unpickles anywhere taskalloc is
installed. BenchMARL pins ``torchrl<0.12``: install it in its own environment (``scripts/heavy_integrations.sh``).
"""

from __future__ import annotations

from typing import Any

from benchmarl.environments import Task
from benchmarl.environments.common import TaskClass
from benchmarl.environments.pettingzoo.common import PettingZooClass
from torchrl.envs import PettingZooWrapper

from taskalloc_env import suite, taskalloc_v0
from taskalloc_env.config import to_mapping

STEPS_WITHOUT_BOUND = 1000      # BenchMARL's evaluation rollouts when the config sets no max_cycles


class TaskAllocClass(PettingZooClass):
    """The task's config holds ``parallel_env``'s keyword arguments; the specs come from BenchMARL's PettingZoo
    class, which reads them off the wrapped env."""

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any):
        config = {"episode_stats": False, **self.config}     # TorchRL fixes the info keys at the first reset
        return lambda: PettingZooWrapper(taskalloc_v0.parallel_env(**config), categorical_actions=True,
                                         return_state=True, device=device, seed=seed)

    def supports_continuous_actions(self) -> bool:
        return False

    def supports_discrete_actions(self) -> bool:
        return True

    def has_state(self) -> bool:
        return True

    def has_render(self, env: Any) -> bool:
        return False

    def max_steps(self, env: Any) -> int:
        # caps BenchMARL's evaluation rollouts only; the env ends its episodes itself (convergence or its bounds)
        return self.config.get("max_cycles") or STEPS_WITHOUT_BOUND

    @staticmethod
    def env_name() -> str:
        return "taskalloc"


def suite_config(member: str) -> dict[str, Any]:
    """``parallel_env`` keywords of the suite task whose upper-cased name is ``member``."""
    for suite_task in suite.TASKS.values():
        if suite_task.name.upper() == member:
            return {"scenario": to_mapping(suite_task.config())}
    raise KeyError(member)


class TaskAllocTask(Task):
    """The suite's tasks (``taskalloc_env.suite``), one member each."""

    SMALL = None
    DEFAULT = None
    LARGE = None
    HETERO = None
    TIGHTWINDOWS = None
    RANGE = None
    LOSSY = None
    DELAY = None
    DROPOUT = None
    ASYNC = None
    LADDER6X12 = None
    LADDER8X16 = None
    LADDER12X24 = None
    LADDER16X32 = None

    @staticmethod
    def associated_class() -> type[TaskAllocClass]:
        return TaskAllocClass

    def get_task(self, config: dict[str, Any] | None = None) -> TaskClass:
        """The task with ``config`` (``parallel_env``'s keywords), by default the suite task's own."""
        return super().get_task(config=suite_config(self.name) if config is None else config)
