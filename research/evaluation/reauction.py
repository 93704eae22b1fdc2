"""CBAA re-auctioned after each visit (ours): the single-assignment auction run again from where the agents stand.

CBAA gives every agent at most one task (Choi, Brunet & How 2009; thesis §2.2.3, Alg 1 l. 4), so one auction over
the collaborative visit's 10 targets serves at most 4. The DCTA benchmark's CBAA allocates one target cell at a
time and auctions again as robots reach their cells. Here the environment plans before anyone moves, so the
re-auction runs in stages: each stage is one CBAA episode (the product's ``cbaa`` policy through the product's
environment and channel) over the targets not yet visited, with every agent starting where its last visit left it;
each agent then flies to the target it holds, and the next stage begins. Two agents that both hold a target (a
conflict the channel left) both fly there. The stages stop when every target is visited or a stage assigns nothing.

Stage 0 is the one-shot ``cbaa`` episode of the same seed (the same instance and the same network draws). Later
stages draw their network from ``seed + stage · STAGE_SEEDS``. The visits are scored as one path per agent on the
original instance (``Allocation.from_paths``): each agent flies its visits back to back, and the re-auctions take no
mission time. Messages, rounds and lost messages add up over the stages; ``max_agent_messages`` is the largest sum
of one agent's messages; the re-auction has converged when every stage has (none stopped at the round bound).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from taskalloc.policies import make_policy, rollout
from taskalloc_env import Scenario, TaskAllocConfig, TaskAllocEnv
from taskalloc_env.allocation import Allocation
from taskalloc_env.config import PROTOCOL_FIELDS, SCORING_FIELDS
from taskalloc_env.scoring import ScoringModel

STAGE_SEEDS = 1_000_003         # stage k's network draws come from seed + k · STAGE_SEEDS


@dataclasses.dataclass(frozen=True)
class Reauction:
    """The outcome: the allocation of the visits, the per-stage figures added up, and the duplicate visits."""

    allocation: Allocation
    stages: int
    rounds: int
    messages_lost: int
    max_agent_messages: int
    duplicate_visits: int       # a target two agents flew to in one stage (a conflict the channel left)
    converged: bool             # every stage ended by the protocol's stop, none at the round bound
    instance: Scenario


def remaining(scenario: Scenario, positions: np.ndarray, tasks: np.ndarray) -> Scenario:
    """The instance of one stage: the agents at ``positions``, the tasks ``tasks`` of ``scenario`` (ids renumbered
    0..len(tasks) − 1 in the order given)."""
    keep = np.asarray(tasks, dtype=np.int64)
    return dataclasses.replace(
        scenario, agent_pos=np.array(positions, dtype=float), task_pos=scenario.task_pos[keep],
        task_reward=scenario.task_reward[keep], task_start=scenario.task_start[keep],
        task_end=scenario.task_end[keep], task_duration=scenario.task_duration[keep],
        task_agents=scenario.task_agents[keep], task_equipment=scenario.task_equipment[keep],
        task_prereqs=scenario.task_prereqs[np.ix_(keep, keep)])


def stage_options(cfg: TaskAllocConfig) -> dict[str, Any]:
    """The scoring and protocol options of ``cfg`` that a stage's fixed instance keeps (its channel among them)."""
    return {name: getattr(cfg, name) for name in SCORING_FIELDS + PROTOCOL_FIELDS}


def reauction(cfg: TaskAllocConfig, seed: int, policy: str = "cbaa") -> Reauction:
    """Re-auction ``policy`` (CBAA: one task per agent and stage) over instance ``seed`` of ``cfg`` until every
    target is visited or a stage assigns nothing."""
    env = TaskAllocEnv(cfg)
    env.reset(seed=seed)
    instance = env.scenario
    options = stage_options(cfg)
    positions = np.array(instance.agent_pos)
    left = np.arange(instance.n_tasks)
    visits: list[list[int]] = [[] for _ in range(instance.n_agents)]
    sent = np.zeros(instance.n_agents, dtype=np.int64)
    rounds = lost = duplicates = stage = 0
    converged = True
    player = make_policy(policy)
    while left.size:
        stage_env = TaskAllocEnv(remaining(instance, positions, left), **options)
        result = rollout(stage_env, player, seed + stage * STAGE_SEEDS)   # the env's protocol: sent_by per agent
        protocol = stage_env.unwrapped.protocol
        sent += protocol.network.sent_by
        rounds += result.counters.rounds
        lost += result.counters.messages_lost
        converged &= result.converged
        stage += 1
        held = {i: int(left[path[0]]) for i, path in enumerate(result.paths) if path}
        if not held:
            break
        for i, task in held.items():
            visits[i].append(task)
            positions[i] = instance.task_pos[task]
        targets = list(held.values())
        duplicates += len(targets) - len(set(targets))
        left = np.setdiff1d(left, targets)
    allocation = Allocation.from_paths(ScoringModel.from_config(instance, cfg), visits, cfg.conflict_policy)
    return Reauction(allocation, stage, rounds, lost, int(sent.max(initial=0)), duplicates, converged, instance)
