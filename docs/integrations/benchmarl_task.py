"""BenchMARL: the shipped task class (taskalloc_env.wrappers.benchmarl), MAPPO and IPPO for 2 tiny iterations on the
suite's Small task, with the state for MAPPO's critic."""

import tempfile

import torch
from benchmarl.algorithms import IppoConfig, MappoConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig

from taskalloc_env.wrappers.benchmarl import TaskAllocTask


def main(iterations: int = 2) -> dict[str, int]:
    torch.set_num_threads(1)
    cfg = ExperimentConfig.get_from_yaml()
    cfg.max_n_iters, cfg.on_policy_collected_frames_per_batch, cfg.on_policy_n_envs_per_worker = iterations, 200, 2
    cfg.on_policy_n_minibatch_iters, cfg.on_policy_minibatch_size = 2, 100
    cfg.evaluation, cfg.render, cfg.loggers, cfg.create_json = False, False, ["csv"], False
    cfg.save_folder = tempfile.mkdtemp()
    done = {}
    for algo in (MappoConfig, IppoConfig):
        experiment = Experiment(task=TaskAllocTask.SMALL.get_task(),           # taskalloc/Small-v0's configuration
                                algorithm_config=algo.get_from_yaml(), model_config=MlpConfig.get_from_yaml(),
                                critic_model_config=MlpConfig.get_from_yaml(), seed=0, config=cfg)
        experiment.run()
        done[algo.__name__] = experiment.total_frames
    return done


if __name__ == "__main__":
    print(main())
