"""Reinforcement learning of bidding policies: the SB3 vector-env adapter, behaviour cloning, PPO training runs,
callbacks and learning curves. Evaluation lives in ``evaluation``, the networks and the learned policy in
``policies``."""

from importlib.util import find_spec

if find_spec("torch") is None:         # every trainer needs torch; say which extra brings it, not a bare traceback
    raise ImportError("training needs torch: pip install 'taskalloc[train]' (SB3 PPO and the MAPPO loop) or "
                      "'taskalloc[ray]' (RLlib PPO)")
