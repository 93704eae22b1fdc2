"""Reinforcement learning of bidding policies: the SB3 vector-env adapter, behaviour cloning, PPO training runs,
callbacks and learning curves. Evaluation lives in ``evaluation``, the networks and the learned policy in
``policies``."""
