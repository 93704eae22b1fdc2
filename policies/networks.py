"""Actor networks of learned bidding policies: observation and action mask in, masked logits out (pure torch).

The observation is ``[own features | task_0 features | … | task_{M−1} features]`` (``taskalloc_env.observation``);
the logits are ``[pass, bid_0 … bid_{M−1}, quit_0 … quit_{M−1}]``, or with ``kinds=3`` (the environment's
``release_actions``) ``[…, release_0 … release_{M−1}]`` too (``taskalloc_env.actions``); invalid actions are set to
``MASKED_LOGIT``.

* ``pooling``: every task's features, concatenated with the agent's own features, go through one shared encoder;
  mean- and max-pooling over tasks gives a context. Each task's embedding with the context gives that task's bid
  and quit logits (and its release logit with ``kinds=3``), the context alone the pass logit (a Deep-Sets network,
  Zaheer et al. 2017). No weight depends on M, so one set of weights serves any number of tasks.
* ``attention``: every task's features with the agent's own features form a task token; self-attention layers
  let the tokens see each other (a Transformer encoder without positional encoding, Vaswani et al. 2017, so the
  tokens form a set as in the Set Transformer, Lee et al. 2019); the agent's own features, embedded, are the query
  of one attention read-out over the tokens, which gives the context. Each token with the context gives that
  task's bid and quit (and release) logits, the context the pass logit. Like ``pooling``, no weight depends on M
  or N; unlike it, a task's logits can depend on every other task (which tasks compete for the same agents, which
  groups are nearly complete), not only through a mean and a max.
* ``mlp``: a plain MLP from the flat observation to the 1 + 2M (or 1 + 3M) logits (fixed M).

``NETWORKS`` names every class a checkpoint may ask for; each takes only integer sizes, so a checkpoint's
architecture is plain JSON (``taskalloc.policies.checkpoint``). Training wraps these actors with a critic
(``taskalloc.training.sb3_policy``, ``taskalloc.training.mappo``).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import ClassVar

import numpy as np
import torch as th
from torch import nn

MASKED_LOGIT = -1e8
KINDS = (2, 3)      # logits per task: bid and quit, or bid, quit and release (``release_actions``)
RELEASE_BIAS = -4.0     # ours: a warm-started release logit (``with_release_head``), e^−4 ≈ 2 % of a zero logit's odds


def mlp(sizes: list[int], activate_last: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if activate_last or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


def check_kinds(kinds: int) -> None:
    """Refuse a number of logits per task other than 2 or 3 (``KINDS``)."""
    if kinds not in KINDS:
        raise ValueError(f"kinds={kinds}: a task has 2 logits (bid, quit) or 3 (bid, quit, release)")


def with_release_head(actor: nn.Module, state: Mapping[str, th.Tensor],
                      bias: float = RELEASE_BIAS) -> dict[str, th.Tensor]:
    """The weights ``state`` of a two-kind actor, widened for ``actor``, the same network with release logits (ours).

    Every weight is copied; the task head's output layer gains a release row of zero weights and a bias of ``bias``
    (``RELEASE_BIAS``), so the release logit starts as that constant whatever the observation and releases start
    rare, while the pass, bid and quit logits are the source's. Any other difference is refused in one line."""
    if getattr(actor, "kinds", None) != 3:
        raise ValueError(f"with_release_head widens into an actor with release logits (kinds=3), not a "
                         f"{type(actor).__name__} with kinds={getattr(actor, 'kinds', None)}")
    head = next(name for name, module in actor.named_modules() if module is actor.task_head[-1])
    own = actor.state_dict()
    if set(state) != set(own):
        raise ValueError(f"the source does not fit this {actor.name} actor: weights "
                         f"{sorted(set(state) ^ set(own))[:3]} differ")
    widened = {}
    for key, value in state.items():
        if key in (f"{head}.weight", f"{head}.bias") and value.shape[0] == 2 and own[key].shape[1:] == value.shape[1:]:
            release = th.full_like(value[:1], bias) if key.endswith("bias") else th.zeros_like(value[:1])
            value = th.cat([value, release])
        if value.shape != own[key].shape:
            raise ValueError(f"the source's {key} has shape {tuple(value.shape)}, this actor's "
                             f"{tuple(own[key].shape)} (hidden, heads and layers must match)")
        widened[key] = value.clone()
    return widened


