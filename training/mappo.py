"""MAPPO: decentralised actors on their own observations, a centralised critic on ``env.state()``, one PPO loop.

    taskalloc mappo --config mappo_small                    # attention actor on train_small
    taskalloc mappo --config mappo_mixture --seed 1         # one model over sizes 4×8 … 10×20
    taskalloc mappo --config mappo_small --out-dir models/mappo_small --overwrite   # the committed one

The loop reads top to bottom in the manner of CleanRL's ``ppo.py`` (Huang et al. 2022, "The 37 Implementation
Details of Proximal Policy Optimization"): config, environments, networks, then rollouts, advantages and clipped
updates. What makes it MAPPO (Yu et al. 2022, "The Surprising Effectiveness of PPO in Cooperative Multi-Agent
Games"):

* every agent acts from its own observation and mask with one shared actor (``taskalloc.policies.networks``:
``attention``
  or ``pooling``), exactly as ``LearnedPolicy`` will at execution;
* the critic (``taskalloc.training.critic.StateCritic``) sees ``env.state()`` and nothing else, and gives one value per
env
  copy and step; every agent of the copy receives the same team reward, so they share that value and advantage;
* only real decisions train the actor: an agent whose mask allows a single action (it has passed in this round,
  or nothing is open to it) contributes nothing to the policy loss or the entropy (its ratio is 1 either way).

A partner (ours, optional): a fixed policy that plays round 0, or every round after it, as part of the
environment's dynamics, while the actor learns the other rounds; its team score is no part of the actor's return when
it plays round 0, and is when it plays the rest. The loop runs without one; ``main(argv, hook)`` takes a
``PartnerHook`` that supplies it (``research.training.partnered`` trains bidders after a learned round-0 planner this
way), and the checkpoint records it in its meta.

Sizes: ``mixture`` lists scenarios (each with its overrides, number of env copies and ``from_steps``, the agent
steps after which it joins: a curriculum). Every rollout collects ``n_steps`` steps from every copy of every active
entry; minibatches never mix sizes. Rewards are the change of the team score divided by c̄ · N (reward × agents),
so returns have the same order of magnitude on every size. An episode cut by ``max_cycles`` is bootstrapped with
the critic's value of its last state (a time limit is not a terminal state, Pardo et al. 2018).

The run writes to ``out_dir``: ``config.yaml``, ``model.json`` + ``model.safetensors`` (the actor, in the project's
checkpoint format, loadable as ``learned:<out_dir>``), ``critic.safetensors`` (for a run that continues this one,
``init_from``), ``eval.csv`` (the greedy policy on the validation seeds of every entry, next to CBGABI), ``train.csv``
(losses and statistics per update) and ``summary.yaml``.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch as th
import yaml
from safetensors.torch import load_file, save_file
from torch import nn

from taskalloc.evaluation.episodes import evaluate, summarise
from taskalloc.evaluation.seeds import TEST_SEEDS, VALIDATION_SEED_START
from taskalloc.policies import checkpoint, make_policy
from taskalloc.policies.base import Policy
from taskalloc.policies.learned import LearnedPolicy, resolve
from taskalloc.policies.networks import (
    RELEASE_BIAS,
    AttentionActor,
    PoolingActor,
    count_parameters,
    with_new_features,
    with_release_head,
)
from taskalloc.training.config import (
    check_at_least,
    check_protocol_options,
    check_types,
    opt,
    parse,
    plain,
    prepare_out_dir,
)
from taskalloc.training.critic import StateCritic
from taskalloc.training.mappo_groups import Group, Partner, PartnerHook
from taskalloc_env.errors import ConfigError, run_cli

ACTORS = ("attention", "pooling")
CRITIC_FILE = "critic.safetensors"      # next to model.json: the critic, for a run that continues this one
ENTRY_KEYS = {"scenario", "overrides", "copies", "from_steps", "label"}
EVAL_COLUMNS = ("steps", "wall_time", "entry", "score", "baseline_score", "ratio", "valid_tasks", "rounds",
                "messages")
TRAIN_COLUMNS = ("update", "steps", "wall_time", "episodes", "episode_score", "policy_loss", "value_loss",
                 "entropy", "approx_kl", "clip_fraction", "explained_variance", "learning_rate", "decisions")


@dataclasses.dataclass
class MappoConfig:
    """Everything a run needs; the resolved copy is saved as ``config.yaml`` next to the model."""

    name: str = opt("mappo", "run name: the default output folder is runs/<name>-<date-time>")
    out_dir: str | None = opt(None, "folder for the model, config, curves and summary (default: a fresh "
                                    "runs/<name>-<date-time>); an existing model there is kept unless --overwrite")
    overwrite: bool = opt(False, "replace a model already in out_dir (needed to regenerate a committed model)")
    seed: int = opt(0, "seed of torch and of the training instances (copy i starts from seed · 1000 + i)")
    # environments
    mixture: list[dict[str, Any]] = dataclasses.field(
        default_factory=lambda: [{"scenario": "train_small", "copies": 16}],
        metadata={"help": "scenarios to train on: [{scenario, overrides, copies, from_steps, label}]; an entry "
                          "joins after from_steps agent steps (a curriculum)"})
    env_overrides: dict[str, Any] = dataclasses.field(
        default_factory=lambda: {"task_quitting": True, "delta": 1},
        metadata={"help": "protocol options the policy plays with, saved in the checkpoint (every runner applies "
                          "them)"})
    max_cycles: int = opt(200, "steps before an episode is truncated (and bootstrapped)")
    # networks
    actor: str = opt("attention", "actor network: attention | pooling (policies.networks)")
    hidden: int = opt(64, "width of the actor and the critic")
    heads: int = opt(4, "attention heads (attention actor and critic)")
    layers: int = opt(2, "self-attention layers of the attention actor")
    init_from: str | None = opt(None, "start from a checkpoint's actor, and its critic when its folder holds "
                                      "critic.safetensors (a run folder or a committed model's name); an actor "
                                      "without release logits may start one with them (releases start rare)")
    release_bias: float = opt(RELEASE_BIAS, "the release logit's bias when init_from widens an actor without "
                                            "release logits (ours; the default keeps releases rare at the start)")
    # PPO
    total_steps: int = opt(1_000_000, "agent steps (one agent's decision in one env step) to train for")
    n_steps: int = opt(64, "steps per env copy in one rollout")
    n_epochs: int = opt(8, "passes over a rollout per update")
    n_minibatches: int = opt(4, "minibatches per entry and pass")
    learning_rate: float = opt(3e-4, "Adam learning rate")
    anneal_lr: bool = opt(True, "decay the learning rate linearly to 0 over the run")
    gamma: float = opt(1.0, "discount (1: the return is the rest of the team score)")
    gae_lambda: float = opt(0.95, "GAE λ")
    clip_range: float = opt(0.2, "PPO clipping range")
    ent_coef: float = opt(0.01, "entropy bonus")
    vf_coef: float = opt(0.5, "value-loss weight")
    max_grad_norm: float = opt(0.5, "gradient-norm clipping")
    target_kl: float | None = opt(None, "stop an update's passes early beyond this KL divergence (null: never)")
    # evaluation, runtime
    eval_freq: int = opt(100_000, "agent steps between evaluations on the validation seeds (0: start and end only)")
    eval_episodes: int = opt(50, "validation instances per entry and evaluation")
    eval_baseline: str = opt("cbgabi", "the scripted policy eval.csv compares with")
    torch_threads: int = opt(1, "torch threads")

    def check(self) -> None:
        """Bad values raise ``ConfigError`` naming the field and what is allowed."""
        check_types(self)
        check_at_least(self, ("hidden", "heads", "layers", "n_steps", "n_epochs", "n_minibatches", "torch_threads",
                              "max_cycles", "eval_episodes"), 1)
        check_at_least(self, ("total_steps", "eval_freq"), 0)
        check_actor(self)
        check_protocol_options(self, "; scenario fields and network conditions go into the mixture entries' "
                                     "overrides")
        if not self.mixture:
            raise ConfigError("training field 'mixture': needs at least one entry")
        for entry in self.mixture:
            if not isinstance(entry, dict) or "scenario" not in entry or set(entry) - ENTRY_KEYS:
                raise ConfigError(f"training field 'mixture': entry {entry!r} must be a mapping with 'scenario' and "
                                  f"optionally {sorted(ENTRY_KEYS - {'scenario'})}")
        if not any(entry.get("from_steps", 0) == 0 for entry in self.mixture):
            raise ConfigError("training field 'mixture': at least one entry must start at from_steps 0")
        copies = sum(int(entry.get("copies", 1)) for entry in self.mixture)
        first, last = self.seed * 1000, self.seed * 1000 + copies - 1
        for label, seeds in (("test", TEST_SEEDS),
                             ("validation", range(VALIDATION_SEED_START, VALIDATION_SEED_START + self.eval_episodes))):
            if first <= seeds.stop - 1 and seeds.start <= last:
                raise ConfigError(f"training seeds {first}..{last} overlap the {label} seeds {seeds.start}.."
                                  f"{seeds.stop - 1}; pick another --seed")


def load_config(argv: Sequence[str] | None = None, hook: PartnerHook | None = None) -> MappoConfig:
    """The run's config: ``MappoConfig``, or the hook's subclass of it (its configs folder resolves names first)."""
    cls, prog = (MappoConfig, "taskalloc mappo") if hook is None else (hook.config, hook.prog)
    cfg = parse(cls, argv, prog, __doc__, configs=None if hook is None else hook.configs)
    cfg.out_dir = cfg.out_dir or f"runs/{cfg.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    cfg.check()
    return cfg


# -- networks ---------------------------------------------------------------------------------------------------------
class ActorSpec(Protocol):
    """The config fields an actor is built from (``MappoConfig``, and research's distillation and planner configs)."""

    actor: str
    hidden: int
    heads: int
    layers: int


def check_actor(cfg: ActorSpec) -> None:
    """A known actor network, and a width the attention heads divide (``ConfigError`` naming the field)."""
    if cfg.actor not in ACTORS:
        raise ConfigError(f"training field 'actor': got {cfg.actor!r}; allowed: {' | '.join(ACTORS)}")
    if cfg.hidden % cfg.heads:
        raise ConfigError(f"training field 'hidden': {cfg.hidden} must be a multiple of heads={cfg.heads}")


def make_actor(cfg: ActorSpec, own_size: int, task_size: int, kinds: int = 2) -> nn.Module:
    """The config's actor network; ``kinds``: logits per task, 3 where the environment has release actions."""
    if cfg.actor == "attention":
        return AttentionActor(own_size, task_size, cfg.hidden, cfg.heads, cfg.layers, kinds)
    return PoolingActor(own_size, task_size, cfg.hidden, kinds)


class ActorCritic(nn.Module):
    """The shared actor (observation + mask → masked logits) and the critic (state → value), kept apart."""

    def __init__(self, actor: nn.Module, critic: StateCritic) -> None:
        super().__init__()
        self.actor, self.critic = actor, critic
        for layer in actor.output_layers():        # near-uniform initial policy (CleanRL: std 0.01 for the logits)
            nn.init.orthogonal_(layer.weight, gain=0.01)
            nn.init.zeros_(layer.bias)

    def policy(self, obs: th.Tensor, mask: th.Tensor) -> th.distributions.Categorical:
        return th.distributions.Categorical(logits=self.actor(obs, mask))

    def value(self, state: th.Tensor, n_agents: int, n_tasks: int) -> th.Tensor:
        return self.critic(state, n_agents, n_tasks)


# -- rollouts and advantages -----------------------------------------------------------------------------------------
@dataclasses.dataclass
class Rollout:
    """One entry's samples: actor samples per (step, copy, agent), critic samples per (step, copy)."""

    obs: th.Tensor          # (T·C·N, D)
    masks: th.Tensor        # (T·C·N, A) bool
    actions: th.Tensor      # (T·C·N,)
    logprobs: th.Tensor     # (T·C·N,)
    agent_adv: th.Tensor    # (T·C·N,) the copy's advantage, for each of its agents
    decisions: th.Tensor    # (T·C·N,) bool: more than one valid action
    states: th.Tensor       # (T·C, S)
    values: th.Tensor       # (T·C,)
    returns: th.Tensor      # (T·C,)
    n_agents: int
    n_tasks: int


def collect(model: ActorCritic, group: Group, n_steps: int, gamma: float, gae_lambda: float) -> Rollout:
    """``n_steps`` steps of every copy of ``group``; GAE(λ) on the critic's values (Schulman et al. 2016)."""
    c, n = group.copies, group.n_agents
    obs, masks, actions, logprobs, states, values, rewards, dones = ([] for _ in range(8))
    for _ in range(n_steps):        # copies: the group's arrays are overwritten in place by the next step
        o = th.tensor(group.obs, dtype=th.float32).reshape(c * n, -1)
        m = th.as_tensor(group.masks > 0).reshape(c * n, -1)
        s = th.tensor(group.states, dtype=th.float32)
        with th.no_grad():
            dist = model.policy(o, m)
            action = dist.sample()
            value = model.value(s, n, group.n_tasks)
        reward, done, cut = group.step(action.reshape(c, n).numpy())
        for i, last_state in enumerate(cut):       # a time limit: add the value of where the copy was cut off
            if last_state is not None:
                with th.no_grad():
                    last = th.as_tensor(last_state[None], dtype=th.float32)
                    reward[i] += gamma * float(model.value(last, n, group.n_tasks))
        obs.append(o), masks.append(m), actions.append(action), logprobs.append(dist.log_prob(action))
        states.append(s), values.append(value)
        rewards.append(th.as_tensor(reward, dtype=th.float32)), dones.append(th.as_tensor(done, dtype=th.float32))
    with th.no_grad():
        next_value = model.value(th.as_tensor(group.states, dtype=th.float32), n, group.n_tasks)
    values_t, rewards_t, dones_t = th.stack(values), th.stack(rewards), th.stack(dones)      # (T, C)
    advantages = th.zeros_like(rewards_t)
    gae = th.zeros(c)
    for t in reversed(range(n_steps)):
        following = next_value if t == n_steps - 1 else values_t[t + 1]
        alive = 1.0 - dones_t[t]
        delta = rewards_t[t] + gamma * following * alive - values_t[t]
        gae = delta + gamma * gae_lambda * alive * gae
        advantages[t] = gae
    masks_t = th.cat(masks)
    return Rollout(obs=th.cat(obs), masks=masks_t, actions=th.cat(actions), logprobs=th.cat(logprobs),
                   agent_adv=advantages.reshape(-1).repeat_interleave(n), decisions=masks_t.sum(dim=1) > 1,
                   states=th.cat(states), values=values_t.reshape(-1), returns=(advantages + values_t).reshape(-1),
                   n_agents=n, n_tasks=group.n_tasks)


# -- the clipped PPO update ------------------------------------------------------------------------------------------
def update(model: ActorCritic, optimizer: th.optim.Optimizer, rollouts: Sequence[Rollout], cfg: MappoConfig,
           rng: np.random.Generator) -> dict[str, float]:
    """``n_epochs`` passes; each pass splits every entry's decisions and states into ``n_minibatches``."""
    stats: dict[str, list[float]] = {k: [] for k in ("policy_loss", "value_loss", "entropy", "approx_kl",
                                                       "clip_fraction")}
    for _ in range(cfg.n_epochs):
        batches = []
        for r in rollouts:
            decisions = th.nonzero(r.decisions).squeeze(1).numpy()
            actor_parts = np.array_split(rng.permutation(decisions), cfg.n_minibatches)
            critic_parts = np.array_split(rng.permutation(len(r.states)), cfg.n_minibatches)
            batches += [(r, th.as_tensor(a), th.as_tensor(v)) for a, v in zip(actor_parts, critic_parts)]
        kls = []
        for i in rng.permutation(len(batches)):
            r, a_idx, v_idx = batches[i]
            value = model.value(r.states[v_idx], r.n_agents, r.n_tasks)
            value_loss = 0.5 * ((value - r.returns[v_idx]) ** 2).mean()
            loss = cfg.vf_coef * value_loss
            if len(a_idx):
                dist = model.policy(r.obs[a_idx], r.masks[a_idx])
                log_ratio = dist.log_prob(r.actions[a_idx]) - r.logprobs[a_idx]
                ratio = log_ratio.exp()
                adv = r.agent_adv[a_idx]
                adv = (adv - adv.mean()) / (adv.std(unbiased=False) + 1e-8)
                policy_loss = th.max(-adv * ratio, -adv * ratio.clamp(1 - cfg.clip_range, 1 + cfg.clip_range)).mean()
                entropy = dist.entropy().mean()
                loss = loss + policy_loss - cfg.ent_coef * entropy
                with th.no_grad():          # the k3 estimator of KL(old ‖ new) (Schulman 2020, CleanRL)
                    kls.append(float(((ratio - 1) - log_ratio).mean()))
                    stats["clip_fraction"].append(float(((ratio - 1).abs() > cfg.clip_range).float().mean()))
                stats["policy_loss"].append(policy_loss.item())
                stats["entropy"].append(entropy.item())
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), cfg.max_grad_norm)
            optimizer.step()
            stats["value_loss"].append(value_loss.item())
        stats["approx_kl"] += kls
        if cfg.target_kl is not None and kls and np.mean(kls) > cfg.target_kl:
            break
    return {k: float(np.mean(v)) if v else float("nan") for k, v in stats.items()}


