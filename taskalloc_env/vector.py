"""The batched environment: K independent instances, arrays in and out (``vector_env``).

``vector_env(num_envs, **env_kwargs)`` takes the keywords of ``parallel_env`` and returns a
``TaskAllocVectorEnv`` of K = ``num_envs`` instances of N agents each::

    venv = taskalloc_env.vector_env(1024, scenario="default")
    obs, infos = venv.reset(seed=0)            # instance k draws what parallel_env draws at reset(seed=0 + k)
    obs["observation"]                         # (K, N, D) float32
    obs["action_mask"]                         # (K, N, A) int8
    obs, rewards, terminations, truncations, infos = venv.step(actions)    # actions: (K, N) integers
    rewards                                    # (K, N): the team reward, the same for every agent of an instance
    terminations, truncations                  # (K,): every agent of an instance ends together
    infos["score"], infos["invalid_actions"]   # arrays of length K (``INFO_KEYS``); infos["passed"] is (K, N)
    venv.state()                               # (K, S) for centralised critics

Instance k is exactly a ``parallel_env`` seeded ``seed + k``: observations, masks, rewards, terminations, infos and
the final allocation, step by step (``tests/test_vector.py``). Two engines step the instances (``venv.engine``):

* ``"arrays"``: every instance's state held as (K, …) arrays and each phase of a step (apply the joint actions,
  the consensus round, re-time the changed paths and score, observe) one compiled call over the instance axis
  (``vector_arrays``, ``kernels.batch``), running the single env's rules through the same compiled kernels (the
  merge, the bid rows, path timing, the paid groups, the observation features, the masks). Its scope: the
  synchronous consensus (``consensus="sync"``, the default, and ``"every_step"``), perfect links or independent
  message loss (``message_loss`` > 0 with ``loss_model="independent"``, no ``max_delay``), task quitting, release
  actions (every ``release_guard``), any scenario, scoring and bidding option, with no pop-up tasks and
  ``require_known_capacity`` off. A new instance is still drawn in Python at each reset (``TaskAllocEnv._begin``)
  and copied in.
* ``"instances"``: each instance stepped in turn by the single env's step (``TaskAllocEnv._advance``: the step
  engine, ``engine.StepEngine``); every other option.

``engine="auto"`` (the default) takes ``"arrays"`` wherever its scope covers the options, else ``"instances"``;
``engine="arrays"`` refuses options outside it, naming the first. ``docs/benchmarks.md`` gives the throughput of
both. The batch adds the array interface, the checks of a whole action array at once and the autoreset.

Autoreset (``autoreset_mode``):

* ``"next_step"`` (Gymnasium's default for vector envs): on the step after an instance's episode ended, its actions
  are ignored and it starts its next episode (its generator continues, so a seeded run replays), returning the
  first observation with zero reward and both flags false;
* ``"same_step"`` (stable-baselines3's convention): an instance that ends is reset within the same step; its last
  observation, state and figures are in ``infos["final_obs"]``, ``infos["final_state"]`` and
  ``infos["final_info"]``, valid where ``infos["_final"]`` is set;
* ``"disabled"`` (TorchRL's convention): an instance that ended waits for ``reset(options={"reset_mask": m})``, which
  restarts the instances where the (K,) boolean ``m`` is set and leaves the others as they are; stepping an ended
  instance is an error.

Supported: every option of the single env except agent drop-outs and late joiners (``dropouts``,
``dropout_schedule``, ``join_at``: a failed agent leaves ``env.agents`` and a joiner enters it, which a fixed (K, N)
layout cannot express) and rendering.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding

from taskalloc_env.actions import PASS, describe
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError, InvalidActionError
from taskalloc_env.kernels import batch
from taskalloc_env.memory import available_memory, memory_estimate
from taskalloc_env.observation import state_vector
from taskalloc_env.scenario import Scenario
from taskalloc_env.vector_arrays import UNRESOLVED_TEXT, ArrayBatch, unsupported

AUTORESET_MODES = ("next_step", "same_step", "disabled")
ENGINES = ("auto", "arrays", "instances")
# the figures of every instance after each step, arrays of length K (``TaskAllocEnv._figures`` per instance)
INFO_KEYS = {"score": np.float64, "valid_tasks": np.int64, "conflicts": np.int64, "round": np.int64,
             "messages": np.int64, "data_items": np.int64, "converged": np.bool_}
UNSUPPORTED = {"dropouts": 0, "dropout_schedule": None, "join_at": None}    # field -> the only value the batch takes
MAX_NUM_ENVS = 1_000_000


def vector_env(num_envs: int, **env_kwargs: Any) -> TaskAllocVectorEnv:
    """A batched environment of ``num_envs`` independent instances; ``env_kwargs`` are ``parallel_env``'s."""
    return TaskAllocVectorEnv(num_envs, **env_kwargs)


