"""Training and evaluation: SB3 adapter, pooling network, BC/PPO training, paired evaluation, experiment runner."""