def explained_variance(values: th.Tensor, returns: th.Tensor) -> float:
    """1 − Var(returns − values) / Var(returns): 1 for a perfect critic, ≤ 0 for one no better than a constant."""
    var = float(returns.var())
    return float("nan") if var == 0 else 1.0 - float((returns - values).var()) / var


# -- evaluation and checkpoints --------------------------------------------------------------------------------------
class Evaluator:
    """The greedy policy on every entry's validation seeds, next to the baseline on the same seeds (eval.csv)."""

    def __init__(self, groups: Sequence[Group], cfg: MappoConfig, path: Path) -> None:
        self.groups, self.cfg, self.path = groups, cfg, path
        self.seeds = range(VALIDATION_SEED_START, VALIDATION_SEED_START + cfg.eval_episodes)
        baseline = make_policy(cfg.eval_baseline)
        self.baseline = {g.label: summarise(evaluate(baseline, g.env_kwargs, self.seeds))["score"] for g in groups}
        with open(path, "w", newline="") as fh:
            csv.writer(fh).writerow(EVAL_COLUMNS)

    def __call__(self, model: ActorCritic, steps: int, wall: float) -> dict[str, float]:
        """One row per entry; returns the score ratio to the baseline per entry."""
        policy = as_played(as_learned(model.actor, self.groups[0], self.cfg), self.groups[0].partner)
        model.actor.eval()
        ratios = {}
        with open(self.path, "a", newline="") as fh:
            for g in self.groups:
                stats = summarise(evaluate(policy, g.env_kwargs, self.seeds))
                ratios[g.label] = stats["score"] / self.baseline[g.label]
                row = {"steps": steps, "wall_time": round(wall, 1), "entry": g.label, **stats,
                       "baseline_score": self.baseline[g.label], "ratio": ratios[g.label]}
                csv.writer(fh).writerow([row[c] for c in EVAL_COLUMNS])
        model.actor.train()
        return ratios


