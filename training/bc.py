"""Behaviour cloning: fit the actor to a scripted expert's actions (CBGABI by default), the critic to its returns.

The demonstrations are the expert's own episodes: for every learned agent and step, the observation, the action
mask, the expert's action and the discounted return-to-go of the shared team reward (the critic's target, so that
PPO fine-tuning starts with a value function that matches the cloned policy). The loss is the masked policy's
negative log-likelihood of the expert action plus ``vf_coef`` times the value MSE, minimised with Adam (the
standard imitation warm start before PPO fine-tuning, e.g. AlphaStar's supervised stage, Vinyals et al. 2019).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.policies import ActorCriticPolicy

from taskalloc.policies.base import stack_observations
from taskalloc.policies.registry import make_policy
from taskalloc.policies.teams import ScriptedTeammates, check_scripted_agents
from taskalloc_env.env import TaskAllocEnv


@dataclasses.dataclass
class Demonstrations:
    """Flat arrays over (episode, step, learned agent) samples."""

    observation: np.ndarray     # (S, D) float32
    action_mask: np.ndarray     # (S, A) int8
    action: np.ndarray          # (S,) int64
    returns: np.ndarray         # (S,) float32, discounted return-to-go
    episode_scores: np.ndarray  # (E,) the expert team's score per episode

    def __len__(self) -> int:
        return len(self.action)


def collect_demonstrations(env_kwargs: Mapping[str, Any], n_episodes: int, seed_start: int, expert: str = "cbgabi",
                           scripted_agents: Mapping[str, str] | None = None, gamma: float = 1.0) -> Demonstrations:
    """Run ``expert`` for the learned agents (scripted teammates as configured) on seeds ``seed_start + k``."""
    expert_policy = make_policy(expert)
    env = TaskAllocEnv(**{**env_kwargs, **expert_policy.env_overrides})
    scripted = check_scripted_agents(scripted_agents, env.possible_agents)
    learned = [a for a in env.possible_agents if a not in scripted]
    teammates = ScriptedTeammates(scripted) if scripted else None
    obs_rows, mask_rows, action_rows, return_rows, scores = [], [], [], [], []
    for k in range(n_episodes):
        seed = seed_start + k
        observations, infos = env.reset(seed=seed)
        expert_policy.start(env, seed)
        if teammates is not None:
            teammates.start(env, seed + 1)
        episode_obs, episode_masks, episode_actions, rewards = [], [], [], []
        while env.agents:
            actions = expert_policy.act({a: observations[a] for a in learned}, infos)
            obs, masks = stack_observations(observations, learned)
            episode_obs.append(obs)
            episode_masks.append(masks)
            episode_actions.append(np.array([actions[a] for a in learned]))
            if teammates is not None:
                actions.update(teammates.act({a: observations[a] for a in scripted}, infos))
            observations, reward, _, _, infos = env.step(actions)
            rewards.append(reward[learned[0]])
        returns = np.zeros(len(rewards))
        running = 0.0
        for t in reversed(range(len(rewards))):
            running = rewards[t] + gamma * running
            returns[t] = running
        obs_rows += episode_obs
        mask_rows += episode_masks
        action_rows += episode_actions
        return_rows += [np.full(len(learned), r) for r in returns]
        scores.append(env.evaluate().score)
    return Demonstrations(
        observation=np.concatenate(obs_rows).astype(np.float32),
        action_mask=np.concatenate(mask_rows).astype(np.int8),
        action=np.concatenate(action_rows).astype(np.int64),
        returns=np.concatenate(return_rows).astype(np.float32),
        episode_scores=np.asarray(scores),
    )


MAX_GRAD_NORM = 1.0   # clip the gradient norm of a behaviour-cloning step (SB3's PPO clips at 0.5)


def behaviour_cloning(policy: ActorCriticPolicy, demos: Demonstrations, epochs: int = 10, batch_size: int = 256,
                      learning_rate: float = 1e-3, vf_coef: float = 0.5, ent_coef: float = 0.0, seed: int = 0,
                      log: Any = None) -> list[dict[str, float]]:
    """Train ``policy`` in place on ``demos``; returns per-epoch mean loss, NLL, value MSE and action accuracy.

    ``ent_coef`` > 0 subtracts that much of the policy's entropy, keeping the clone stochastic enough for PPO to
    explore from it.
    """
    rng = np.random.default_rng(seed)
    device = policy.device
    optimizer = th.optim.Adam(policy.parameters(), lr=learning_rate)
    tensors = {
        "observation": th.as_tensor(demos.observation, device=device),
        "action_mask": th.as_tensor(demos.action_mask, device=device),
        "action": th.as_tensor(demos.action, device=device),
        "returns": th.as_tensor(demos.returns, device=device),
    }
    history = []
    policy.set_training_mode(True)
    for epoch in range(epochs):
        order = rng.permutation(len(demos))
        sums = {"loss": 0.0, "nll": 0.0, "entropy": 0.0, "value_mse": 0.0, "accuracy": 0.0}
        for start in range(0, len(order), batch_size):
            idx = th.as_tensor(order[start: start + batch_size], device=device)
            obs = {"observation": tensors["observation"][idx], "action_mask": tensors["action_mask"][idx]}
            features = policy.extract_features(obs, policy.pi_features_extractor)
            logits, latent_vf = policy.mlp_extractor(features)
            log_probs = th.log_softmax(logits, dim=-1)
            action = tensors["action"][idx]
            nll = -log_probs.gather(1, action[:, None]).squeeze(1).mean()
            entropy = -(log_probs.exp() * log_probs).sum(dim=-1).mean()
            value_mse = th.nn.functional.mse_loss(policy.value_net(latent_vf).squeeze(-1), tensors["returns"][idx])
            loss = nll + vf_coef * value_mse - ent_coef * entropy
            optimizer.zero_grad()
            loss.backward()
            th.nn.utils.clip_grad_norm_(policy.parameters(), MAX_GRAD_NORM)
            optimizer.step()
            n = len(idx)
            sums["loss"] += loss.item() * n
            sums["nll"] += nll.item() * n
            sums["entropy"] += entropy.item() * n
            sums["value_mse"] += value_mse.item() * n
            sums["accuracy"] += (logits.argmax(dim=-1) == action).sum().item()
        row = {k: v / len(demos) for k, v in sums.items()}
        row["epoch"] = epoch
        history.append(row)
        if log is not None:
            log(row)
    policy.set_training_mode(False)
    return history
