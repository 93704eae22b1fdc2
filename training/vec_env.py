"""A stable-baselines3 ``VecEnv`` over copies of the parallel env, with parameter sharing.

Every learned agent of every env copy is one slot of the vector env: slot ``c * K + k`` is the k-th learned agent
(in ``possible_agents`` order) of copy c, with K learned agents per copy. One policy therefore acts for all of
them (parameter sharing, as SuperSuit's ``pettingzoo_env_to_vec_env_v1``), but this adapter also provides what
SuperSuit's converter lacks with SB3 2.9 (SuperSuit 3.11's ``ConcatVecEnv`` has no ``seed``, ``has_attr`` or
``env_method``, and never sets ``TimeLimit.truncated``; sb3-contrib's ``MaskablePPO`` reads masks through
``env_method("action_masks")``):

* ``seed(seed)``: copy c is reset with ``seed + c`` at the next ``reset()``; later episodes continue each copy's
  generator, so a seeded run replays exactly;
* ``has_attr("action_masks")`` / ``env_method("action_masks")`` for sb3-contrib's ``MaskablePPO`` (the masks come
  from the last observations, so no round trip to the copies);
* ``TimeLimit.truncated`` (truncated and not terminated) and ``terminal_observation`` in the infos of every slot
  of a finished copy; the copy is then reset (all agents of a copy end together);
* ``episode``: the env's record (``r``, ``l``, score, valid tasks, conflicts, rounds, messages, converged;
  ``taskalloc_env.rewards``) plus the wall time ``t``, in the info of the copy's first slot only, once per episode,
  so SB3's ``ep_info_buffer`` counts episodes, not agents (the env gives every agent one);
* mixed teams: agents in ``scripted_agents`` are played by scripted policies inside the copy and get no slot;
* copies run in this process (``n_procs=0``, like ``DummyVecEnv``) or spread over ``n_procs`` subprocesses.

Observations keep the env's ``Dict(observation, action_mask)`` space, so a policy can also mask its logits itself.
"""

from __future__ import annotations

import itertools
import multiprocessing as mp
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnv, VecEnvIndices

from taskalloc.policies.base import stack_observations
from taskalloc.policies.teams import ScriptedTeammates, check_scripted_agents

EnvFn = Callable[[], ParallelEnv]
MASK_METHOD = "action_masks"