def load_weights(model: ActorCritic, source: str, hook: PartnerHook | None = None,
                 release_bias: float = RELEASE_BIAS, names: tuple[tuple[str, ...], tuple[str, ...]] | None = None,
                 ) -> list[str]:
    """Start from a checkpoint's actor weights and, when its folder holds one, its critic (``init_from``); an actor
    without release logits starts one with them (``with_release_head``, its release logit at ``release_bias``). When
    this run's observation features ``names`` (own, per task) add to the source's, the actor's new inputs start at
    zero (``with_new_features``) and the critic, whose state then differs too, starts afresh."""
    json_path = Path(str(resolve(source)))
    json_path = json_path / "model.json" if json_path.is_dir() else json_path.with_suffix(".json")
    source_checkpoint = checkpoint.load(json_path)
    actor_state = source_checkpoint.actor.state_dict()
    source_names = (source_checkpoint.own_features, source_checkpoint.task_features)
    widened = names is not None and tuple(map(tuple, source_names)) != tuple(map(tuple, names))
    if widened:
        try:
            actor_state = with_new_features(model.actor, actor_state, source_names, names)
        except ValueError as exc:
            raise ConfigError(f"init_from {source}: {exc}") from None
    source_kinds, kinds = getattr(source_checkpoint.actor, "kinds", 2), getattr(model.actor, "kinds", 2)
    if (source_kinds, kinds) == (2, 3):
        try:
            actor_state = with_release_head(model.actor, actor_state, release_bias)
        except ValueError as exc:
            raise ConfigError(f"init_from {source}: {exc}") from None
    elif source_kinds != kinds:
        raise ConfigError(f"init_from {source}: its actor has release logits and this run has no release_actions; "
                          "only an actor without them can start one with them")
    states = [("actor", model.actor, actor_state)]
    if (json_path.parent / CRITIC_FILE).is_file() and not widened:
        states.append(("critic", model.critic, load_file(str(json_path.parent / CRITIC_FILE))))
    for name, module, state in states:
        try:
            module.load_state_dict(state, strict=True)
        except RuntimeError as exc:
            raise ConfigError(f"init_from {source}: its {name} does not fit this run's networks (actor, hidden, "
                              f"heads, layers): {str(exc).splitlines()[0]}") from None
    if hook is not None:
        hook.init_actor(model.actor, source_checkpoint.meta)
    return [name for name, _, _ in states]


