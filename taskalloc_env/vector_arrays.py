"""The batched environment's ``arrays`` engine: K instances as (K, …) arrays, each phase of a step one compiled call
over the instance axis (``kernels.batch``).

``ArrayBatch`` holds every instance's state as arrays: the group tables (member ids, bids, counts, own bids),
timestamps and discovered agents, bundles and paths (padded, with their lengths), the quit timers, the round of each
agent's latest bid on each task and its releases (the release guard's state), the path table,
the bid view, the last round's tables for the convergence test, the network's counters, and the integer and float
state of ``kernels.batch`` (round, steps, counters, flags; score, reward, scales). An instance starts from a single env
reset in Python (``load``: the scenario, the protocol's derived arrays and the observation's fixed columns are copied
in; resets are rare) and is then stepped only here. ``sync`` writes an instance back into its env, for what is read
rarely (``evaluate``, the reason an action was masked).

Scope (``unsupported`` names what is outside it): the synchronous consensus (``sync`` and ``every_step``), perfect
links or independent message loss (``loss_model="independent"``, no delay), no pop-up tasks, ``require_known_capacity``
off, the compiled kernels on (``TASKALLOC_KERNELS`` unset). Task quitting and release actions (every
``release_guard``, either ``release_order``) are in.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.config import TaskAllocConfig
from taskalloc_env.group_table import EMPTY, GroupTable
from taskalloc_env.kernels import batch
from taskalloc_env.kernels.bids import PREREQ_MODES
from taskalloc_env.kernels.observe import COLUMNS as KERNEL_COLUMNS
from taskalloc_env.kernels.quits import RELEASE_GUARDS
from taskalloc_env.observation import state_vector

# what Protocol.unresolved says, by ``kernels.batch``'s code (the texts are Protocol.end_round's)
UNRESOLVED_TEXT: dict[int, str | None] = {
    0: None,
    batch.NOT_SETTLED: "no table changed for D + 1 rounds, but an agent has not received a message its neighbour "
                       "sent after the last change (lost or delayed messages), or still counts on a failed agent",
    batch.DISAGREE: "no table changed for D + 1 rounds, but the agents' tables disagree",
    batch.ROUND_BOUND: "the round bound T_max came while the tables were still changing (lost or delayed messages, "
                       "or failed agents)",
}
# the Counters fields the integer state carries
COUNTERS = {"rounds": batch.ROUND, "messages": batch.MESSAGES, "informative_messages": batch.INFORMATIVE,
            "data_items": batch.DATA_ITEMS, "bids": batch.BIDS, "invalid_actions": batch.INVALID,
            "rounds_to_agreement": batch.TO_AGREEMENT, "messages_to_agreement": batch.MESSAGES_TO_AGREEMENT,
            "messages_sent": batch.SENT, "messages_lost": batch.LOST, "data_items_sent": batch.ITEMS_SENT,
            "max_agent_messages": batch.MAX_AGENT, "conflicting_bids": batch.CONFLICTING,
            "silent_releases": batch.SILENT, "quits": batch.QUITS, "quits_seen": batch.QUITS_SEEN,
            "releases": batch.RELEASES}


def unsupported(cfg: TaskAllocConfig) -> str | None:
    """Why ``cfg`` is outside the arrays engine's scope (None: inside it)."""
    if not kernels.COMPILED:
        return "the compiled kernels are off (TASKALLOC_KERNELS=reference or no numba)"
    checks = [
        (cfg.consensus in ("sync", "every_step"), f"consensus={cfg.consensus!r} (only 'sync' and 'every_step')"),
        (not cfg.loses_messages or cfg.loss_model == "independent",
         f"loss_model={cfg.loss_model!r} (only 'independent')"),
        (cfg.max_delay == 0, "max_delay > 0"),
        (cfg.popup_tasks == 0, "popup_tasks > 0"),
        (not cfg.require_known_capacity, "require_known_capacity"),
    ]
    for ok, reason in checks:
        if not ok:
            return reason
    return None


