"""Fuzzing: random scenarios across every option, every policy, and the invariants that must hold on each episode.

    taskalloc fuzz                      # 300 episodes (seconds), seed 0
    taskalloc fuzz --episodes 20000 --seed 7 --jobs 2

Each episode draws a config (sizes, L_j, equipment mixes, prerequisite chains, communication range, every named
scoring and protocol option, message loss, bursts, delays and failing agents, heavier loss and delay from a third
stream (``HEAVY_FAULTS``), pop-up tasks, the asynchronous consensus ``acbba`` with its processing times and table
options), a policy (random, CBGA and its variants, CBBA and ACBBA where every L_j = 1) and a seed, runs it and checks:

* ``spaces``: every observation lies in its space, every mask is binary int8 with pass allowed, every action the
  policy takes is allowed;
* ``return``: the episode return × reward_scale equals ``evaluate().score``;
* ``converged``: the episode ends by convergence (every live agent agreeing), not by the round bound (lost and
  delayed messages and failing agents included). Not applicable, counted apart with the reason: the documented ACBBA
  livelocks (docs/decisions.md "livelock"), recognised by ``AsyncProtocol.livelocked`` (agents keep talking while the
  bundles reach no new state: Johnson's row 15 on a network that is not fully connected, a stale bid re-timed by
  ``acbba_outbid_time = bump`` on any); an episode under message loss that ends saying why (``Protocol.unresolved``:
  a synchronous agent still waiting for a neighbour's message after the last change; under ``acbba``, which never
  resends, two agents disagreeing after the last message between them was lost, docs/decisions.md "lost
  messages"); and ``cbba_table = thesis`` where the canonical table converges on the same case (docs/decisions.md
  "thesis table");
* ``agreement`` and ``conflict-free``: at convergence on a connected network every live agent holds the same table
  and no task has more than L_j members (thesis §3.2: the consensus reaches a conflict-free allocation);
* ``valid groups``: every valid task has exactly L_j members whose equipment covers it, and its prerequisites are
  valid;
* ``determinism``: the same (config, policy, seed) run again gives byte-identical observations, rewards and infos.

The counts per check are printed; any failure prints its reproducer (the config mapping, the policy and the seed) and
the command exits with status 1. ``tests/test_fuzz.py`` runs a fixed budget in CI.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from taskalloc.evaluation.episodes import default_jobs
from taskalloc.evaluation.pool import parallel_map
from taskalloc.policies import make_policy
from taskalloc_env import TaskAllocEnv
from taskalloc_env.config import CHOICES
from taskalloc_env.errors import run_cli, seed_argument

# loss and delay beyond the drawn range: those under which episodes once ended "converged" in disagreement
HEAVY_FAULTS = ((0.3, 2), (0.5, 4), (1.0, 0))
THESIS_TABLE = ("the thesis's printed CBBA table (cbba_table = thesis, Table 2.1 cell (m, i)) loops where the "
                "canonical table converges (docs/decisions.md \"thesis table\")")
CHECKS = ("spaces", "return", "converged", "agreement", "conflict-free", "valid groups", "determinism")
POLICIES = ("random", "cbga", "cbga+tb", "cbga+tq", "cbgabi")


def options(field: str, *without: str) -> list[str]:
    """The values the fuzzer draws for a named option: its choices (the config's facts) but ``without``."""
    return [value for value in CHOICES[field] if value not in without]


def draw_equipment(rng: np.random.Generator, n_tasks: int) -> dict[str, Any]:
    """Agent types A and B and a random task mix: tasks needing one agent per item (thesis §3.1.3) and plain ones."""
    first = int(rng.integers(0, n_tasks + 1))
    second = int(rng.integers(0, n_tasks - first + 1))
    return {"agent_types": ["A", "B"],
            "task_mix": [{"count": first, "equipment": list(rng.choice(["A", "B", "AB", "AA"]))},
                         {"count": second, "equipment": list(rng.choice(["AB", "BB"]))},
                         {"count": n_tasks - first - second, "agents": int(rng.integers(1, 3))}]}


def draw_config(rng: np.random.Generator, extra: np.random.Generator,
                faults: np.random.Generator | None = None) -> dict[str, Any]:
    """A random config over every option (small sizes, so that thousands of episodes run in minutes). Pop-up tasks
    and the asynchronous consensus come from ``extra``, a second stream, so the other options of a seed are drawn
    as before they existed; heavy faults (``HEAVY_FAULTS``) from ``faults``, a third, when given."""
    n_agents, n_tasks = int(rng.integers(2, 8)), int(rng.integers(2, 10))
    kw: dict[str, Any] = {"n_agents": n_agents, "n_tasks": n_tasks,
                          "start_time_range": [0.0, float(rng.choice([10.0, 30.0, 60.0]))],
                          "window": float(rng.choice([2.0, 5.0, 10.0])), "duration": float(rng.choice([0.0, 5.0]))}
    kind = rng.choice(["plain", "plain", "equipment", "prerequisites"])
    if kind == "equipment":
        kw.update(draw_equipment(rng, n_tasks))
    else:
        choices = [1, 2, 3, [1, 2], [1, 2, 3], [2, 3]]
        kw["agents_per_task"] = choices[int(rng.integers(len(choices)))]
        kw["agents_per_task"] = [v for v in np.atleast_1d(kw["agents_per_task"]).tolist() if v <= n_agents] or 1
        if kind == "prerequisites":
            length = int(rng.integers(2, min(3, n_tasks) + 1))
            kw["prerequisites"] = {"chains": int(rng.integers(1, max(1, n_tasks // length) + 1)), "length": length,
                                   "followup_window": bool(rng.integers(2))}
            kw["prereq_mode"] = str(rng.choice(options("prereq_mode")))
            kw["prereq_timing"] = str(rng.choice(options("prereq_timing")))
    if rng.random() < 0.3:
        kw["comm_range"] = float(rng.uniform(0.5, 4.0))
        kw["require_known_capacity"] = bool(rng.integers(2))
    for field in ("marginal_gain", "reward_split", "release_order", "cbba_table", "consensus", "reset_on",
                  "quit_block", "conflict_policy", "distance_cost"):
        kw[field] = str(rng.choice(options(field, "acbba")))            # acbba: drawn from ``extra`` below
    if rng.random() < 0.3:
        kw["max_bundle"] = int(rng.integers(1, 4))
    if extra.random() < 0.3:                            # pop-up tasks (releases), in every consensus mode
        kw["popup_tasks"] = int(extra.integers(1, n_tasks + 1))
        kw["popup_period"] = int(extra.choice([1, 5, 20]))
        kw["popup_arrivals"] = str(extra.choice(options("popup_arrivals")))
        kw["mission_time_per_tick"] = float(extra.choice([0.0, 0.5]))
    if extra.random() < 0.35:                           # the asynchronous consensus (async_protocol)
        kw["consensus"] = "acbba"
        low = float(extra.choice([0.0, 0.1]))
        kw["message_ticks"] = [low, low + float(extra.choice([0.0, 0.3]))]
        kw["build_ticks"] = [int(extra.integers(0, 2)), int(extra.integers(2, 4))]
        kw["separation_time"] = int(extra.choice([5, 25]))
        kw["termination"] = str(extra.choice(options("termination")))
        for field in ("acbba_row11", "acbba_row15", "acbba_time_refresh", "acbba_ties", "acbba_equal_bids",
                      "acbba_outbid_time"):
            kw[field] = str(extra.choice(options(field, "empty")))  # row 15 "empty" is not the thesis's (livelock)
        kw["acbba_row20_guard"] = kw["acbba_row28_guard"] = bool(extra.random() < 0.8)
    if rng.random() < 0.4:                              # an imperfect network (network.Network)
        kw["message_loss"] = float(rng.choice([0.0, 0.1, 0.3]))
        kw["max_delay"] = int(rng.integers(0, 3))
        if rng.random() < 0.3:
            kw["loss_model"] = "gilbert_elliott"        # the bursty model (faults.LOSS_MODELS)
        if rng.random() < 0.3:
            kw["dropouts"] = 1
            kw["dropout_rounds"] = [1, 6]
    if faults is not None and faults.random() < 0.15:
        kw["message_loss"], kw["max_delay"] = HEAVY_FAULTS[int(faults.integers(len(HEAVY_FAULTS)))]
    return kw


def run_case(case: tuple[dict[str, Any], str, int]) -> dict[str, Any]:
    """Run one (config, policy, seed); returns the verdict of every check (True, False, or None: not applicable)."""
    kw, name, seed = case
    policy = make_policy(name)
    verdict: dict[str, Any] = {"case": case}
    first = _episode(kw, policy, seed, verdict)
    second = _episode(kw, make_policy(name), seed, None)
    verdict["determinism"] = first == second
    if verdict["converged"] is False and kw.get("cbba_table") == "thesis" and _converges(
            {**kw, "cbba_table": "canonical"}, name, seed):
        verdict["converged"], verdict["why"] = None, THESIS_TABLE
    return verdict


def _converges(kw: dict[str, Any], name: str, seed: int) -> bool:
    """Whether the episode converges (the same config, policy and seed)."""
    policy = make_policy(name)
    env = TaskAllocEnv(**{**kw, **policy.env_overrides}, reward_scale=10.0, invalid_action="raise")
    obs, infos = env.reset(seed=seed)
    policy.start(env, seed)
    while env.agents:
        obs, _, _, _, infos = env.step(policy.act({a: obs[a] for a in env.agents}, infos))
    return env.protocol.converged


def _episode(kw: dict[str, Any], policy: Any, seed: int, verdict: dict[str, Any] | None) -> str:
    env = TaskAllocEnv(**{**kw, **policy.env_overrides}, reward_scale=10.0, invalid_action="raise")
    digest = hashlib.sha256()
    obs, infos = env.reset(seed=seed)
    last_lost = _record_losses(env)
    policy.start(env, seed)
    space = env.observation_space(env.possible_agents[0])
    spaces_ok, total = True, 0.0
    while env.agents:
        for o in obs.values():
            mask = o["action_mask"]
            binary = set(np.unique(mask).tolist()) <= {0, 1}
            spaces_ok &= space.contains(o) and mask.dtype == np.int8 and bool(mask[0]) and binary
            digest.update(o["observation"].tobytes() + mask.tobytes())
        actions = policy.act({a: obs[a] for a in env.agents}, infos)
        spaces_ok &= all(obs[a]["action_mask"][act] == 1 for a, act in actions.items())
        obs, rewards, _, _, infos = env.step(actions)
        total += sum(rewards.values()) / max(1, len(rewards))
        digest.update(json.dumps([rewards, infos], sort_keys=True, default=str).encode())
    if verdict is not None:
        allocation = env.evaluate()
        protocol = env.protocol
        live = protocol.alive
        connected = bool((protocol.live_graph.component[live] == np.flatnonzero(live)[0]).all())
        complete = bool(protocol.graph.adjacency.sum() == len(live) * (len(live) - 1))
        # the documented livelocks (docs/decisions.md "livelock"): row 15's loop on networks that are not fully
        # connected, and a stale bid re-timed by the outbid bump (acbba_outbid_time = bump) on any network
        documented = not complete or env.config.acbba_outbid_time == "bump"
        livelock = env.config.asynchronous and documented and protocol.livelocked
        verdict.update({"spaces": spaces_ok, "return": abs(total * env.reward_scale - allocation.score) < 1e-6,
                        "converged": allocation.converged})
        if not allocation.converged and _lost_messages_explain(env, last_lost):
            verdict["converged"], verdict["why"] = None, f"lost messages: {protocol.unresolved}"
        elif livelock:
            verdict["converged"], verdict["why"] = None, "ACBBA livelock (docs/decisions.md \"livelock\")"
        at_rest = allocation.globally_converged and connected       # converged implies agreement (Protocol._decide)
        verdict["agreement"] = allocation.agreement if at_rest else None
        verdict["conflict-free"] = not allocation.conflicts if at_rest else None
        verdict["valid groups"] = _valid_groups(env, allocation)
    return digest.hexdigest()


def _record_losses(env: TaskAllocEnv) -> np.ndarray:
    """(N, N) bool, filled as the episode runs: whether the last message on each link (sender, receiver) was lost.
    Wraps the loss model's draw, so the episode is unchanged."""
    loss = env.protocol.network.loss
    n = env.scenario.n_agents
    last = np.zeros((n, n), dtype=bool)
    draw = loss.lost

    def lost(sender: np.ndarray, receiver: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        out = draw(sender, receiver, rng)
        last[sender, receiver] = out
        return out

    loss.lost = lost
    return last


def _lost_messages_explain(env: TaskAllocEnv, last_lost: np.ndarray) -> bool:
    """A non-converged episode under message loss that says why (``Protocol.unresolved``): synchronous agents still
    waiting for a neighbour's message sent after the last change, or tables still changing at the round bound;
    under ``acbba``, which never resends, two agents disagreeing after the last message between them was lost
    (docs/decisions.md "lost messages")."""
    protocol = env.protocol
    if protocol.unresolved is None or protocol.network.perfect:
        return False
    return not env.config.asynchronous or _lost_disagreement(protocol, last_lost)


def _lost_disagreement(protocol: Any, last_lost: np.ndarray) -> bool:
    """Two live agents hold different tables and the last message from one of them to the other was lost."""
    groups = protocol.knowledge.groups
    live = np.flatnonzero(protocol.alive)
    return any((last_lost[i, k] or last_lost[k, i]) and not groups.same_table(i, k)
               for i in live for k in live if i < k)


def _valid_groups(env: TaskAllocEnv, allocation: Any) -> bool:
    """Valid tasks have L_j members covering te_j (a conflict under ``first_L_paid`` pays its first L_j starters,
    whose equipment ``team_score`` checked) and valid prerequisites."""
    s = env.scenario
    valid = set(allocation.valid_tasks)
    for j in valid:
        members = allocation.members[j]
        if j in allocation.conflicts:
            if env.config.conflict_policy != "first_L_paid" or len(members) <= s.task_agents[j]:
                return False
            continue
        if len(members) != s.task_agents[j]:
            return False
        if np.any(s.agent_equipment[list(members)].sum(axis=0) < s.task_equipment[j]):
            return False
        if any(p not in valid for p in np.flatnonzero(s.task_prereqs[j])):
            return False
    return True


def cases(episodes: int, seed: int) -> list[tuple[dict[str, Any], str, int]]:
    rng, extra, faults = np.random.default_rng(seed), np.random.default_rng([seed, 2]), np.random.default_rng([seed, 3])
    out = []
    for _ in range(episodes):
        kw = draw_config(rng, extra, faults)
        single = kw.get("task_mix") is None and max(np.atleast_1d(kw["agents_per_task"])) == 1
        name = str(rng.choice((*POLICIES, "cbba") if single else POLICIES))
        if single and extra.random() < 0.2:
            name = "acbba"
        out.append((kw, name, int(rng.integers(2**31))))
    return out


def fuzz(episodes: int, seed: int, jobs: int = 1) -> tuple[Counter, list[dict[str, Any]]]:
    """Run the fuzz; returns per-check counts (``check: passed`` / ``check: failed``) and the failing verdicts."""
    todo = cases(episodes, seed)
    verdicts = list(parallel_map(run_case, todo, jobs))
    counts: Counter = Counter()
    failures = []
    for v in verdicts:
        if v.get("why"):
            counts[f"not converged: {v['why']}"] += 1
        failed = False
        for check in CHECKS:
            if v[check] is None:
                counts[f"{check}: not applicable"] += 1
            elif v[check]:
                counts[f"{check}: passed"] += 1
            else:
                counts[f"{check}: failed"] += 1
                failed = True
        if failed:
            failures.append(v)
    return counts, failures


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc fuzz", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=300, help="random episodes to run (default 300)")
    parser.add_argument("--seed", type=seed_argument, default=0, help="seed of the draw of configs, policies and seeds")
    parser.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    args = parser.parse_args(argv)
    counts, failures = fuzz(args.episodes, args.seed, args.jobs)
    print(f"{args.episodes} episodes (seed {args.seed}):")
    for check in CHECKS:
        parts = [f"{counts[f'{check}: {k}']} {k}" for k in ("passed", "failed", "not applicable")
                 if counts[f"{check}: {k}"]]
        print(f"  {check:<14} {', '.join(parts)}")
    for key in sorted(k for k in counts if k.startswith("not converged: ")):
        print(f"  {counts[key]} {key}")
    for v in failures[:10]:
        kw, name, seed = v["case"]
        bad = [c for c in CHECKS if v[c] is False]
        print(f"FAILED {bad}: policy {name}, seed {seed}, config {json.dumps(kw)}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