def as_learned(actor: nn.Module, group: Group, cfg: MappoConfig) -> LearnedPolicy:
    return LearnedPolicy(actor, group.layout.own_names, group.layout.task_names, cfg.env_overrides, name=cfg.name)


def as_played(bidder: LearnedPolicy, partner: Partner | None) -> Policy:
    """The bidder as it plays, with the run's partner when it has one (what its checkpoint loads as)."""
    return bidder if partner is None else partner.with_actor(bidder)


def save_actor(stem: Path, actor: nn.Module, group: Group, cfg: MappoConfig, meta: Mapping[str, Any]) -> Path:
    """The actor as a checkpoint (``taskalloc.policies.checkpoint``): what ``learned:<path>`` loads."""
    return checkpoint.save(stem, actor, group.layout.own_names, group.layout.task_names, cfg.env_overrides, meta)


# -- the run -----------------------------------------------------------------------------------------------------------
def main(argv: Sequence[str] | None = None, hook: PartnerHook | None = None) -> dict[str, Any]:
    """Train; ``hook`` (optional) supplies a partner and its config fields (see the module docstring)."""
    cfg = load_config(argv, hook)
    out_dir = prepare_out_dir(cfg.out_dir, cfg.overwrite)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    th.set_num_threads(cfg.torch_threads)
    th.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    summary: dict[str, Any] = {"command": " ".join([hook.prog if hook else "taskalloc mappo",
                                                    *(argv or sys.argv[1:])]),
                               "cpu_count": os.cpu_count(), "load_average_at_start": round(os.getloadavg()[0], 2)}
    t_start, cpu_start = time.perf_counter(), time.process_time()

    # -- environments: one group of copies per mixture entry ----------------------------------------------------------
    groups, first, partner = [], cfg.seed * 1000, hook.partner(cfg) if hook is not None else None
    for entry in cfg.mixture:
        groups.append(Group(entry, cfg.env_overrides, cfg.max_cycles, first, partner))
        first += groups[-1].copies
    layout = groups[0].layout
    for g in groups:
        if (g.layout.own_names, g.layout.task_names) != (layout.own_names, layout.task_names):
            raise ConfigError(f"mixture entry {g.label!r} has other observation features than {groups[0].label!r} "
                              f"(own {g.layout.own_names}, per task {g.layout.task_names}); one actor needs one "
                              "feature set (e.g. every entry on a faulty network, or none)")
        if g.kinds != (3 if cfg.env_overrides.get("release_actions") else 2):
            raise ConfigError(f"mixture entry {g.label!r}: release_actions goes into env_overrides (the checkpoint "
                              "keeps them, so its policy plays with release actions), not into an entry's overrides")
        g.reset()

    # -- networks --------------------------------------------------------------------------------------------------
    actor = make_actor(cfg, layout.own_size, layout.task_size, groups[0].kinds)
    model = ActorCritic(actor, StateCritic(layout.n_equipment, cfg.hidden, cfg.heads))
    if cfg.init_from:
        summary["init_from"] = load_weights(model, cfg.init_from, hook, cfg.release_bias,
                                              (layout.own_names, layout.task_names))
    optimizer = th.optim.Adam(model.parameters(), lr=cfg.learning_rate, eps=1e-5)
    summary["parameters"] = {"actor": count_parameters(model.actor), "critic": count_parameters(model.critic)}
    evaluator = Evaluator(groups, cfg, out_dir / "eval.csv")

    # -- PPO ---------------------------------------------------------------------------------------------------------
    steps, env_steps, next_eval, update_i, t0 = 0, 0, 0, 0, time.perf_counter()
    with open(out_dir / "train.csv", "w", newline="") as fh:
        csv.writer(fh).writerow(TRAIN_COLUMNS)
    while steps < cfg.total_steps:
        if steps >= next_eval:
            evaluator(model, steps, time.perf_counter() - t0)
            next_eval = steps + cfg.eval_freq if cfg.eval_freq else cfg.total_steps
        lr = cfg.learning_rate * (1 - steps / cfg.total_steps) if cfg.anneal_lr else cfg.learning_rate
        for param_group in optimizer.param_groups:
            param_group["lr"] = lr
        active = [g for g in groups if g.from_steps <= steps]
        rollouts = [collect(model, g, cfg.n_steps, cfg.gamma, cfg.gae_lambda) for g in active]
        steps += sum(cfg.n_steps * g.copies * g.n_agents for g in active)
        env_steps += sum(cfg.n_steps * g.copies for g in active)
        stats = update(model, optimizer, rollouts, cfg, rng)
        update_i += 1
        finished = [s for g in active for s in g.scores]
        for g in active:
            g.scores.clear()
        row = {"update": update_i, "steps": steps, "wall_time": round(time.perf_counter() - t0, 1),
               "episodes": len(finished), "episode_score": float(np.mean(finished)) if finished else float("nan"),
               **stats, "learning_rate": lr,
               "explained_variance": explained_variance(th.cat([r.values for r in rollouts]),
                                                        th.cat([r.returns for r in rollouts])),
               "decisions": int(sum(int(r.decisions.sum()) for r in rollouts))}
        with open(out_dir / "train.csv", "a", newline="") as fh:
            csv.writer(fh).writerow([f"{row[c]:.6g}" if isinstance(row[c], float) else row[c] for c in TRAIN_COLUMNS])
        print(f"update {update_i}: {steps} steps, {row['wall_time']} s, episode score {row['episode_score']:.1f}, "
              f"entropy {stats['entropy']:.3f}, kl {stats['approx_kl']:.4f}, "
              f"explained variance {row['explained_variance']:.2f}", flush=True)
    seconds = time.perf_counter() - t0

    # -- save ----------------------------------------------------------------------------------------------------------
    ratios = evaluator(model, steps, seconds)
    save_actor(out_dir / "model", model.actor, groups[0], cfg,
               {"name": cfg.name, "algo": "mappo", "seed": cfg.seed, "steps": steps,
                "mixture": [g.label for g in groups], "init_from": cfg.init_from,
                **(partner.meta if partner is not None else {})})
    save_file({k: v.contiguous() for k, v in model.critic.state_dict().items()}, str(out_dir / CRITIC_FILE))
    summary.update(steps=steps, env_steps=env_steps, updates=update_i, train_seconds=round(seconds, 1),
                   agent_steps_per_second=round(steps / seconds, 1) if seconds else None,
                   env_steps_per_second=round(env_steps / seconds, 1) if seconds else None,
                   validation_ratio=ratios,
                   cpu_seconds=round(time.process_time() - cpu_start, 1),
                   load_average_at_end=round(os.getloadavg()[0], 2),
                   wall_seconds=round(time.perf_counter() - t_start, 1))
    (out_dir / "summary.yaml").write_text(yaml.safe_dump(plain(summary), sort_keys=False))
    print(yaml.safe_dump(plain(summary), sort_keys=False), flush=True)
    return summary


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
