"""The few adapters other libraries need beyond the environment's defaults, one module per library.

The defaults already suit most libraries (PettingZoo's tests, TorchRL, BenchMARL, Tianshou: no adapter): actions
outside the mask become flagged passes, observations and state are float32, infos hold fixed-key scalars and, on
the step an agent's episode ends, its ``episode`` record (TorchRL and BenchMARL: ``episode_stats=False``, since
TorchRL fixes the info keys at the first reset).

* ``rllib.RLlibObservations``: RLlib's action-masking module reads ``observations`` and ``action_mask``;
* ``agilerl.MaskInInfos``: AgileRL reads the mask from ``infos`` and refuses a mask in the observation;
* ``sb3.sb3_vec_env``: SuperSuit's vector env with ``seed``, ``has_attr`` and ``env_method("action_masks")``, so
  stable-baselines3 PPO and sb3-contrib MaskablePPO run on it.

Each module imports only what it adapts to; ``docs/integrations.md`` has a tested recipe per library.
"""