def with_new_features(actor: nn.Module, state: Mapping[str, th.Tensor], source: tuple[Sequence[str], Sequence[str]],
                      names: tuple[Sequence[str], Sequence[str]]) -> dict[str, th.Tensor]:
    """The weights ``state`` of a pooling actor over the observation features ``source`` (own, per task), for
    ``actor``, the same network over ``names``, which hold every source feature and more (ours; the fault feature
    of a lossy or delayed network, say). The input layer's columns are copied by name and a new feature's column is
    zero, so the widened actor's logits are the source's whatever the new features hold."""
    if getattr(actor, "name", None) != "pooling":
        raise ValueError("only the pooling actor takes new observation features, not the "
                         f"{getattr(actor, 'name', actor)} actor")
    (source_own, source_task), (own, task) = source, names
    missing = sorted((set(source_own) - set(own)) | (set(source_task) - set(task)))
    if missing:
        raise ValueError(f"this run's observation lacks the source's features {missing}")
    key = "actor.encode.0.weight"                       # PoolingEncoder.encode over [task features | own features]
    weight = state[key]
    if weight.shape[1] != len(source_task) + len(source_own):
        raise ValueError(f"the source's {key} has {weight.shape[1]} inputs, its features name "
                         f"{len(source_task) + len(source_own)}")
    widened = weight.new_zeros((weight.shape[0], len(task) + len(own)))
    for k, name in enumerate(task):
        if name in source_task:
            widened[:, k] = weight[:, source_task.index(name)]
    for k, name in enumerate(own):
        if name in source_own:
            widened[:, len(task) + k] = weight[:, len(source_task) + source_own.index(name)]
    return {**state, key: widened}


def task_logits(pass_logit: th.Tensor, per_task: th.Tensor, mask: th.Tensor, name: str) -> th.Tensor:
    """``[pass | kind 0 of every task | kind 1 … ]`` (B, 1 + K·M) from the pass logit (B, 1) and the per-task logits
    (B, M, K), masked; a mask of another width is refused."""
    n_tasks, kinds = per_task.shape[1], per_task.shape[2]
    if mask.shape[-1] != 1 + kinds * n_tasks:
        actions = "bid, quit, release" if kinds == 3 else "bid, quit"
        raise ValueError(f"the {name} actor has {kinds} actions per task ({actions}): with {n_tasks} tasks it "
                         f"takes a mask of 1 + {kinds}·{n_tasks} = {1 + kinds * n_tasks} "
                         f"columns, got {mask.shape[-1]}")
    logits = th.cat([pass_logit, *per_task.unbind(dim=-1)], dim=-1)
    return logits.masked_fill(~mask, MASKED_LOGIT)


def split_tasks(observation: th.Tensor, own_size: int, task_size: int) -> tuple[th.Tensor, th.Tensor]:
    """``[own | tasks]`` (B, D) → own (B, O), tasks (B, M, F); M follows from the width."""
    n_tasks, rest = divmod(observation.shape[-1] - own_size, task_size)
    if rest or n_tasks < 1:
        raise ValueError(f"observation width {observation.shape[-1]} does not fit own_size={own_size}, "
                         f"task_size={task_size}: expected own_size + M * task_size")
    return observation[:, :own_size], observation[:, own_size:].reshape(-1, n_tasks, task_size)