class TaskAllocVectorEnv:
    """K instances of the parallel environment behind one array interface; see the module docstring."""

    metadata: ClassVar[dict[str, Any]] = {"name": "taskalloc_vector_v0", "autoreset_modes": AUTORESET_MODES}

    def __init__(self, num_envs: int, scenario: str | Path | TaskAllocConfig | Mapping[str, Any] | Scenario = "default",
                 autoreset_mode: str = "next_step", memory_limit_gb: float | None = None, engine: str = "auto",
                 **env_kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or not 1 <= num_envs <= MAX_NUM_ENVS:
            raise ConfigError(f"num_envs must be an integer in 1..{MAX_NUM_ENVS:,}, got {num_envs!r}")
        if autoreset_mode not in AUTORESET_MODES:
            raise ConfigError(f"autoreset_mode {autoreset_mode!r} is not one of {AUTORESET_MODES}")
        if engine not in ENGINES:
            raise ConfigError(f"engine {engine!r} is not one of {ENGINES}")
        for key in ("render_mode", "render_path", "mask_in_infos"):
            if env_kwargs.get(key):
                raise ConfigError(f"{key}: the batched env does not render or copy masks into infos; "
                                  "use parallel_env for that")
        template = TaskAllocEnv(scenario, memory_limit_gb=memory_limit_gb, **env_kwargs)   # checks every option
        cfg = template.config
        for field, allowed in UNSUPPORTED.items():
            if getattr(cfg, field) != allowed:
                raise ConfigError(f"{field}={getattr(cfg, field)!r}: the batched env keeps every agent for the whole "
                                  f"episode (a failed agent would leave env.agents, a late joiner enter it); only "
                                  f"{allowed!r} is supported")
        k = int(num_envs)
        outside = unsupported(cfg)
        if engine == "arrays" and outside is not None:
            raise ConfigError(f"engine='arrays' does not cover {outside}; use engine='auto' or 'instances'")
        # which path steps the instances: the compiled arrays where the options allow, else each env in turn
        self.engine = "instances" if engine == "instances" or outside is not None else "arrays"
        self._check_memory(k, template, memory_limit_gb, self.engine == "arrays")
        self.num_envs = k
        self.autoreset_mode = autoreset_mode
        self.render_mode = None                         # the batch does not render (Gymnasium's attribute)
        self.config = cfg
        self.possible_agents = list(template.possible_agents)
        self.n_agents, self.n_tasks = cfg.n_agents, cfg.n_tasks
        self.observation_layout = template.observation_layout
        self.single_observation_space = template.observation_space(self.possible_agents[0])
        self.single_action_space = template.action_space(self.possible_agents[0])
        self.single_state_space = template.state_space
        n, a = self.n_agents, int(self.single_action_space.n)
        d = self.single_observation_space["observation"].shape[0]
        box = self.single_observation_space["observation"]
        self.observation_space = spaces.Dict({
            "observation": spaces.Box(np.broadcast_to(box.low, (k, n, d)), np.broadcast_to(box.high, (k, n, d)),
                                      dtype=box.dtype),
            "action_mask": spaces.Box(0, 1, (k, n, a), dtype=np.int8)})
        self.action_space = spaces.MultiDiscrete(np.full((k, n), a))
        self.state_space = spaces.Box(-np.inf, np.inf, (k, template.state_space.shape[0]),
                                      dtype=template.state_space.dtype)
        self.invalid_action = template.invalid_action
        self.envs = [template] + [_clone(template) for _ in range(k - 1)]
        self._obs = np.zeros((k, n, d), dtype=box.dtype)
        self._masks = np.zeros((k, n, a), dtype=np.int8)
        self._batch = ArrayBatch(k, template, self._obs) if self.engine == "arrays" else None
        self._ended = np.zeros(k, dtype=bool)            # the instance's episode ended at the last step
        self._started = False

    @staticmethod
    def _per_instance_bytes(template: TaskAllocEnv, arrays: bool) -> int:
        """The estimated bytes of one instance: its env (``memory.memory_estimate``), its observations and masks, and
        with ``arrays`` its state in the arrays engine (``ArrayBatch.bytes_per_instance``)."""
        cfg = template.config
        d = template.observation_space(template.possible_agents[0])["observation"].shape[0]
        a = int(template.action_space(template.possible_agents[0]).n)
        per_instance = memory_estimate(cfg.n_agents, cfg.n_tasks, cfg.max_bundle, template._max_agents_per_task,
                                       cfg.asynchronous) + cfg.n_agents * (8 * d + 2 * a)
        return per_instance + (ArrayBatch.bytes_per_instance(template) if arrays else 0)

    @classmethod
    def _check_memory(cls, k: int, template: TaskAllocEnv, limit_gb: float | None, arrays: bool) -> None:
        """Refuse K instances whose estimate exceeds ``limit_gb`` (default: the memory available now), before any
        instance beyond the template exists."""
        cfg = template.config
        per_instance = cls._per_instance_bytes(template, arrays)
        need = k * per_instance
        limit = available_memory() if limit_gb is None else limit_gb * 2**30
        if need > limit:
            raise ConfigError(f"num_envs={k:,} instances of {cfg.n_agents} agents × {cfg.n_tasks} tasks need about "
                              f"{need / 2**30:.1f} GiB ({per_instance / 2**20:.1f} MiB each, see "
                              f"memory.memory_estimate); the limit is {limit / 2**30:.1f} GiB "
                              f"({'available now' if limit_gb is None else 'memory_limit_gb'})")

    # -- episodes ----------------------------------------------------------------------------------------------
    def reset(self, seed: int | Sequence[int] | None = None, options: dict | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Start every instance: instance k with ``seed + k`` (or ``seed[k]`` for a sequence of K seeds; None
        continues each instance's own generator)."""
        options = dict(options or {})
        chosen = self._reset_mask(options.pop("reset_mask", None))
        seeds = self._seeds(seed)
        if self._batch is not None:
            self._restart(chosen, seeds)
        else:
            for k in np.flatnonzero(chosen).tolist():
                self.envs[k].reset(seed=seeds[k], options=options or None)
                self._write_rows(k)
        self._ended &= ~chosen
        self._started = True
        return self._handed(), self._infos(np.zeros(self.num_envs, dtype=np.int64))

    def _reset_mask(self, mask: Any) -> np.ndarray:
        """(K,) the instances a reset restarts: all, or those set in ``options["reset_mask"]`` (after the first
        reset)."""
        if mask is None:
            return np.ones(self.num_envs, dtype=bool)
        array = np.asarray(mask)
        if array.dtype != np.bool_ or array.shape != (self.num_envs,):
            raise ConfigError(f"options['reset_mask'] must be a boolean array of shape ({self.num_envs},), got "
                              f"{array.dtype} {array.shape}")
        if not self._started and not array.all():
            raise ConfigError("the first reset() starts every instance; options['reset_mask'] comes after it")
        return array.copy()

    def _seeds(self, seed: int | Sequence[int] | None) -> list[int | None]:
        k = self.num_envs
        if seed is None:
            return [None] * k
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            if seed < 0:
                raise ConfigError(f"seed must be a non-negative integer, got {seed}")
            return [int(seed) + i for i in range(k)]
        seeds = list(seed) if isinstance(seed, Sequence) else None
        if seeds is None or len(seeds) != k or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool)
                                                       and s >= 0 for s in seeds):
            raise ConfigError(f"seed must be None, a non-negative integer or a sequence of {k} of them, got "
                              f"{type(seed).__name__}")
        return [int(s) for s in seeds]

    def step(self, actions: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, np.ndarray]]:
        """One joint action per instance, ``actions`` of shape (K, N); see the module docstring for the outputs."""
        if not self._started:
            raise InvalidActionError("step() called before reset(); call reset() first")
        actions = self._checked(actions)
        k_count, n = self.num_envs, self.n_agents
        valid = self._valid(actions)
        invalid = np.count_nonzero(~valid, axis=1)
        if self.autoreset_mode == "disabled" and self._ended.any():
            raise InvalidActionError(f"instance {int(np.flatnonzero(self._ended)[0])} ended: restart it with "
                                     "reset(options={'reset_mask': mask}) before the next step (autoreset_mode="
                                     "'disabled')")
        if self.invalid_action == "raise" and invalid.any():
            self._raise_first(actions, valid)
        if self._batch is not None:
            return self._step_arrays(np.where(valid, actions, PASS), invalid)
        played = np.where(valid, actions, PASS).tolist()
        rewards = np.zeros(k_count, dtype=np.float64)
        terminations = np.zeros(k_count, dtype=bool)
        truncations = np.zeros(k_count, dtype=bool)
        restarted = self._ended.copy()         # next-step autoreset (under "disabled" no instance has ended here)
        final = np.zeros(k_count, dtype=bool)
        finals: list[tuple[int, np.ndarray, np.ndarray, np.ndarray, dict[str, Any], str | None]] = []
        unresolved: list[str | None] = [None] * k_count
        agents = range(n)
        for k, env in enumerate(self.envs):
            if restarted[k]:                      # next-step autoreset: the actions of this step are ignored
                env.reset()
                invalid[k] = 0
            else:
                env.protocol.counters.invalid_actions += int(invalid[k])
                reward, terminated, truncated = env._advance(list(zip(agents, played[k])))
                rewards[k], terminations[k], truncations[k] = reward, terminated, truncated
                if truncated:
                    unresolved[k] = env.protocol.unresolved
                if (terminated or truncated) and self.autoreset_mode == "same_step":
                    obs, masks = env._rows()
                    finals.append((k, obs, masks.copy(), env.state(), env._figures(), unresolved[k]))
                    final[k] = True
                    env.reset()
            self._write_rows(k)
        self._ended = (terminations | truncations) & (self.autoreset_mode != "same_step")
        infos = self._infos(invalid, unresolved)
        if self.autoreset_mode == "same_step":
            infos.update(self._finals(finals, final))
        return self._handed(), np.repeat(rewards[:, None], n, axis=1), terminations, truncations, infos

    def _step_arrays(self, played: np.ndarray, invalid: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray,
                                                                             np.ndarray, np.ndarray,
                                                                             dict[str, np.ndarray]]:
        """``step`` on the arrays engine: the same outputs, each phase one compiled call over the instances."""
        b, k_count = self._batch, self.num_envs
        restarted = self._ended.copy()        # next-step autoreset (under "disabled" no instance has ended here)
        stepping = ~restarted
        invalid[restarted] = 0
        b.istate[:, batch.INVALID] += invalid
        b.step(played, stepping)
        terminations = b.istate[:, batch.TERMINATED].astype(bool) & stepping
        truncations = b.istate[:, batch.TRUNCATED].astype(bool) & stepping
        rewards = np.where(stepping, b.fstate[:, batch.REWARD], 0.0)
        unresolved: list[str | None] = [None] * k_count
        for k in np.flatnonzero(truncations).tolist():
            unresolved[k] = UNRESOLVED_TEXT[int(b.istate[k, batch.UNRESOLVED])]
        b.observe(stepping, self._masks)
        ended = terminations | truncations
        finals = None
        if self.autoreset_mode == "same_step":
            finals = self._final_arrays(ended, unresolved)
            if ended.any():
                self._restart(ended, [None] * k_count)
        if restarted.any():
            self._restart(restarted, [None] * k_count)
        self._ended = ended & (self.autoreset_mode != "same_step")
        infos = self._infos(invalid, unresolved)
        if finals is not None:
            infos.update(finals)
        return self._handed(), np.repeat(rewards[:, None], self.n_agents, axis=1), terminations, truncations, infos

    def _final_arrays(self, ended: np.ndarray, unresolved: Sequence[str | None]) -> dict[str, Any]:
        """The last observation, state and figures of the instances that ended this step (arrays engine)."""
        rows = ended[:, None, None]
        obs = np.where(rows, self._obs, np.zeros_like(self._obs))
        masks = np.where(rows, self._masks, np.zeros_like(self._masks))
        states = np.where(ended[:, None], self._batch.state(self.state_space.dtype), 0).astype(self.state_space.dtype)
        figures = self._batch.figures()
        info = {key: np.where(ended, figures[key], np.zeros(1, dtype=dtype)).astype(dtype)
                for key, dtype in INFO_KEYS.items()}
        info["unresolved"] = np.array([why if end else None for why, end in zip(unresolved, ended.tolist())],
                                      dtype=object)
        return {"final_obs": {"observation": obs, "action_mask": masks}, "final_state": states,
                "final_info": info, "_final": ended.copy()}

    def _restart(self, chosen: np.ndarray, seeds: Sequence[int | None]) -> None:
        """Reset the instances where ``chosen`` is set (each env draws its next instance in Python) and load them into
        the arrays engine, with their first observations."""
        b = self._batch
        for k in np.flatnonzero(chosen).tolist():
            self.envs[k]._begin(seeds[k])             # TaskAllocEnv.reset takes no options of its own
            b.load(k, self.envs[k])
        b.score(chosen, np.zeros(self.num_envs, dtype=bool))
        b.observe(chosen, self._masks)

    # -- actions -----------------------------------------------------------------------------------------------
    def _checked(self, actions: Any) -> np.ndarray:
        """``actions`` as a (K, N) int64 array; a wrong shape or dtype is one line naming what was given."""
        array = np.asarray(actions)
        if array.dtype == np.bool_ or not np.issubdtype(array.dtype, np.integer):
            raise InvalidActionError(f"actions must be an integer array of shape ({self.num_envs}, {self.n_agents}),"
                                     f" got dtype {array.dtype}")
        if array.shape != (self.num_envs, self.n_agents):
            raise InvalidActionError(f"actions must have shape (num_envs, n_agents) = ({self.num_envs}, "
                                     f"{self.n_agents}), got {array.shape}")
        return array.astype(np.int64, copy=False)

    def _valid(self, actions: np.ndarray) -> np.ndarray:
        """(K, N) whether each action is in range and allowed by the mask handed out with the last observations;
        an instance that restarts this step (next-step autoreset) takes any action."""
        a = self._masks.shape[2]
        inside = (actions >= 0) & (actions < a)
        allowed = np.take_along_axis(self._masks, np.where(inside, actions, PASS)[:, :, None], axis=2)[:, :, 0]
        return (inside & (allowed > 0)) | self._ended[:, None]

    def _raise_first(self, actions: np.ndarray, valid: np.ndarray) -> None:
        k, i = (int(x) for x in np.argwhere(~valid)[0])
        action, agent = int(actions[k, i]), self.possible_agents[i]
        a = self._masks.shape[2]
        if not 0 <= action < a:
            raise InvalidActionError(f"instance {k}: action {action} of {agent} is outside Discrete({a})")
        env = self.envs[k]
        if self._batch is not None:
            self._batch.sync(k, env)
        raise InvalidActionError(f"instance {k}: action {action} ({describe(action, self.n_tasks)}) of {agent} is "
                                 f"not allowed by its mask: {env._why_masked(agent, action)}")

    # -- outputs -----------------------------------------------------------------------------------------------
    def _write_rows(self, k: int) -> None:
        obs, masks = self.envs[k]._rows()
        self._obs[k] = obs
        self._masks[k] = masks

    def _handed(self) -> dict[str, np.ndarray]:
        """The observations as new arrays (editing them leaves the batch's own masks, which check actions, alone)."""
        return {"observation": self._obs.copy(), "action_mask": self._masks.copy()}

    def _infos(self, invalid: np.ndarray, unresolved: Sequence[str | None] | None = None) -> dict[str, np.ndarray]:
        if self._batch is not None:
            figures = self._batch.figures()
            infos = {key: figures[key].astype(dtype) for key, dtype in INFO_KEYS.items()}
            passed = self._batch.passed.copy()
        else:
            rows = [env._figures() for env in self.envs]
            infos = {key: np.array([row[key] for row in rows], dtype=dtype) for key, dtype in INFO_KEYS.items()}
            passed = np.stack([env._engine.passed for env in self.envs])
        infos["invalid_actions"] = invalid.astype(np.int64)
        infos["passed"] = passed
        infos["unresolved"] = np.array(unresolved if unresolved is not None else [None] * self.num_envs,
                                       dtype=object)
        return infos

    def _finals(self, finals: Sequence[tuple], final: np.ndarray) -> dict[str, Any]:
        """The last observation, state and figures of the instances that ended this step (same-step autoreset)."""
        k_count = self.num_envs
        obs = np.zeros_like(self._obs)
        masks = np.zeros_like(self._masks)
        states = np.zeros(self.state_space.shape, dtype=self.state_space.dtype)
        info = {key: np.zeros(k_count, dtype=dtype) for key, dtype in INFO_KEYS.items()}
        info["unresolved"] = np.array([None] * k_count, dtype=object)
        for k, o, m, s, figures, why in finals:
            obs[k], masks[k], states[k] = o, m, s
            for key in INFO_KEYS:
                info[key][k] = figures[key]
            info["unresolved"][k] = why
        return {"final_obs": {"observation": obs, "action_mask": masks}, "final_state": states,
                "final_info": info, "_final": final}

    def state(self) -> np.ndarray:
        """(K, S) the global state of every instance (``observation.state_vector``)."""
        if not self._started:
            raise RuntimeError("call reset() before state()")
        if self._batch is not None:
            return self._batch.state(self.state_space.dtype)
        return np.stack([state_vector(env.protocol) for env in self.envs]).astype(self.state_space.dtype)

    def evaluate(self, k: int) -> Any:
        """Instance k's allocation as it stands (``TaskAllocEnv.evaluate``)."""
        if self._batch is not None:
            self._batch.sync(k, self.envs[k])
        return self.envs[k].evaluate()

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _clone(template: TaskAllocEnv) -> TaskAllocEnv:
    """A copy of an unstarted env with its own unseeded generator (copying costs a tenth of a construction)."""
    env = copy.deepcopy(template)
    env._np_random, env._np_random_seed = seeding.np_random()
    return env
