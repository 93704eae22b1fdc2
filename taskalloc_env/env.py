"""TaskAlloc: decentralised multi-agent task allocation as a PettingZoo parallel environment.

Create it with ``pettingzoo.make("parallel", "taskalloc/TaskAlloc-v0", ...)`` (or ``"aec"``), or
``taskalloc_env.taskalloc_v0.parallel_env(...)``.

=====================  ==============================================================================
Agents                 ``uav_0 … uav_{N-1}`` (N = ``n_agents``, default 10)
Parallel API           yes (AEC through ``parallel_to_aec``)
Action space           ``Discrete(1 + 2M)``: 0 pass, 1..M bid on task j−1, M+1..2M quit task j−M−1; with
                       ``release_actions`` ``Discrete(1 + 3M)``: 2M+1..3M release task j−2M−1
Observation space      ``Dict(observation=Box(D,) float32, action_mask=Box(0, 1, (A,), int8))``, A = the action
                       space's size (``dtype``)
State space            ``Box`` of agent/task attributes, every agent's own bids and the round
Reward                 cooperative, potential-based: every agent gets Δ team score ÷ the episode's scale
                       (``reward_scale``: by default the instance's total task reward, so the return is the
                       share of it earned, at most 1; ``"raw"``: the score itself; ``taskalloc_env.rewards``)
Termination            the allocation converged: every live agent agrees (no table changed for D + 1 rounds; our
                       stopping rule; under ``acbba``: the network went quiet, or every agent converged locally,
                       Johnson §4.1.3)
Truncation             the round bound T_max (``max_rounds``), or ``max_cycles`` steps (default: 5 · T_max under
                       ``sync``, T_max when a step is a round or tick; ``max_cycles=env.step_bound``, the most
                       steps T_max rounds can take, leaves the round bound alone); under ``acbba`` also a quiet
                       network whose agents disagree after lost messages. Infos carry ``unresolved`` when the
                       stopping test passed without agreement (the reason)
Episode record         on the step an agent's episode ends, ``info["episode"]``: ``r`` (return), ``l`` (steps),
                       ``score``, ``valid_tasks``, ``conflicts``, ``rounds``, ``messages``, ``converged``
=====================  ==============================================================================

Each step is one decision per agent in the bundle phase of CBGA (thesis §3.2.2, Alg 5): *bid* on a task (inserted
at the agent's best path slot, the bid being its marginal gain (3.11)), *quit* a multi-agent task (thesis §5.2.2,
Alg 9, only with ``task_quitting``), or *pass*. The consensus protocol between agents is the environment's dynamics
(``consensus="sync"``: once every agent has passed, the network exchanges messages and agents release what they
were outbid on; ``"every_step"``: after every step; ``"acbba"``: asynchronous, one step is one tick of a global clock,
see ``async_protocol``). The action mask allows exactly the bids the protocol deems valid (eligibility and the outbid
test h_ij) and the quits it allows; a passed agent may only pass until the round ends.

Asynchronous mode (``consensus="acbba"``, Johnson §4.1): every live agent stays in ``agents`` and gets an observation
and a mask every step (PettingZoo's parallel convention: all live agents act simultaneously); an agent whose bundle
builder is not ready this tick has a mask that allows only pass, and its ``passed`` feature and info are set. A ready
agent bids, quits, or passes, which completes its build and broadcasts its outgoing buffer. Pop-up tasks
(``popup_tasks``) are invisible (zero features, masked) until released, in every consensus mode; the observation then
gains a per-task ``released`` feature.

Constructor arguments: ``scenario`` (a name from ``configs/scenarios``, a YAML path, a
:class:`~taskalloc_env.config.TaskAllocConfig`, a mapping, or a fixed :class:`~taskalloc_env.scenario.Scenario`),
``max_cycles`` (steps before truncation; None: ``STEPS_PER_BOUND_ROUND`` = 5 steps per round of the bound T_max
under ``sync``, T_max under ``every_step`` and ``acbba``), ``render_mode`` (``ansi``, ``rgb_array``,
``human``), ``invalid_action`` (``noop``, the default: an invalid action becomes a pass, flagged in infos; ``raise``:
bad input raises ``InvalidActionError``), ``dtype`` (``float32``, the default, or ``float64`` observations and state),
``reward_scale`` (``"total_reward"``, the default: rewards are Δscore over the instance's total task reward;
``"raw"``: Δscore; a number s > 0: Δscore / s; ``env.reward_scale`` is the current episode's divisor),
``episode_stats`` (True, the default: the episode record in the final infos; False for libraries that fix the info
keys at the first reset, such as TorchRL), ``render_path`` (where ``human`` saves its figure: at the end of
every episode and on each ``render()`` call; None shows it in a window, redrawn every step), and any config field
as a keyword override (``n_agents=10, n_tasks=20, agents_per_task=4, comm_range=None``).

Observation: agent i's own features and, per task, features of *its own* table (marginal gain, L_j, members,
lowest member bid, group total, displaced bid, in bundle, quit before, rounds since the group changed, equipment
match, prerequisites met, window, relative position); ``ObservationLayout`` names the columns. The episode
return equals ``evaluate().score / env.reward_scale``; neither ``reward_scale`` nor ``max_cycles`` changes an
observation.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from taskalloc_env.actions import PASS, ActionKind, decode, describe, n_actions
from taskalloc_env.allocation import Allocation
from taskalloc_env.async_protocol import AsyncProtocol
from taskalloc_env.config import TaskAllocConfig, episode_bound, max_required_agents, resolve_config
from taskalloc_env.engine import StepEngine
from taskalloc_env.errors import ConfigError, InvalidActionError
from taskalloc_env.memory import check_memory
from taskalloc_env.observation import ObservationBuilder, state_vector
from taskalloc_env.protocol import Protocol
from taskalloc_env.render import ansi_table, figure, rgb_array
from taskalloc_env.rewards import (
    DEFAULT_REWARD_SCALE,
    check_reward_scale,
    episode_record,
    episode_scale,
    step_reward,
)
from taskalloc_env.scenario import Scenario, generate, scenario_config

INVALID_ACTION_MODES = ("noop", "raise")
DTYPES = ("float32", "float64")
# the default step limit of a synchronous episode, in steps per round of the round bound T_max: on every test seed
# of every suite task no episode of the scripted baselines took more than 1.44 · T_max steps, none of the committed
# learned policies more than 2.16 · T_max (docs/decisions.md, ``python -m evaluation.episode_stats``)
STEPS_PER_BOUND_ROUND = 5
_MISSING = object()                # an agent the action dict leaves out


class TaskAllocEnv(ParallelEnv):
    """The parallel environment; see the module docstring for the card."""

    metadata: ClassVar[dict[str, Any]] = {"name": "taskalloc_v0", "render_modes": ["ansi", "rgb_array", "human"],
                                          "is_parallelizable": True, "render_fps": 2}

    def __init__(self, scenario: str | Path | TaskAllocConfig | Mapping[str, Any] | Scenario = "default",
                 max_cycles: int | None = None, render_mode: str | None = None, invalid_action: str = "noop",
                 reward_scale: str | float = DEFAULT_REWARD_SCALE, render_path: str | Path | None = None,
                 dtype: str = "float32", memory_limit_gb: float | None = None, mask_in_infos: bool = False,
                 episode_stats: bool = True, **overrides: Any) -> None:
        if isinstance(scenario, Scenario):
            self.fixed_scenario: Scenario | None = scenario
            self.config = scenario_config(scenario, **overrides)
        else:
            self.fixed_scenario = None
            self.config = resolve_config(scenario, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode {render_mode!r} is not one of {self.metadata['render_modes']} or None")
        if invalid_action not in INVALID_ACTION_MODES:
            raise ConfigError(f"invalid_action {invalid_action!r} is not one of {INVALID_ACTION_MODES}")
        if dtype not in DTYPES:
            raise ConfigError(f"dtype {dtype!r} is not one of {DTYPES}")
        self.dtype = np.dtype(dtype)
        self.mask_in_infos = bool(mask_in_infos)
        self.invalid_action_reasons: dict[Any, str] = {}     # why each flagged action (or key) of the last step failed
        if max_cycles is not None and (isinstance(max_cycles, bool) or not isinstance(max_cycles, int)
                                       or max_cycles < 1):
            raise ConfigError(f"max_cycles must be a positive integer or None, got {max_cycles!r}")
        self.reward_scale_rule = check_reward_scale(reward_scale)
        if not isinstance(episode_stats, bool):
            raise ConfigError(f"episode_stats must be True or False, got {episode_stats!r}")
        self.episode_stats = episode_stats
        self.render_mode = render_mode
        self.render_path = _checked_render_path(render_path)
        self.invalid_action = invalid_action
        n, m = self.config.n_agents, self.config.n_tasks
        widest = (int(self.fixed_scenario.task_agents.max()) if self.fixed_scenario is not None
                  else max_required_agents(self.config))
        check_memory(n, m, self.config.max_bundle, memory_limit_gb, widest,     # before anything of that size exists
                     self.config.asynchronous)
        self.possible_agents = [f"uav_{i}" for i in range(n)]
        self.agent_index = {a: i for i, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self._np_random, self._np_random_seed = seeding.np_random()
        self._protocol: Protocol | None = None
        self._window = None
        # spaces depend only on counts and on bounds that hold for every instance, so they are built once
        probe = self.fixed_scenario or generate(self.config, np.random.default_rng(0))
        protocol_class = AsyncProtocol if self.config.asynchronous else Protocol
        self._protocol_class = protocol_class
        probe_protocol = protocol_class(probe, self.config)
        if self.fixed_scenario is not None:
            self._max_agents_per_task = int(probe.task_agents.max())
            self._max_rounds = probe_protocol.max_rounds
        else:
            self._max_agents_per_task = max_required_agents(self.config)
            # the largest diameter any instance can have: 1 fully connected, n − 1 for agents in a line
            diameter = 1 if self.config.comm_range is None else max(1, n - 1)
            self._max_rounds = episode_bound(self.config, m, n, self._max_agents_per_task, diameter)
        # the most steps T_max rounds can take: a sync round ends when all have passed; before that an agent's
        # steps are its bids (each adds a task to its bundle; only its own quits, at most one per task, each
        # dropping at most M tasks, make room again: at most M + M² bids), its quits (at most M) and the pass,
        # (M + 1)² in all; every_step and acbba: a round (tick) per step. Release actions lift the bound on a sync
        # round's bids (release, re-bid, …): the limit then cuts an episode whose agents never stop doing that
        sync = self.config.consensus == "sync"
        self.step_bound = self._max_rounds * ((m + 1) ** 2 if sync else 1)
        # the default limit: STEPS_PER_BOUND_ROUND steps per round of the bound under sync (a realistic bound that
        # clears every measured episode), the bound itself when a step is a round (tick)
        self.max_cycles = max_cycles if max_cycles is not None else \
            self._max_rounds * (STEPS_PER_BOUND_ROUND if sync else 1)
        builder = ObservationBuilder(probe_protocol, self._max_agents_per_task, self._max_rounds)
        self.observation_layout = builder.layout
        self._observation_space = spaces.Dict({
            "observation": builder.space(self.dtype),
            "action_mask": spaces.Box(0, 1, (n_actions(m, self.config.release_actions),), dtype=np.int8),
        })
        self._action_space = spaces.Discrete(n_actions(m, self.config.release_actions))
        state_size = len(state_vector(probe_protocol))
        self.state_space = spaces.Box(-np.inf, np.inf, (state_size,), dtype=self.dtype)

    # -- spaces ------------------------------------------------------------------------------------------------
    # every agent shares one space object, built once per env: the same object on every call, as parallel_api_test
    # requires, with no cache that would keep the env alive
    def observation_space(self, agent: str) -> spaces.Dict:
        self._check_agent_name(agent)
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Discrete:
        self._check_agent_name(agent)
        return self._action_space

    def _check_agent_name(self, agent: str) -> None:
        if agent not in self.agent_index:
            raise KeyError(f"unknown agent {agent!r}; agents are "
                           f"{self.possible_agents[0]} … {self.possible_agents[-1]}")

    # -- episode -------------------------------------------------------------------------------------------------
    @property
    def protocol(self) -> Protocol:
        if self._protocol is None:
            raise RuntimeError("call reset() before using the environment")
        return self._protocol

    @property
    def scenario(self) -> Scenario:
        """The current instance (arrays of agent and task attributes)."""
        return self.protocol.scenario

    @property
    def round_bound(self) -> int:
        """T_max of every episode of this env: the round (tick) bound at the widest network diameter its config
        allows; ``max_cycles`` defaults to ``STEPS_PER_BOUND_ROUND`` steps per round of it under ``sync``."""
        return self._max_rounds

    @property
    def reward_scale(self) -> float:
        """The divisor of this episode's rewards (``rewards.episode_scale``): the return is ``score / reward_scale``.
        Under ``total_reward`` it is the instance's, so it is known from ``reset()`` on."""
        if self._protocol is None:
            raise RuntimeError("reward_scale belongs to an episode: call reset() first")
        return self._reward_scale

    @property
    def np_random(self) -> np.random.Generator:
        return self._np_random

    def reset(self, seed: int | None = None, options: dict | None = None):
        self._begin(seed)
        observations = self._observations()
        infos = self._infos({})
        return observations, infos

    def _begin(self, seed: int | None) -> None:
        """``reset`` without the first observations and infos: draw the episode's instance and start its protocol
        (the batched env's arrays engine starts an instance with it and observes it in its own arrays)."""
        if seed is not None:
            self._np_random, self._np_random_seed = seeding.np_random(seed)
        scenario = self.fixed_scenario or generate(self.config, self._np_random)
        # faults, Poisson arrivals and processing times draw from a generator spawned from the env's own (after the
        # instance), so episodes replay from the seed; a config that draws nothing leaves the env's stream as it was
        protocol_rng = np.random.default_rng(self._np_random.integers(2**63)) if self.config.stochastic else None
        self._protocol = self._protocol_class(scenario, self.config, rng=protocol_rng)
        self._builder = ObservationBuilder(self._protocol, self._max_agents_per_task, self._max_rounds)
        self._engine = StepEngine(self._protocol)
        self.agents = [a for a, present in zip(self.possible_agents, self._protocol.alive) if present]  # join_at
        self._reward_scale = episode_scale(self.reward_scale_rule, self._protocol.model)
        self._last_score = 0.0
        self._return = 0.0
        self._done = False

    def step(self, actions: Mapping[str, Any]):
        if self._protocol is None:
            raise InvalidActionError("step() called before reset(); call reset() first")
        if self._done or not self.agents:
            if self.invalid_action == "noop":
                return {}, {}, {}, {}, {}
            raise InvalidActionError("step() called after the episode ended; call reset() first")
        protocol = self.protocol
        flags: dict[str, str] = {}
        decisions = self._read_actions(actions, flags)
        protocol.counters.invalid_actions += len(flags)
        self.invalid_action_reasons = flags
        reward, terminated, truncated = self._advance(decisions)
        alive, index = protocol.alive.tolist(), self.agent_index
        if self.config.join_at:             # late joiners enter env.agents the step they join, with this step's returns
            acted = set(self.agents)
            self.agents = [a for a in self.possible_agents if a in acted or alive[index[a]]]
        agents = list(self.agents)
        observations = self._observations()
        rewards = dict.fromkeys(agents, reward)
        terminations = {a: terminated or not alive[index[a]] for a in agents}
        truncations = dict.fromkeys(agents, truncated)
        infos = self._infos(flags)
        if truncated and protocol.unresolved is not None:     # why the episode ended without convergence
            for info in infos.values():
                info["unresolved"] = protocol.unresolved
        if self.episode_stats:                                  # the record of every agent whose episode ends here
            for a in agents:
                if terminated or truncated or terminations[a]:
                    infos[a]["episode"] = episode_record(self._return, self._engine.steps, infos[a])
        if terminated or truncated:
            self._done = True
            self.agents = []
        else:                                                   # failed agents leave (PettingZoo: terminated)
            self.agents = [a for a in agents if alive[index[a]]]
        # human mode redraws its window every step (Gymnasium's convention); saving a file every step would cost a
        # figure per step, so with render_path the file is written at the end of the episode and on render() calls
        if self.render_mode == "human" and (self.render_path is None or not self.agents):
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _advance(self, decisions: list[tuple[int, int]]) -> tuple[float, bool, bool]:
        """Apply a joint action of (agent, valid action) pairs in agent order: (the team reward, terminated,
        truncated). The one step of this env and of each instance of the batched env (``vector``)."""
        self._engine.apply(decisions)
        score = self.protocol.score().score
        reward = step_reward(score, self._last_score, self._reward_scale)
        self._last_score = score
        self._return += reward
        terminated, truncated = self._engine.ended(self.max_cycles)
        return reward, terminated, truncated

    def _read_actions(self, actions: Mapping[str, Any], flags: dict[str, str]) -> list[tuple[int, int]]:
        """Validate the action dict against the live agents and their masks; apply ``invalid_action``."""
        if not isinstance(actions, Mapping):
            raise InvalidActionError(f"actions must be a dict agent -> action, got {type(actions).__name__}")
        unknown = [] if actions.keys() <= set(self.agents) else [a for a in actions if a not in self.agents]
        for key in unknown:                     # flagged under its own key: the live agents' actions still count
            message = f"action for {_shown(key)}, which is not a live agent; live agents: {self.agents}"
            if self.invalid_action == "raise":
                raise InvalidActionError(message)
            flags[key] = message
        masks = self._masks                     # the masks handed out with the last observations
        allowed = self._allowed                 # the same masks as lists: a plain int is checked in two lookups
        decisions = []
        for agent in self.agents:
            i = self.agent_index[agent]
            raw = actions.get(agent, _MISSING)
            if type(raw) is int and 0 <= raw < len(allowed[i]) and allowed[i][raw]:
                action, problem = raw, None
            elif raw is _MISSING:
                problem = f"no action given for {agent}"
                action = None
            else:
                action, problem = self._check_action(agent, raw, masks[i])
            if problem:
                if self.invalid_action == "raise":
                    raise InvalidActionError(problem)
                flags[agent] = problem
                action = PASS
            decisions.append((i, action))
        return decisions

    def validate_action(self, agent: str, action: Any) -> int:
        """``action`` as an int if ``agent`` may take it now; otherwise ``InvalidActionError`` saying why."""
        if self._protocol is None:
            raise InvalidActionError("no episode: call reset() first")
        if agent not in self.agents:
            raise InvalidActionError(f"unknown or finished agent {agent!r}; live agents: {self.agents}")
        checked, problem = self._check_action(agent, action, self._masks[self.agent_index[agent]])
        if problem:
            raise InvalidActionError(problem)
        return checked

    def _check_action(self, agent: str, raw: Any, mask: np.ndarray) -> tuple[int | None, str | None]:
        """``raw`` as an int and no problem if ``action_space.contains`` accepts it (a Python or NumPy integer, a 0-d
        integer array) and the mask allows it; else None and why not. A bool is refused although ``Discrete`` takes
        Python's ``True`` for 1 (bool subclasses int; ours: a flag is never an action, as ``np.bool_`` is not)."""
        n = len(mask)
        if isinstance(raw, (bool, np.bool_)) or not _integer(raw):
            return None, f"action {_shown(raw)} of {agent} is not an integer scalar (Discrete({n}) takes an int, " \
                         f"a NumPy integer or a 0-d integer array)"
        if not self._action_space.contains(raw):
            return None, f"action {_shown(raw)} of {agent} is outside Discrete({n})"
        action = int(raw)
        if not mask[action]:
            return None, f"action {action} ({self.describe_action(action)}) of {agent} is not allowed by its mask: " \
                         f"{self._why_masked(agent, action)}"
        return action, None

    def _why_masked(self, agent: str, action: int) -> str:
        i = self.agent_index[agent]
        passed = self._engine.passed[i]
        if passed and self.config.asynchronous:
            return "the agent's bundle builder is not ready this tick (it has no news, or its build is still running)"
        if passed:
            return "the agent passed this round and may only pass until the round ends"
        kind, task = decode(action, self.config.n_tasks)
        if kind is ActionKind.BID:
            return self.protocol.explain_bid(i, task)
        if kind is ActionKind.RELEASE:
            return f"{agent} may not release task {task}: {self.protocol.explain_release(i, task)}"
        return "quitting needs task_quitting on, L_j > 1, membership, an incomplete group, no earlier quit, " \
               f"and T − H > delta = {self.config.delta}"

    def describe_action(self, action: int) -> str:
        """``pass``, ``bid on task j``, ``quit task j`` or ``release task j``."""
        return describe(action, self.config.n_tasks)

    # -- outputs ---------------------------------------------------------------------------------------------------
    def _rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, D) observations and (N, A) action masks of every agent now (new arrays); the masks are kept for the
        action checks of the next step."""
        obs = self._builder.observe(self.protocol, self._engine.passed, self.dtype)
        self._masks = self._engine.masks()
        return obs, self._masks

    def _observations(self) -> dict[str, dict[str, np.ndarray]]:
        obs, _ = self._rows()
        self._allowed = self._masks.tolist()
        handed = self._masks.copy()             # the caller's masks: editing one leaves the env's checks alone
        index = self.agent_index
        return {a: {"observation": obs[index[a]], "action_mask": handed[index[a]]} for a in self.agents}

    def _figures(self) -> dict[str, Any]:
        """The episode's figures now, the same in every agent's info: score, valid tasks, conflicts, round,
        messages, data items, converged."""
        p = self.protocol
        ts = p.score()
        return {"score": ts.score, "valid_tasks": int(np.count_nonzero(ts.valid)),
                "conflicts": int(np.count_nonzero(ts.conflicts)),
                "round": p.round, "messages": p.counters.messages, "data_items": p.counters.data_items,
                "converged": p.converged}

    def _infos(self, flags: dict[str, str]) -> dict[str, dict[str, Any]]:
        p = self.protocol
        figures = self._figures()
        asynchronous = self.config.asynchronous
        if asynchronous:                                 # Johnson §4.1.3: each agent declares its own convergence
            declared, declared_at = p.agents_locally_converged, p.local_ticks
        passed = self._engine.passed.tolist()
        infos = {}
        for a in self.agents:
            i = self.agent_index[a]
            info = dict(figures, passed=passed[i])
            if asynchronous:
                info["locally_converged"] = bool(declared[i])
                info["locally_converged_at"] = int(declared_at[i])
            info["invalid_action"] = a in flags          # the reason: env.unwrapped.invalid_action_reasons[a]
            if self.mask_in_infos:
                info["action_mask"] = self._masks[i].copy()
            infos[a] = info
        return infos

    def state(self) -> np.ndarray:
        return state_vector(self.protocol).astype(self.dtype)

    def evaluate(self) -> Allocation:
        """The allocation as it stands: paths with start times, groups, valid tasks, conflicts, score, traffic."""
        return self.protocol.allocation()

    def render(self):
        if self.render_mode is None:
            raise ValueError("render() needs a render_mode: 'ansi', 'rgb_array' or 'human'")
        allocation = self.evaluate()
        if self.render_mode == "ansi":
            return ansi_table(self.scenario, allocation)
        if self.render_mode == "rgb_array":
            return rgb_array(self.scenario, allocation, self.config.units)
        if self.render_path is not None:
            figure(self.scenario, allocation, units=self.config.units).savefig(self.render_path)
        elif _interactive_backend():
            import matplotlib.pyplot as plt
            if self._window is None:
                self._window = plt.figure("taskalloc")
            self._window.clf()
            ax = self._window.add_subplot(1, 1, 1)
            ax.imshow(rgb_array(self.scenario, allocation, self.config.units))
            ax.axis("off")
            plt.pause(0.001)
        return None

    def close(self) -> None:
        if self._window is not None:
            import matplotlib.pyplot as plt
            plt.close(self._window)
            self._window = None


def _checked_render_path(render_path: str | Path | None) -> Path | None:
    """``render_path`` as a Path, refused before any episode when matplotlib could not save a figure there."""
    if render_path is None:
        return None
    if not isinstance(render_path, (str, Path)):
        raise ConfigError(f"render_path must be a path or None, got {type(render_path).__name__}")
    path = Path(render_path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ConfigError(f"render_path {str(path)!r} is a directory; give a file name such as allocation.png")
    if not parent.is_dir():
        raise ConfigError(f"render_path {str(path)!r}: the directory {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK):
        raise ConfigError(f"render_path {str(path)!r}: the directory {str(parent)!r} is not writable")
    if path.suffix:
        from matplotlib.backend_bases import FigureCanvasBase

        formats = FigureCanvasBase.get_supported_filetypes()
        if path.suffix[1:].lower() not in formats:
            raise ConfigError(f"render_path {str(path)!r}: matplotlib saves {', '.join(sorted(formats))}, "
                              f"not {path.suffix!r}")
    return path


def _integer(raw: Any) -> bool:
    """Whether ``raw`` is an integer scalar in ``Discrete.contains``'s sense: an int, or a NumPy integer of shape ()."""
    if isinstance(raw, int):
        return True
    return isinstance(raw, (np.generic, np.ndarray)) and np.issubdtype(raw.dtype, np.integer) and raw.shape == ()


def _shown(value: Any) -> str:
    """``value`` for a one-line message: its repr, or its type and shape when that is long or spans lines."""
    text = repr(value)
    if "\n" not in text and len(text) <= 60:
        return text
    shape = getattr(value, "shape", None)
    return f"{type(value).__name__}{f' of shape {shape}' if shape is not None else ''}"


def _interactive_backend() -> bool:
    """Whether matplotlib can open a window here (``human`` shows the figure only then)."""
    import matplotlib
    from matplotlib.backends import BackendFilter, backend_registry

    return matplotlib.get_backend().lower() in backend_registry.list_builtin(BackendFilter.INTERACTIVE)