class PoolingEncoder(nn.Module):
    """Per-task embeddings from a shared encoder and a context from mean- and max-pooling them."""

    def __init__(self, own_size: int, task_size: int, hidden: int) -> None:
        super().__init__()
        self.encode = mlp([task_size + own_size, hidden, hidden])
        self.context = mlp([2 * hidden, hidden])

    def forward(self, own: th.Tensor, tasks: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        own_per_task = own.unsqueeze(1).expand(-1, tasks.shape[1], -1)
        embedded = self.encode(th.cat([tasks, own_per_task], dim=-1))                 # (B, M, H)
        pooled = th.cat([embedded.mean(dim=1), embedded.amax(dim=1)], dim=-1)         # (B, 2H)
        return embedded, self.context(pooled)


class PoolingActor(nn.Module):
    """The pooling actor: any number of tasks, the same per-task and own features."""

    name: ClassVar[str] = "pooling"

    def __init__(self, own_size: int, task_size: int, hidden: int = 64, kinds: int = 2) -> None:
        super().__init__()
        check_kinds(kinds)
        self.own_size, self.task_size, self.hidden, self.kinds = own_size, task_size, hidden, kinds
        self.actor = PoolingEncoder(own_size, task_size, hidden)
        self.task_head = mlp([2 * hidden, hidden, kinds], activate_last=False)
        self.pass_head = nn.Linear(hidden, 1)

    def config(self) -> dict[str, int]:
        return {"own_size": self.own_size, "task_size": self.task_size, "hidden": self.hidden, "kinds": self.kinds}

    def action_width(self, n_tasks: int) -> int:
        """The width of its logits (and of the mask it takes) on ``n_tasks`` tasks."""
        return 1 + self.kinds * n_tasks

    def output_layers(self) -> list[nn.Linear]:
        return [self.task_head[-1], self.pass_head]

    def fits(self, own_size: int, task_size: int, n_tasks: int) -> bool:
        return (self.own_size, self.task_size) == (own_size, task_size)

    def forward(self, observation: th.Tensor, mask: th.Tensor) -> th.Tensor:
        own, tasks = split_tasks(observation, self.own_size, self.task_size)
        embedded, context = self.actor(own, tasks)
        per_task = self.task_head(th.cat([embedded, context.unsqueeze(1).expand_as(embedded)], dim=-1))  # (B, M, K)
        return task_logits(self.pass_head(context), per_task, mask, self.name)


class AttentionActor(nn.Module):
    """The attention actor: task tokens that attend to each other, read out by the agent's own features."""

    name: ClassVar[str] = "attention"

    def __init__(self, own_size: int, task_size: int, hidden: int = 64, heads: int = 4, layers: int = 2,
                 kinds: int = 2) -> None:
        super().__init__()
        if hidden % heads:
            raise ValueError(f"hidden={hidden} must be a multiple of heads={heads}")
        check_kinds(kinds)
        self.own_size, self.task_size, self.hidden, self.heads, self.layers = own_size, task_size, hidden, heads, layers
        self.kinds = kinds
        self.tokens = mlp([task_size + own_size, hidden, hidden], activate_last=False)
        self.encoder = nn.ModuleList(
            nn.TransformerEncoderLayer(hidden, heads, dim_feedforward=2 * hidden, dropout=0.0, batch_first=True,
                                       norm_first=True) for _ in range(layers))
        self.norm = nn.LayerNorm(hidden)
        self.query = mlp([own_size, hidden], activate_last=False)
        self.read_out = nn.MultiheadAttention(hidden, heads, batch_first=True)
        self.task_head = mlp([2 * hidden, hidden, kinds], activate_last=False)
        self.pass_head = mlp([hidden, hidden, 1], activate_last=False)

    def config(self) -> dict[str, int]:
        return {"own_size": self.own_size, "task_size": self.task_size, "hidden": self.hidden, "heads": self.heads,
                "layers": self.layers, "kinds": self.kinds}

    def action_width(self, n_tasks: int) -> int:
        """The width of its logits (and of the mask it takes) on ``n_tasks`` tasks."""
        return 1 + self.kinds * n_tasks

    def output_layers(self) -> list[nn.Linear]:
        return [self.task_head[-1], self.pass_head[-1]]

    def fits(self, own_size: int, task_size: int, n_tasks: int) -> bool:
        return (self.own_size, self.task_size) == (own_size, task_size)

    def forward(self, observation: th.Tensor, mask: th.Tensor) -> th.Tensor:
        own, tasks = split_tasks(observation, self.own_size, self.task_size)
        own_per_task = own.unsqueeze(1).expand(-1, tasks.shape[1], -1)
        tokens = self.tokens(th.cat([tasks, own_per_task], dim=-1))                  # (B, M, H)
        for layer in self.encoder:
            tokens = layer(tokens)
        tokens = self.norm(tokens)
        query = self.query(own).unsqueeze(1)                                           # (B, 1, H)
        context = (query + self.read_out(query, tokens, tokens, need_weights=False)[0]).squeeze(1)   # (B, H)
        per_task = self.task_head(th.cat([tokens, context.unsqueeze(1).expand_as(tokens)], dim=-1))  # (B, M, K)
        return task_logits(self.pass_head(context), per_task, mask, self.name)


class MlpActor(nn.Module):
    """A plain MLP on the flat observation (tied to one number of tasks)."""

    name: ClassVar[str] = "mlp"

    def __init__(self, obs_size: int, n_actions: int, hidden: int = 256) -> None:
        super().__init__()
        self.obs_size, self.n_actions, self.hidden = obs_size, n_actions, hidden
        self.actor = mlp([obs_size, hidden, hidden, n_actions], activate_last=False)

    def config(self) -> dict[str, int]:
        return {"obs_size": self.obs_size, "n_actions": self.n_actions, "hidden": self.hidden}

    def output_layers(self) -> list[nn.Linear]:
        return [self.actor[-1]]

    def fits(self, own_size: int, task_size: int, n_tasks: int) -> bool:
        return self.obs_size == own_size + n_tasks * task_size

    def action_width(self, n_tasks: int) -> int:
        """The width of its logits (fixed: it fits one number of tasks)."""
        return self.n_actions

    def forward(self, observation: th.Tensor, mask: th.Tensor) -> th.Tensor:
        if mask.shape[-1] != self.n_actions:
            raise ValueError(f"the mlp actor was built for {self.n_actions} actions, got {mask.shape[-1]}")
        return self.actor(observation).masked_fill(~mask, MASKED_LOGIT)


NETWORKS: dict[str, type[nn.Module]] = {cls.name: cls for cls in (PoolingActor, AttentionActor, MlpActor)}


def masked_logits(actor: nn.Module, observation: np.ndarray, action_mask: np.ndarray) -> th.Tensor:
    """Masked logits (B, 1 + KM) of a batch of raw observations (B, D) and masks (B, 1 + KM)."""
    obs = th.as_tensor(np.asarray(observation), dtype=th.float32)
    mask = th.as_tensor(np.asarray(action_mask) > 0)
    with th.no_grad():
        return actor(obs, mask)


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())