class EnvCopy:
    """One parallel env and its scripted teammates; steps with the learned agents' actions and auto-resets."""

    def __init__(self, env_fn: EnvFn, scripted_agents: Mapping[str, str] | None = None) -> None:
        self.env = env_fn()
        self.scripted = check_scripted_agents(scripted_agents, list(self.env.possible_agents))
        self.learned = [a for a in self.env.possible_agents if a not in self.scripted]
        self.teammates = ScriptedTeammates(self.scripted) if self.scripted else None
        self._rng = np.random.default_rng()
        self._obs: dict[str, Any] = {}
        self._infos: dict[str, Any] = {}
        self._t0 = time.perf_counter()

    def spaces(self) -> tuple[spaces.Space, spaces.Space]:
        agent = self.learned[0]
        return self.env.observation_space(agent), self.env.action_space(agent)

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[dict[str, np.ndarray], list[dict]]:
        """Reset the env (``seed`` drives the instance and the teammates); per-slot observations and infos."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._obs, self._infos = self.env.reset(seed=seed, options=options)
        if self.teammates is not None:
            self.teammates.start(self.env, int(self._rng.integers(2**31)))
        self._t0 = time.perf_counter()
        return self._stack(self._obs), [dict(self._infos.get(a, {})) for a in self.learned]

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict]]:
        """Step with one action per learned agent; at the episode end, report it and reset."""
        joint = {a: int(x) for a, x in zip(self.learned, actions)}
        if self.teammates is not None:
            joint.update(self.teammates.act({a: self._obs[a] for a in self.scripted}, self._infos))
        obs, rewards, terminations, truncations, infos = self.env.step(joint)
        self._obs, self._infos = obs, infos
        reward = np.array([rewards[a] for a in self.learned], dtype=np.float32)
        terminated = all(terminations.values())
        truncated = all(truncations.values())
        done = terminated or truncated or not self.env.agents
        slot_infos = [dict(infos.get(a, {})) for a in self.learned]
        for info in slot_infos:                 # an agent's own record (a failed agent's too): one per episode below
            info.pop("episode", None)
        if not done:
            return self._stack(obs), reward, np.zeros(len(self.learned), dtype=bool), slot_infos
        for agent, info in zip(self.learned, slot_infos):
            info["terminal_observation"] = obs[agent]
            info["TimeLimit.truncated"] = truncated and not terminated
        # every agent still in the episode carries the same record (none with episode_stats=False)
        record = next((info["episode"] for info in infos.values() if "episode" in info), None)
        if record is not None:
            slot_infos[0]["episode"] = {**record, "t": round(time.perf_counter() - self._t0, 6)}
        new_obs, _ = self.reset()
        return new_obs, reward, np.ones(len(self.learned), dtype=bool), slot_infos

    def _stack(self, obs: Mapping[str, Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
        observations, masks = stack_observations(obs, self.learned)
        return {"observation": observations, "action_mask": masks}

    def get_attr(self, name: str) -> Any:
        return getattr(self.env, name)

    def set_attr(self, name: str, value: Any) -> None:
        setattr(self.env, name, value)

    def call(self, name: str, args: tuple, kwargs: dict) -> Any:
        return getattr(self.env, name)(*args, **kwargs)

    def dispatch(self, request: tuple[str, tuple] | None) -> Any:
        """Run ``getattr(self, method)(*args)``; None does nothing (for copies a request does not concern)."""
        if request is None:
            return None
        method, args = request
        return getattr(self, method)(*args)

    def close(self) -> None:
        self.env.close()


def _worker(remote: Any, parent_remote: Any, factory: CloudpickleWrapper) -> None:
    """Subprocess loop: holds a few copies and runs ``(method, [args per copy])`` requests on them."""
    parent_remote.close()
    copies: list[EnvCopy] = factory.var()
    try:
        while True:
            method, args = remote.recv()
            if method == "close":
                for copy in copies:
                    copy.close()
                remote.close()
                return
            try:
                remote.send((True, [getattr(copy, method)(*a) for copy, a in zip(copies, args)]))
            except Exception as error:
                remote.send((False, error))
    except (EOFError, KeyboardInterrupt):
        return


class _LocalCopies:
    """Copies in this process (``DummyVecEnv``-style)."""

    def __init__(self, env_fns: Sequence[EnvFn], scripted_agents: Mapping[str, str] | None) -> None:
        self.copies = [EnvCopy(fn, scripted_agents) for fn in env_fns]
        self._pending: list[Any] = []

    def send(self, method: str, args: Sequence[tuple]) -> None:
        self._pending = [getattr(copy, method)(*a) for copy, a in zip(self.copies, args)]

    def recv(self) -> list[Any]:
        return self._pending

    def close(self) -> None:
        for copy in self.copies:
            copy.close()


class _SubprocCopies:
    """Copies spread over ``n_procs`` worker processes (contiguous chunks)."""

    def __init__(self, env_fns: Sequence[EnvFn], scripted_agents: Mapping[str, str] | None, n_procs: int,
                 start_method: str | None = None) -> None:
        n_procs = min(n_procs, len(env_fns))
        bounds = np.linspace(0, len(env_fns), n_procs + 1).astype(int)
        self.chunks = [(int(lo), int(hi)) for lo, hi in itertools.pairwise(bounds)]
        ctx = mp.get_context(start_method or ("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"))
        self.remotes, self.processes = [], []
        for lo, hi in self.chunks:
            fns = list(env_fns[lo:hi])
            factory = CloudpickleWrapper(lambda fns=fns: [EnvCopy(fn, scripted_agents) for fn in fns])
            remote, work_remote = ctx.Pipe()
            process = ctx.Process(target=_worker, args=(work_remote, remote, factory), daemon=True)
            process.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(process)
        self.closed = False

    def send(self, method: str, args: Sequence[tuple]) -> None:
        for remote, (lo, hi) in zip(self.remotes, self.chunks):
            remote.send((method, list(args[lo:hi])))

    def recv(self) -> list[Any]:
        out: list[Any] = []
        for remote in self.remotes:
            ok, value = remote.recv()
            if not ok:
                raise value
            out.extend(value)
        return out

    def close(self) -> None:
        if self.closed:
            return
        for remote in self.remotes:
            remote.send(("close", None))
        for process in self.processes:
            process.join(timeout=5)
        self.closed = True


class TaskAllocVecEnv(VecEnv):
    """``num_envs = n_copies × learned agents per copy``; see the module docstring for the contract."""

    def __init__(self, env_fns: Sequence[EnvFn], scripted_agents: Mapping[str, str] | None = None,
                 n_procs: int = 0, start_method: str | None = None) -> None:
        if not env_fns:
            raise ValueError("TaskAllocVecEnv needs at least one env_fn")
        probe = EnvCopy(env_fns[0], scripted_agents)
        self.learned_agents = list(probe.learned)
        self.scripted_agents = dict(probe.scripted)
        self.n_copies = len(env_fns)
        self.agents_per_copy = len(self.learned_agents)
        observation_space, action_space = probe.spaces()
        if n_procs > 0:
            probe.close()
            self._copies: _LocalCopies | _SubprocCopies = _SubprocCopies(env_fns, scripted_agents, n_procs,
                                                                         start_method)
        else:
            self._copies = _LocalCopies(env_fns[1:], scripted_agents)
            self._copies.copies.insert(0, probe)
        self._copy_seeds: list[int | None] = [None] * self.n_copies
        self._masks = np.ones((self.n_copies * self.agents_per_copy, action_space.n), dtype=bool)
        super().__init__(self.n_copies * self.agents_per_copy, observation_space, action_space)

    # -- slots <-> copies ----------------------------------------------------------------------------------------
    def _slots(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [int(indices)] if isinstance(indices, (int, np.integer)) else [int(i) for i in indices]

    def _slot_copies(self, indices: VecEnvIndices) -> list[int]:
        return [s // self.agents_per_copy for s in self._slots(indices)]

    def _merge_obs(self, per_copy: Sequence[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
        obs = {key: np.concatenate([o[key] for o in per_copy]) for key in ("observation", "action_mask")}
        self._masks = obs["action_mask"].astype(bool)
        return obs

    # -- VecEnv API ------------------------------------------------------------------------------------------------
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Copy c gets ``seed + c`` at the next ``reset()``; returns one entry per slot (its copy's seed)."""
        if seed is None:
            seed = int(np.random.default_rng().integers(np.iinfo(np.uint32).max))
        self._copy_seeds = [seed + c for c in range(self.n_copies)]
        return [self._copy_seeds[c] for c in self._slot_copies(None)]

    def reset(self) -> dict[str, np.ndarray]:
        options = [self._options[c * self.agents_per_copy] or None for c in range(self.n_copies)]
        self._copies.send("reset", [(s, o) for s, o in zip(self._copy_seeds, options)])
        results = self._copies.recv()
        self._copy_seeds = [None] * self.n_copies
        self._reset_options()
        self.reset_infos = [info for _, infos in results for info in infos]
        return self._merge_obs([obs for obs, _ in results])

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions).reshape(self.n_copies, self.agents_per_copy)
        self._copies.send("step", [(a,) for a in actions])

    def step_wait(self) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, list[dict]]:
        results = self._copies.recv()
        obs = self._merge_obs([r[0] for r in results])
        rewards = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        return obs, rewards, dones, infos

    def action_masks(self) -> np.ndarray:
        """(num_envs, n_actions) bool masks of the last observations."""
        return self._masks.copy()

    def has_attr(self, attr_name: str) -> bool:
        if attr_name == MASK_METHOD:
            return True
        return super().has_attr(attr_name)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        copies = self._slot_copies(indices)
        values = self._call_copies("get_attr", {c: (attr_name,) for c in set(copies)})
        return [values[c] for c in copies]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._call_copies("set_attr", {c: (attr_name, value) for c in set(self._slot_copies(indices))})

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        if method_name == MASK_METHOD:
            masks = self.action_masks()
            return [masks[s] for s in self._slots(indices)]
        copies = self._slot_copies(indices)
        values = self._call_copies("call", {c: (method_name, method_args, method_kwargs) for c in set(copies)})
        return [values[c] for c in copies]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._slot_copies(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        return self.env_method("render", indices=[c * self.agents_per_copy for c in range(self.n_copies)])

    def close(self) -> None:
        self._copies.close()

    def _call_copies(self, method: str, args: Mapping[int, tuple]) -> dict[int, Any]:
        """Run ``method`` on the copies named in ``args``; the others do nothing."""
        self._copies.send("dispatch", [((method, args[c]) if c in args else None,) for c in range(self.n_copies)])
        values = self._copies.recv()
        return {c: values[c] for c in args}


def make_env_fns(n_copies: int, **env_kwargs: Any) -> list[EnvFn]:
    """``n_copies`` picklable constructors of ``TaskAllocEnv(**env_kwargs)``."""
    from taskalloc_env.taskalloc_v0 import parallel_env

    return [_EnvFactory(parallel_env, dict(env_kwargs)) for _ in range(n_copies)]


class _EnvFactory:
    """A picklable ``lambda: parallel_env(**kwargs)``."""

    def __init__(self, fn: Callable[..., ParallelEnv], kwargs: dict[str, Any]) -> None:
        self.fn, self.kwargs = fn, kwargs

    def __call__(self) -> ParallelEnv:
        return self.fn(**self.kwargs)
