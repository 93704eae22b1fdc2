"""BenchMARL: a minimal task for the env (through TorchRL's PettingZooWrapper), MAPPO and IPPO for 2 tiny iterations.

BenchMARL pickles the task into its save folder, so the task class must be importable: define it in a module
(run this file as a script, or import it), not in code that is exec'd.
"""

import tempfile

import torch
from benchmarl.algorithms import IppoConfig, MappoConfig
from benchmarl.environments import Task
from benchmarl.environments.pettingzoo.common import PettingZooClass
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig
from torchrl.envs import PettingZooWrapper

from taskalloc_env import taskalloc_v0


class TaskAllocClass(PettingZooClass):
    """The task config holds the env's keyword arguments; the specs are read by BenchMARL's PettingZoo class."""

    def get_env_fun(self, num_envs, continuous_actions, seed, device):
        config = {"episode_stats": False, **self.config}     # TorchRL fixes the info keys at the first reset
        return lambda: PettingZooWrapper(taskalloc_v0.parallel_env(**config), categorical_actions=True,
                                         return_state=True, device=device, seed=seed)

    def supports_continuous_actions(self):
        return False

    def supports_discrete_actions(self):
        return True

    def has_state(self):
        return True

    def has_render(self, env):
        return False

    def max_steps(self, env):
        # caps BenchMARL's evaluation rollouts only; episodes end by themselves (convergence or the round bound)
        return self.config.get("max_cycles") or 1000

    @staticmethod
    def env_name():
        return "taskalloc"


class TaskAllocTask(Task):
    TRAIN_SMALL = None

    @staticmethod
    def associated_class():
        return TaskAllocClass


def main(iterations: int = 2) -> dict[str, int]:
    torch.set_num_threads(1)
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_iters, cfg.on_policy_collected_frames_per_batch, cfg.on_policy_n_envs_per_worker = iterations, 200, 2
    cfg.on_policy_n_minibatch_iters, cfg.on_policy_minibatch_size = 2, 100
    cfg.evaluation, cfg.render, cfg.loggers, cfg.create_json = False, False, ["csv"], False
    cfg.save_folder = tempfile.mkdtemp()
    done = {}
    for algo in (MappoConfig, IppoConfig):
        experiment = Experiment(task=TaskAllocTask.TRAIN_SMALL.get_task(config={"scenario": "train_small"}),
                                algorithm_config=algo.get_from_yaml(), model_config=MlpConfig.get_from_yaml(),
                                critic_model_config=MlpConfig.get_from_yaml(), seed=0, config=cfg)
        experiment.run()
        done[algo.__name__] = experiment.total_frames
    return done


if __name__ == "__main__":
    print(main())