class ArrayBatch:
    """The state of K instances as arrays and the compiled phases of their step; see the module docstring."""

    def __init__(self, k: int, template: Any, obs: np.ndarray) -> None:
        """Arrays for K instances shaped like ``template``'s (an unstarted ``TaskAllocEnv``); the observations are
        written into ``obs`` (K, N, D), whose fixed columns are set when an instance starts."""
        cfg = template.config
        n, m = cfg.n_agents, cfg.n_tasks
        layout = template.observation_layout
        e = layout.n_equipment
        w = max(min(template._max_agents_per_task, n), 1)
        self.k, self.n, self.m = k, n, m
        self.own_size, self.task_size = layout.own_size, layout.task_size
        self.max_cycles = int(template.max_cycles)
        self.every_step = cfg.consensus == "every_step"
        self.perfect = not cfg.loses_messages
        self.loss = float(cfg.message_loss)
        self.by_bundle = cfg.release_order == "bundle"
        self.canonical = cfg.cbba_table == "canonical"
        self.leg_cost, self.arrival_time = cfg.distance_cost == "leg", cfg.reward_time == "arrival"
        self.frozen, self.first_l_paid = cfg.marginal_gain == "frozen", cfg.conflict_policy == "first_L_paid"
        self.prereq_mode, self.warping = PREREQ_MODES[cfg.prereq_mode], bool(cfg.bid_warping)
        self.strict = cfg.outbid_ties == "strict"
        self.task_quitting, self.delta = bool(cfg.task_quitting), int(cfg.delta)
        self.reset_on_additions, self.until_joined = cfg.reset_on == "additions", cfg.quit_block == "until_joined"
        self.guard = RELEASE_GUARDS[cfg.release_guard]
        names = layout.task_names
        self.columns = np.array([names.index(c) for c in KERNEL_COLUMNS], dtype=np.int64)
        self.silence_column = names.index("member_silence") if "member_silence" in names else -1

        def z(*shape: int, dtype: Any = np.float64) -> np.ndarray:
            return np.zeros((k, *shape), dtype=dtype)

        i64, b = np.int64, np.bool_
        self.istate, self.fstate, self.statics = z(batch.INT_STATE, dtype=i64), z(batch.FLOAT_STATE), \
            z(batch.STATIC_INTS, dtype=i64)
        self.count, self.ids, self.values, self.own = z(n, m, dtype=i64), z(n, m, w, dtype=i64), z(n, m, w), z(n, m)
        self.stamps, self.known = z(n, n), z(n, n, dtype=b)
        self.bundles, self.bundle_len = z(n, m, dtype=i64), z(n, dtype=i64)
        self.paths, self.path_len = z(n, m, dtype=i64), z(n, dtype=i64)
        self.assigned_at, self.quit = z(n, m, dtype=i64), z(n, m, dtype=b)
        self.quit_blocked, self.pending = z(n, m, dtype=b), z(n, m, dtype=b)      # pending: quits nobody saw yet
        self.bid_round, self.released = z(n, m, dtype=i64), z(n, m, dtype=b)      # Protocol._bid_round, _released
        self.last_count, self.last_ids, self.last_values = z(n, m, dtype=i64), z(n, m, w, dtype=i64), z(n, m, w)
        self.last_bundles, self.last_bundle_len = z(n, m, dtype=i64), z(n, dtype=i64)
        self.last_heard, self.sent_by = z(n, n, dtype=i64), z(n, dtype=i64)
        self.passed, self.dirty, self.stale = z(n, dtype=b), z(n, dtype=b), z(n, dtype=b)   # paths, view rows
        self.gain, self.slot = z(n, m), z(n, m, dtype=i64)
        self.pt_members, self.pt_reward, self.pt_start, self.pt_cost = z(n, m, dtype=b), z(n, m), z(n, m), z(n)
        self.view_bid, self.outbid, self.eligible, self.prereqs_met = z(n, m), z(n, m, dtype=b), z(n, m, dtype=b), \
            z(n, m, dtype=b)
        self.members, self.group_total, self.lowest_bid = z(n, m, dtype=i64), z(n, m), z(n, m)
        self.displaced, self.displaced_bid, self.in_bundle = z(n, m, dtype=i64), z(n, m), z(n, m, dtype=b)
        # the scenario of each instance (written at its reset)
        self.speed, self.dist_at, self.dist_tt = z(n), z(n, m), z(m, m)
        self.earliest, self.deadline, self.doable = z(m), z(m), z(m, dtype=b)
        self.duration, self.task_start, self.pay = z(m), z(m), z(m)
        self.capacity, self.single, self.restricted = z(m, dtype=i64), z(m, dtype=b), z(m, dtype=b)
        self.required, self.agent_eq = z(m, e, dtype=i64), z(n, e, dtype=b)
        self.equipment_match, self.fillable, self.prereqs = z(n, m, dtype=b), z(m, dtype=b), z(m, m, dtype=b)
        self.adjacency, self.component = z(n, n, dtype=b), z(n, dtype=i64)
        # views into the observations: the own columns (K, N, own) and the task blocks (K, N, M, F)
        self.obs = obs
        self.own_features = obs[:, :, :self.own_size]
        self.tasks = obs[:, :, self.own_size:].reshape(k, n, m, self.task_size)
        if not np.shares_memory(self.tasks, obs):
            raise ValueError("the task blocks must be a view into the observations")
        self.state_static = z(template.state_space.shape[0] - n * m - 1)       # state_vector before the bids
        self.rngs: list[np.random.Generator | None] = [None] * k
        self.keep = np.ones((k, n * n), dtype=bool)

    @staticmethod
    def bytes_per_instance(template: Any) -> int:
        """The bytes one instance's arrays take (counted on a batch of one shaped like ``template``), without the
        observations, which the caller allocates."""
        n = template.config.n_agents
        d = template.observation_space(template.possible_agents[0])["observation"].shape[0]
        one = ArrayBatch(1, template, np.zeros((1, n, d)))
        return sum(value.nbytes for value in vars(one).values()
                   if isinstance(value, np.ndarray) and not np.shares_memory(value, one.obs))

    # -- instances in and out --------------------------------------------------------------------------------------
    def load(self, k: int, env: Any) -> None:
        """Instance k starts from ``env`` just reset: its scenario, derived arrays and empty tables."""
        p = env.protocol
        s, model, kn, groups = p.scenario, p.model, p.knowledge, p.knowledge.groups
        w = groups.members.shape[2]
        self.ids[k] = EMPTY
        self.values[k] = 0.0
        self.ids[k, :, :, :w], self.values[k, :, :, :w] = groups.members, groups.bids
        self.count[k], self.own[k] = groups.count, groups.own
        self.last_ids[k], self.last_values[k], self.last_count[k] = self.ids[k], self.values[k], self.count[k]
        self.stamps[k], self.known[k] = kn.timestamps, kn.known
        self.bundle_len[k] = self.path_len[k] = self.last_bundle_len[k] = 0
        self.assigned_at[k], self.quit[k], self.quit_blocked[k] = kn.assigned_at, kn.quit, kn.quit_blocked
        self.pending[k] = False
        self.bid_round[k], self.released[k] = p._bid_round, p._released
        self.last_heard[k], self.sent_by[k] = 0, 0
        self.passed[k] = env._engine.passed
        self.dirty[k] = self.stale[k] = True      # every path is timed (empty) and every row viewed at the start
        self.pt_members[k], self.pt_reward[k], self.pt_start[k], self.pt_cost[k] = False, 0.0, np.inf, 0.0
        self.gain[k], self.slot[k] = 0.0, -1
        self.istate[k] = 0
        graph = p.live_graph
        self.statics[k] = 0
        st = self.statics[k]
        st[batch.MAX_ROUNDS], st[batch.DIAMETER], st[batch.SILENCE_TIMEOUT] = p.max_rounds, graph.diameter, \
            p.silence_timeout
        st[batch.MAX_BUNDLE], st[batch.HAS_PREREQS] = p.max_bundle, s.has_prerequisites
        st[batch.EQUIPMENT_ANY], st[batch.N_LINKS] = model.equipment.any, int(graph.adjacency.sum())
        fs = self.fstate[k]
        fs[:] = 0.0
        fs[batch.SCALE], fs[batch.LAM], fs[batch.GAMMA] = env._reward_scale, model.lam, model.gamma
        fs[batch.UNIT] = env._builder.scales.reward_unit
        self.speed[k], self.dist_at[k], self.dist_tt[k] = model.speed, model.dist_agent_task, model.dist_task_task
        self.earliest[k], self.deadline[k], self.doable[k] = model.earliest, model.deadline, model.doable
        self.duration[k], self.task_start[k], self.pay[k] = s.task_duration, s.task_start, model.pay
        self.capacity[k], self.single[k] = s.task_agents, kn.single
        self.restricted[k], self.required[k], self.agent_eq[k] = p.equipment.restricted, p.equipment.required, \
            p.equipment.agent
        self.equipment_match[k], self.fillable[k] = p.equipment_match, p.fillable & p.released
        self.prereqs[k] = s.task_prereqs
        self.adjacency[k], self.component[k] = graph.adjacency, graph.component
        self.obs[k] = env._builder._buffer        # the fixed columns, in the observations' dtype (as ``_finish``)
        self.rngs[k] = p.network.rng
        self.state_static[k] = state_vector(p)[:self.state_static.shape[1]]

    def sync(self, k: int, env: Any) -> None:
        """Write instance k's state into ``env`` (its protocol, engine and last score), for rare reads."""
        p, w = env.protocol, env.protocol.knowledge.groups.members.shape[2]
        kn, g, ist = p.knowledge, p.knowledge.groups, self.istate[k]
        g.members[:], g.bids[:] = self.ids[k, :, :, :w], self.values[k, :, :, :w]
        g.count[:], g.own[:] = self.count[k], self.own[k]
        kn.timestamps[:], kn.known[:], kn.assigned_at[:] = self.stamps[k], self.known[k], self.assigned_at[k]
        kn.quit[:], kn.quit_blocked[:] = self.quit[k], self.quit_blocked[k]
        p._pending_quits = {(int(i), int(j)): None for i, j in zip(*np.nonzero(self.pending[k]))}
        p._bid_round[:], p._released[:] = self.bid_round[k], self.released[k]
        kn.bundles = [self.bundles[k, i, :self.bundle_len[k, i]].tolist() for i in range(self.n)]
        kn.paths = [self.paths[k, i, :self.path_len[k, i]].tolist() for i in range(self.n)]
        p.round, p.stable_rounds = int(ist[batch.ROUND]), int(ist[batch.STABLE])
        p.converged, p.unresolved = bool(ist[batch.CONVERGED]), UNRESOLVED_TEXT[int(ist[batch.UNRESOLVED])]
        for name, column in COUNTERS.items():
            setattr(p.counters, name, int(ist[column]))
        last = GroupTable(self.last_ids[k, :, :, :w].copy(), self.last_values[k, :, :, :w].copy(),
                          self.last_count[k].copy(), np.zeros_like(g.own), g.capacity, g.n_agents)
        p._last_groups = last
        p._last_bundles = [self.last_bundles[k, i, :self.last_bundle_len[k, i]].tolist() for i in range(self.n)]
        p.last_heard[:], p.network.sent_by[:] = self.last_heard[k], self.sent_by[k]
        p._paths.members[:], p._paths.reward[:] = self.pt_members[k], self.pt_reward[k]
        p._paths.start[:], p._paths.cost[:] = self.pt_start[k], self.pt_cost[k]
        p._gain[:], p._slot[:] = self.gain[k], self.slot[k]
        p._dirty.clear()
        p._touch()
        env._engine.passed[:] = self.passed[k]
        env._engine.steps = int(ist[batch.STEPS])
        env._last_score = float(self.fstate[k, batch.LAST_SCORE])

    # -- the phases --------------------------------------------------------------------------------------------------
    def step(self, actions: np.ndarray, which: np.ndarray) -> None:
        """One step of the instances in ``which`` with their (K, N) valid actions: apply, end the rounds that end
        (the losses drawn from each instance's generator, as ``IndependentLoss.lost`` draws them), score."""
        batch.apply_actions(which, actions, self.every_step, self.by_bundle, self.until_joined, self.leg_cost,
                            self.arrival_time, self.frozen, self.istate, self.fstate, self.passed, self.dirty,
                            self.stale, self.bundles, self.bundle_len, self.paths, self.path_len, self.assigned_at,
                            self.quit, self.quit_blocked, self.pending, self.count, self.ids, self.values, self.own,
                            self.capacity, self.view_bid, self.slot, self.displaced, self.speed, self.dist_at,
                            self.dist_tt, self.earliest, self.deadline, self.doable, self.duration, self.task_start,
                            self.pay, self.gain, self.pt_members, self.pt_reward, self.pt_start, self.pt_cost,
                            self.bid_round, self.released)
        if not self.perfect:
            links = self.statics[:, batch.N_LINKS]
            for k in np.flatnonzero(self.istate[:, batch.ENDS_ROUND]).tolist():
                self.keep[k, :links[k]] = ~(self.rngs[k].random(int(links[k])) < self.loss)
        batch.end_rounds(self.istate, self.statics, self.perfect, self.by_bundle, self.canonical, self.task_quitting,
                         self.delta, self.reset_on_additions, self.keep, self.assigned_at, self.quit,
                         self.quit_blocked, self.pending, self.passed, self.dirty, self.stale, self.count, self.ids,
                         self.values, self.own, self.stamps, self.known,
                         self.bundles, self.bundle_len, self.paths, self.path_len, self.last_count, self.last_ids,
                         self.last_values, self.last_bundles, self.last_bundle_len, self.last_heard, self.sent_by,
                         self.adjacency, self.component, self.single, self.capacity, self.restricted, self.required,
                         self.agent_eq)
        self.score(which, which)

    def score(self, which: np.ndarray, stepped: np.ndarray) -> None:
        """The team score of the instances in ``which``; the reward and flags of those ``stepped``."""
        batch.score_all(which, stepped, self.max_cycles, self.leg_cost, self.arrival_time, self.frozen,
                        self.first_l_paid, self.istate, self.fstate, self.statics, self.dirty, self.paths,
                        self.path_len, self.speed, self.dist_at, self.dist_tt, self.earliest, self.deadline,
                        self.doable, self.duration, self.task_start, self.pay, self.gain, self.slot, self.pt_members,
                        self.pt_reward, self.pt_start, self.pt_cost, self.capacity, self.required, self.agent_eq,
                        self.prereqs)

    def observe(self, which: np.ndarray, masks: np.ndarray) -> None:
        """The observations of the instances in ``which`` (their rows of ``obs``) and their rows of ``masks``."""
        batch.observe_all(which, self.prereq_mode, self.warping, self.strict, self.silence_column,
                          self.task_quitting, self.delta, self.guard, self.columns, self.istate, self.fstate,
                          self.statics,
                          self.passed, self.stale, self.count, self.ids, self.values, self.own, self.stamps,
                          self.assigned_at, self.quit, self.quit_blocked, self.bundle_len, self.single, self.gain,
                          self.equipment_match, self.fillable, self.capacity, self.restricted, self.required,
                          self.agent_eq, self.prereqs, self.view_bid, self.outbid, self.eligible, self.prereqs_met,
                          self.members, self.group_total, self.lowest_bid, self.displaced, self.displaced_bid,
                          self.in_bundle, self.bid_round, self.released, self.tasks, self.own_features, masks)

    # -- outputs -------------------------------------------------------------------------------------------------------
    def figures(self) -> dict[str, np.ndarray]:
        """``TaskAllocEnv._figures`` of every instance, as arrays."""
        ist = self.istate
        return {"score": self.fstate[:, batch.SCORE].copy(), "valid_tasks": ist[:, batch.VALID].copy(),
                "conflicts": ist[:, batch.CONFLICTS].copy(), "round": ist[:, batch.ROUND].copy(),
                "messages": ist[:, batch.MESSAGES].copy(), "data_items": ist[:, batch.DATA_ITEMS].copy(),
                "converged": ist[:, batch.CONVERGED].astype(bool)}

    def state(self, dtype: np.dtype) -> np.ndarray:
        """(K, S) ``observation.state_vector`` of every instance: its fixed part, the own bids ÷ c̄, the round."""
        bids = self.own.reshape(self.k, -1) / self.fstate[:, batch.UNIT, None]
        fraction = np.minimum(self.istate[:, batch.ROUND] / self.statics[:, batch.MAX_ROUNDS], 1.0)
        return np.concatenate([self.state_static, bids, fraction[:, None]], axis=1).astype(dtype)
