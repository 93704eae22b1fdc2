"""The synchronous step of K instances at once, compiled over the instance axis (the batched env's ``arrays`` engine).

Every instance's state lives in (K, …) arrays (the group tables, timestamps, bundles and paths, the path table and
the bid view, counters); each phase of a step is one call that loops over the instances and, inside, runs the same
rules as the single env through the kernels it already uses (``merge.exchange_all``, ``bids.bid_rows``,
``plan.retime_rows``, ``score.paid_groups``, ``observe.step_features``, ``masks.fill_masks``, ``table.set_member``):

* ``apply_actions``: the joint actions in agent order (``engine.StepEngine.apply``, ``Protocol.bid``,
  ``Protocol.quit``, ``Protocol.release``);
* ``end_rounds``: Phase 2 of the instances whose round ends (``Protocol.end_round`` on perfect links or under
  independent loss, whose draws the caller makes from each instance's own generator);
* ``score_all``: the changed paths re-timed (``ScoringModel.refresh``), the team score (``scoring.team_score``),
  the reward and the episode flags (``TaskAllocEnv._advance``);
* ``observe_all``: the bid view, the observations and the action masks (``TaskAllocEnv._rows``).

Sums follow numpy's pairwise order (``pairwise_sum``), so every float is bit-identical to the single env's
(``tests/test_vector.py``). The references are the Python classes named above. These phases embed the kernels they
call; the cache folder is keyed on every kernel file (``kernels.cache.sources_digest``), so a change to any of them
recompiles the phases.
"""

from __future__ import annotations

import numpy as np

from taskalloc_env.kernels import jit
from taskalloc_env.kernels.bids import bid_rows
from taskalloc_env.kernels.masks import fill_masks
from taskalloc_env.kernels.merge import exchange_all
from taskalloc_env.kernels.observe import step_features
from taskalloc_env.kernels.plan import retime_rows
from taskalloc_env.kernels.quits import quittable, releasable
from taskalloc_env.kernels.score import paid_groups
from taskalloc_env.kernels.table import joined_members, set_member

NONE = -1
NO_TIMER = np.iinfo(np.int64).max          # ``protocol.NO_TIMER``: the quit conditions without the timer
# columns of the (K, C) integer state
ROUND, STEPS, STABLE, CONVERGED, UNRESOLVED, BIDS, MESSAGES, INFORMATIVE, DATA_ITEMS, SENT, LOST, ITEMS_SENT, \
    MAX_AGENT, CONFLICTING, TO_AGREEMENT, MESSAGES_TO_AGREEMENT, SILENT, VALID, CONFLICTS, ENDS_ROUND, \
    TERMINATED, TRUNCATED, INVALID, QUITS, QUITS_SEEN, RELEASES = range(26)
INT_STATE = 26
# ``Protocol.unresolved`` as a code: none, not settled, disagreement, round bound (``UNRESOLVED_TEXT`` in vector)
NOT_SETTLED, DISAGREE, ROUND_BOUND = 1, 2, 3
# columns of the (K, C) float state
SCORE, LAST_SCORE, REWARD, SCALE, LAM, GAMMA, UNIT = range(7)
FLOAT_STATE = 7
# columns of the (K, C) static integers of an instance
MAX_ROUNDS, DIAMETER, SILENCE_TIMEOUT, MAX_BUNDLE, HAS_PREREQS, EQUIPMENT_ANY, N_LINKS = range(7)
STATIC_INTS = 7


@jit
def pairwise_sum(a: np.ndarray, n: int) -> float:
    """The sum of ``a[:n]`` in numpy's pairwise order (``np.add.reduce`` of float64: eight accumulators up to 128
    items, halves beyond)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    if n <= 128:
        r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
        i = 8
        while i < n - (n % 8):
            r0 += a[i]
            r1 += a[i + 1]
            r2 += a[i + 2]
            r3 += a[i + 3]
            r4 += a[i + 4]
            r5 += a[i + 5]
            r6 += a[i + 6]
            r7 += a[i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[i]
            i += 1
        return res
    half = n // 2
    half -= half % 8
    return pairwise_sum(a[:half], half) + pairwise_sum(a[half:], n - half)


@jit
def apply_actions(which: np.ndarray, actions: np.ndarray, every_step: bool, by_bundle: bool, until_joined: bool,
                  leg_cost: bool, arrival_time: bool, frozen: bool, istate: np.ndarray, fstate: np.ndarray,
                  passed: np.ndarray, dirty: np.ndarray, stale: np.ndarray, bundles: np.ndarray, bundle_len: np.ndarray,
                  paths: np.ndarray, path_len: np.ndarray, assigned_at: np.ndarray, quit: np.ndarray,
                  quit_blocked: np.ndarray, pending: np.ndarray, count: np.ndarray, ids: np.ndarray,
                  values: np.ndarray, own: np.ndarray, capacity: np.ndarray, view_bid: np.ndarray, slot: np.ndarray,
                  displaced: np.ndarray, speed: np.ndarray, dist_at: np.ndarray, dist_tt: np.ndarray,
                  earliest: np.ndarray, deadline: np.ndarray, doable: np.ndarray, duration: np.ndarray,
                  task_start: np.ndarray, pay: np.ndarray, gain: np.ndarray, pt_members: np.ndarray,
                  pt_reward: np.ndarray, pt_start: np.ndarray, pt_cost: np.ndarray, bid_round: np.ndarray,
                  released: np.ndarray) -> None:
    """``StepEngine.apply`` of each instance in ``which``: its (N,) valid actions (pass, bid j + 1, quit M + 1 + j,
    release 2M + 1 + j) in agent order against the view taken before them (``Protocol.bid``, ``Protocol.quit``,
    ``Protocol.release``); marks ``ENDS_ROUND`` where the round ends. A quit or a release after a change in the same
    step re-times the changed paths first, as ``Protocol.quit_options`` and ``Protocol.release_options`` do through
    ``Protocol.view``."""
    n_inst, n = actions.shape
    m = count.shape[2]
    gone = np.zeros(m, dtype=np.bool_)
    for k in range(n_inst):
        istate[k, ENDS_ROUND] = False
        if not which[k]:
            continue
        now = istate[k, ROUND]
        for i in range(n):
            action = actions[k, i]
            if action == 0:
                passed[k, i] = True
                continue
            if action > m:                                   # a quit or a release
                quitting = action <= 2 * m                   # actions.encode_quit(j, m) = 1 + m + j
                j = action - 1 - m if quitting else action - 1 - 2 * m      # actions.encode_release(j, m)
                touched = False
                for a in range(n):
                    touched = touched or dirty[k, a]
                if touched:
                    _refresh_paths(dirty[k], paths[k], path_len[k], speed[k], dist_at[k], dist_tt[k], earliest[k],
                                   deadline[k], doable[k], duration[k], task_start[k], pay[k], fstate[k, LAM],
                                   fstate[k, GAMMA], leg_cost, arrival_time, frozen, gain[k], slot[k],
                                   pt_members[k], pt_reward[k], pt_start[k], pt_cost[k])
                _release(i, j, by_bundle, bundles[k], bundle_len[k], paths[k], path_len[k], ids[k], values[k],
                         count[k], own[k], capacity[k], gone)
                if quitting:
                    quit[k, i, j] = True
                    quit_blocked[k, i, j] = until_joined
                    istate[k, QUITS] += 1
                    pending[k, i, j] = True
                else:
                    released[k, i, j] = True
                    istate[k, RELEASES] += 1
                dirty[k, i] = stale[k, i] = True
                passed[k, i] = False
                continue
            j = action - 1                                   # actions.encode_bid(j) = 1 + j
            value = view_bid[k, i, j]
            bundles[k, i, bundle_len[k, i]] = j              # b_i ⊕_end j
            bundle_len[k, i] += 1
            at = slot[k, i, j]                               # p_i ⊕_slot j
            for r in range(path_len[k, i], at, -1):
                paths[k, i, r] = paths[k, i, r - 1]
            paths[k, i, at] = j
            path_len[k, i] += 1
            if displaced[k, i, j] != NONE:
                set_member(ids[k], values[k], count[k], own[k], capacity[k], i, displaced[k, i, j], j, 0.0)
            set_member(ids[k], values[k], count[k], own[k], capacity[k], i, i, j, value)
            assigned_at[k, i, j] = now
            istate[k, BIDS] += 1
            bid_round[k, i, j] = now
            pending[k, i, j] = False                         # re-bid before anyone saw the quit
            dirty[k, i] = stale[k, i] = True
            passed[k, i] = False
        istate[k, STEPS] += 1
        everyone = True
        for i in range(n):
            everyone = everyone and passed[k, i]
        istate[k, ENDS_ROUND] = every_step or everyone


@jit(inline=True)
def _drop_gone(seq: np.ndarray, length: int, gone: np.ndarray) -> int:
    """Remove the tasks marked ``gone`` from ``seq[:length]`` in place, keeping the order; the new length."""
    kept = 0
    for r in range(length):
        if not gone[seq[r]]:
            seq[kept] = seq[r]
            kept += 1
    return kept


@jit
def _release(i: int, lost: int, by_bundle: bool, bundles: np.ndarray, bundle_len: np.ndarray, paths: np.ndarray,
             path_len: np.ndarray, ids: np.ndarray, values: np.ndarray, count: np.ndarray, own: np.ndarray,
             capacity: np.ndarray, gone: np.ndarray) -> None:
    """``LocalKnowledge.release``: ``lost`` and what follows it in the bundle (or the path) leave both; i's own bids
    on them are zeroed in that order."""
    gone[:] = False
    seq = bundles[i] if by_bundle else paths[i]
    length = bundle_len[i] if by_bundle else path_len[i]
    cut = 0
    while seq[cut] != lost:
        cut += 1
    dropped = seq[cut:length].copy()
    for j in dropped:
        gone[j] = True
    bundle_len[i] = _drop_gone(bundles[i], bundle_len[i], gone)
    path_len[i] = _drop_gone(paths[i], path_len[i], gone)
    for j in dropped:
        set_member(ids, values, count, own, capacity, i, i, j, 0.0)


@jit
def end_rounds(istate: np.ndarray, statics: np.ndarray, perfect: bool, by_bundle: bool, canonical: bool,
               task_quitting: bool, delta: int, reset_on_additions: bool, keep: np.ndarray, assigned_at: np.ndarray,
               quit: np.ndarray, quit_blocked: np.ndarray, pending: np.ndarray, passed: np.ndarray, dirty: np.ndarray,
               stale: np.ndarray, count: np.ndarray, ids: np.ndarray, values: np.ndarray, own: np.ndarray,
               stamps: np.ndarray, known: np.ndarray, bundles: np.ndarray, bundle_len: np.ndarray, paths: np.ndarray,
               path_len: np.ndarray, last_count: np.ndarray, last_ids: np.ndarray, last_values: np.ndarray,
               last_bundles: np.ndarray, last_bundle_len: np.ndarray, last_heard: np.ndarray, sent_by: np.ndarray,
               adjacency: np.ndarray, component: np.ndarray, single: np.ndarray, capacity: np.ndarray,
               restricted: np.ndarray, required: np.ndarray, agent_eq: np.ndarray) -> None:
    """``Protocol.end_round`` of every instance whose ``ENDS_ROUND`` is set: snapshot, send (``keep`` (K, links):
    the links' messages not lost, sender-major), deliver in (receiver, sender) order, merge (``exchange_all``),
    count the quits seen, forget silent agents (lossy links), release outbid tasks, the quit timers and blocks,
    counters, the convergence test; every agent present passes no longer."""
    n_inst, n, m, width = ids.shape
    gone = np.zeros(m, dtype=np.bool_)
    own_before = np.zeros((n, m), dtype=np.bool_)
    items = np.zeros(n, dtype=np.int64)
    kept = np.zeros((n, n), dtype=np.bool_)
    receiver = np.zeros(n * n, dtype=np.int64)
    sender = np.zeros(n * n, dtype=np.int64)
    for k in range(n_inst):
        if not istate[k, ENDS_ROUND]:
            continue
        now = istate[k, ROUND] + 1
        istate[k, ROUND] = now
        for i in range(n):
            for j in range(m):
                own_before[i, j] = own[k, i, j] > 0
            stamps[k, i, i] = now
        snap_count = count[k].copy().reshape((1, n, m))
        snap_ids = ids[k].copy().reshape((1, n, m, width))
        snap_values = values[k].copy().reshape((1, n, m, width))
        snap_stamps = stamps[k].copy().reshape((1, n, n))
        snap_known = known[k].copy().reshape((1, n, n))
        for s in range(n):
            total = 0
            for j in range(m):
                total += count[k, s, j]
            items[s] = 3 * total + n
        # send: every link, sender-major; the kept ones are delivered this round (no delay)
        links, lost, items_sent = 0, 0, 0
        for s in range(n):
            for r in range(n):
                kept[s, r] = False
                if adjacency[k, s, r]:
                    sent_by[k, s] += 1
                    items_sent += items[s]
                    kept[s, r] = perfect or keep[k, links]
                    lost += not kept[s, r]
                    links += 1
        delivered, items_delivered = 0, 0
        for r in range(n):
            for s in range(n):
                if kept[s, r]:
                    receiver[delivered], sender[delivered] = r, s
                    items_delivered += items[s]
                    delivered += 1
        informative = 0
        if delivered:
            informative = exchange_all(count[k], ids[k], values[k], own[k], stamps[k], known[k], snap_count,
                                       snap_ids, snap_values, snap_stamps, snap_known, receiver[:delivered],
                                       sender[:delivered], np.zeros(delivered, dtype=np.int64), float(now),
                                       single[k], capacity[k], restricted[k], required[k], agent_eq[k], canonical)
            for d in range(delivered):
                if last_heard[k, receiver[d], sender[d]] < now:
                    last_heard[k, receiver[d], sender[d]] = now
        for i in range(n):                                   # Protocol._count_seen_quits
            for j in range(m):
                if not pending[k, i, j]:
                    continue
                seen = False
                for h in range(n):
                    listed_before, listed_now = False, False
                    for c in range(snap_count[0, h, j]):
                        listed_before = listed_before or snap_ids[0, h, j, c] == i
                    for c in range(count[k, h, j]):
                        listed_now = listed_now or ids[k, h, j, c] == i
                    seen = seen or (listed_before and not listed_now)
                if seen:
                    pending[k, i, j] = False
                    istate[k, QUITS_SEEN] += 1
        if not perfect:                                      # Protocol._forget_silent
            timeout = statics[k, SILENCE_TIMEOUT]
            listed = np.zeros((n, n), dtype=np.bool_)
            for i in range(n):
                for j in range(m):
                    for c in range(count[k, i, j]):
                        listed[i, ids[k, i, j, c]] = True
            for i in range(n):
                for a in range(n):
                    if a == i or not listed[i, a] or not now - stamps[k, i, a] > timeout:
                        continue
                    for j in range(m):
                        held = False
                        for c in range(count[k, i, j]):
                            held = held or ids[k, i, j, c] == a
                        if held:
                            set_member(ids[k], values[k], count[k], own[k], capacity[k], i, a, j, 0.0)
                    istate[k, SILENT] += 1
        conflicting = 0
        for i in range(n):
            for j in range(m):
                conflicting += own_before[i, j] and own[k, i, j] <= 0
        istate[k, CONFLICTING] += conflicting
        losers = np.zeros(n, dtype=np.bool_)                 # Protocol._release_outbid
        for i in range(n):
            for r in range(bundle_len[k, i]):
                losers[i] = losers[i] or own[k, i, bundles[k, i, r]] <= 0
        for i in range(n):
            if not losers[i]:
                continue
            seq = bundles[k, i] if by_bundle else paths[k, i]
            length = bundle_len[k, i] if by_bundle else path_len[k, i]
            lost_task = -1
            for r in range(length):
                if own[k, i, seq[r]] <= 0:
                    lost_task = seq[r]
                    break
            _release(i, lost_task, by_bundle, bundles[k], bundle_len[k], paths[k], path_len[k], ids[k], values[k],
                     count[k], own[k], capacity[k], gone)
            dirty[k, i] = True
        blocked = False
        for i in range(n):
            for j in range(m):
                blocked = blocked or quit_blocked[k, i, j]
        pending_quit = False
        if task_quitting or blocked:
            joined = joined_members(ids[k], snap_ids[0])
            if task_quitting:                                # Protocol._reset_quit_timers, then _quit_pending
                allowed = quittable(count[k], capacity[k], own[k], quit[k], single[k], assigned_at[k], NO_TIMER)
                for i in range(n):
                    for j in range(m):
                        updated = joined[i, j]
                        if not reset_on_additions:
                            updated = False
                            for c in range(width):
                                updated = updated or ids[k, i, j, c] != snap_ids[0, i, j, c] \
                                    or values[k, i, j, c] != snap_values[0, i, j, c]
                        if updated and allowed[i, j]:
                            assigned_at[k, i, j] = now
                for i in range(n):
                    for j in range(m):
                        pending_quit = pending_quit or (allowed[i, j] and now - 1 - assigned_at[k, i, j] <= delta)
            if blocked:
                for i in range(n):
                    for j in range(m):
                        quit_blocked[k, i, j] = quit_blocked[k, i, j] and not joined[i, j]
        istate[k, MESSAGES] += delivered
        istate[k, INFORMATIVE] += informative
        istate[k, DATA_ITEMS] += items_delivered
        istate[k, SENT] += links
        most = 0
        for s in range(n):
            most = max(most, sent_by[k, s])
        istate[k, MAX_AGENT] = most
        istate[k, LOST] += lost
        istate[k, ITEMS_SENT] += items_sent
        # changed: the groups or the bundles differ from the last round's (then kept for the next)
        changed = False
        for i in range(n):
            if bundle_len[k, i] != last_bundle_len[k, i]:
                changed = True
            else:
                for r in range(bundle_len[k, i]):
                    changed = changed or bundles[k, i, r] != last_bundles[k, i, r]
            last_bundle_len[k, i] = bundle_len[k, i]
            for r in range(m):
                last_bundles[k, i, r] = bundles[k, i, r]
            for j in range(m):
                changed = changed or count[k, i, j] != last_count[k, i, j]
                last_count[k, i, j] = count[k, i, j]
                for c in range(width):
                    changed = changed or ids[k, i, j, c] != last_ids[k, i, j, c] \
                        or values[k, i, j, c] != last_values[k, i, j, c]
                    last_ids[k, i, j, c] = ids[k, i, j, c]
                    last_values[k, i, j, c] = values[k, i, j, c]
        if changed:
            istate[k, TO_AGREEMENT] = now
            istate[k, MESSAGES_TO_AGREEMENT] = istate[k, MESSAGES]
        istate[k, STABLE] = 0 if changed or pending_quit else istate[k, STABLE] + 1
        stable = istate[k, STABLE] >= statics[k, DIAMETER] + 1
        settled = True
        if stable and not perfect:                           # Protocol._settled: heard after the last change
            last_change = istate[k, TO_AGREEMENT]
            for i in range(n):
                for a in range(n):
                    settled = settled and (last_heard[k, i, a] > last_change or not adjacency[k, i, a])
        if stable and not settled:
            istate[k, CONVERGED] = False
            istate[k, UNRESOLVED] = NOT_SETTLED
        else:
            agreed = stable
            if stable:                                       # Protocol.agreement
                for i in range(n):
                    h = component[k, i]
                    for j in range(m):
                        agreed = agreed and count[k, i, j] == count[k, h, j]
                        for c in range(width):
                            agreed = agreed and ids[k, i, j, c] == ids[k, h, j, c] \
                                and values[k, i, j, c] == values[k, h, j, c]
            istate[k, CONVERGED] = agreed
            istate[k, UNRESOLVED] = DISAGREE if stable and not agreed else 0
        if not istate[k, CONVERGED] and istate[k, UNRESOLVED] == 0 and now >= statics[k, MAX_ROUNDS] \
                and not perfect:
            istate[k, UNRESOLVED] = ROUND_BOUND
        for i in range(n):
            passed[k, i] = False
            stale[k, i] = True                               # Protocol._touch(): the whole view


@jit
def _refresh_paths(dirty: np.ndarray, paths: np.ndarray, path_len: np.ndarray, speed: np.ndarray,
                   dist_at: np.ndarray, dist_tt: np.ndarray, earliest: np.ndarray, deadline: np.ndarray,
                   doable: np.ndarray, duration: np.ndarray, task_start: np.ndarray, pay: np.ndarray, lam: float,
                   gamma: float, leg_cost: bool, arrival_time: bool, frozen: bool, gain: np.ndarray,
                   slot: np.ndarray, pt_members: np.ndarray, pt_reward: np.ndarray, pt_start: np.ndarray,
                   pt_cost: np.ndarray) -> None:
    """``Protocol._refresh_paths``: the changed agents' paths re-timed in one ``retime_rows`` call, their travel
    costs summed over the call's padded width (as numpy sums them)."""
    n = dirty.size
    agents_count, total = 0, 0
    for i in range(n):
        if dirty[i]:
            agents_count += 1
            total += path_len[i]
    if agents_count == 0:
        return
    agents = np.empty(agents_count, dtype=np.int64)
    lengths = np.empty(agents_count, dtype=np.int64)
    flat = np.empty(total, dtype=np.int64)
    a, at = 0, 0
    for i in range(n):
        if dirty[i]:
            agents[a] = i
            lengths[a] = path_len[i]
            for r in range(path_len[i]):
                flat[at] = paths[i, r]
                at += 1
            a += 1
            dirty[i] = False
    cost = retime_rows(flat, lengths, agents, speed, dist_at, dist_tt, earliest, deadline, doable, duration,
                       task_start, pay, lam, gamma, leg_cost, arrival_time, frozen, gain, slot, pt_members,
                       pt_reward, pt_start)
    for a in range(agents_count):
        pt_cost[agents[a]] = pairwise_sum(cost[a], cost.shape[1])


@jit
def score_all(which: np.ndarray, stepped: np.ndarray, max_cycles: int, leg_cost: bool, arrival_time: bool,
              frozen: bool, first_l_paid: bool, istate: np.ndarray, fstate: np.ndarray, statics: np.ndarray,
              dirty: np.ndarray, paths: np.ndarray, path_len: np.ndarray, speed: np.ndarray, dist_at: np.ndarray,
              dist_tt: np.ndarray, earliest: np.ndarray, deadline: np.ndarray, doable: np.ndarray,
              duration: np.ndarray, task_start: np.ndarray, pay: np.ndarray, gain: np.ndarray, slot: np.ndarray,
              pt_members: np.ndarray, pt_reward: np.ndarray, pt_start: np.ndarray, pt_cost: np.ndarray,
              capacity: np.ndarray, required: np.ndarray, agent_eq: np.ndarray, prereqs: np.ndarray) -> None:
    """``Protocol.score`` of each instance in ``which`` (the changed paths re-timed first); where ``stepped``, also
    ``TaskAllocEnv._advance``'s reward and flags (``StepEngine.ended``)."""
    n_inst, n, m = gain.shape
    paid = np.zeros((n, m), dtype=np.bool_)
    valid = np.zeros(m, dtype=np.bool_)
    conflicts = np.zeros(m, dtype=np.bool_)
    row = np.zeros(m)
    scores = np.zeros(n)
    for k in range(n_inst):
        if not which[k]:
            continue
        _refresh_paths(dirty[k], paths[k], path_len[k], speed[k], dist_at[k], dist_tt[k], earliest[k], deadline[k],
                       doable[k], duration[k], task_start[k], pay[k], fstate[k, LAM], fstate[k, GAMMA], leg_cost,
                       arrival_time, frozen, gain[k], slot[k], pt_members[k], pt_reward[k], pt_start[k], pt_cost[k])
        paid_groups(pt_members[k], pt_start[k], capacity[k], required[k], agent_eq[k], statics[k, EQUIPMENT_ANY] > 0,
                    prereqs[k], statics[k, HAS_PREREQS] > 0, first_l_paid, paid, valid, conflicts)
        for i in range(n):
            for j in range(m):
                row[j] = pt_reward[k, i, j] if paid[i, j] else 0.0
            scores[i] = pairwise_sum(row, m) - pt_cost[k, i]
        score = pairwise_sum(scores, n)
        fstate[k, SCORE] = score
        n_valid, n_conflicts = 0, 0
        for j in range(m):
            n_valid += valid[j]
            n_conflicts += conflicts[j]
        istate[k, VALID] = n_valid
        istate[k, CONFLICTS] = n_conflicts
        if not stepped[k]:
            continue
        fstate[k, REWARD] = (score - fstate[k, LAST_SCORE]) / fstate[k, SCALE]
        fstate[k, LAST_SCORE] = score
        terminated = istate[k, CONVERGED] > 0
        istate[k, TERMINATED] = terminated
        istate[k, TRUNCATED] = not terminated and (istate[k, STEPS] >= max_cycles
                                                   or istate[k, ROUND] >= statics[k, MAX_ROUNDS])


@jit
def observe_all(which: np.ndarray, prereq_mode: int, warping: bool, strict: bool, silence_column: int,
                task_quitting: bool, delta: int, guard: int, columns: np.ndarray, istate: np.ndarray,
                fstate: np.ndarray, statics: np.ndarray, passed: np.ndarray, stale: np.ndarray, count: np.ndarray,
                ids: np.ndarray, values: np.ndarray, own: np.ndarray, stamps: np.ndarray, assigned_at: np.ndarray,
                quit: np.ndarray, quit_blocked: np.ndarray, bundle_len: np.ndarray, single: np.ndarray,
                gain: np.ndarray, equipment_match: np.ndarray, fillable: np.ndarray, capacity: np.ndarray,
                restricted: np.ndarray, required: np.ndarray, agent_eq: np.ndarray, prereqs: np.ndarray,
                view_bid: np.ndarray, outbid: np.ndarray, eligible: np.ndarray, prereqs_met: np.ndarray,
                members: np.ndarray, group_total: np.ndarray, lowest_bid: np.ndarray, displaced: np.ndarray,
                displaced_bid: np.ndarray, in_bundle: np.ndarray, bid_round: np.ndarray, released: np.ndarray,
                tasks: np.ndarray, own_features: np.ndarray, masks: np.ndarray) -> None:
    """``TaskAllocEnv._rows`` of each instance in ``which``: the stale rows of its bid view (``bids.bid_rows``), the
    per-step observation columns (``observe.step_features``; ``member_silence`` at ``silence_column`` ≥ 0, as
    ``ObservationBuilder._finish`` writes it) and the action masks (``masks.fill_masks``; with release columns,
    ``masks`` (K, N, 1 + 3M), the releases ``quits.releasable`` allows under ``guard``, a ``quits.RELEASE_GUARDS``
    code). ``tasks`` (K, N, M, F) and ``own_features`` (K, N, ≥ 7) are views into the observations in their dtype:
    each value is computed in float64 and rounded once when stored, as ``ObservationBuilder`` rounds its float64
    buffer."""
    n_inst, n, m = gain.shape
    rows = np.zeros(n, dtype=np.int64)
    sizes = np.zeros(n, dtype=np.int64)
    sizes_float = np.zeros(n)
    can_bid = np.zeros((n, m), dtype=np.bool_)
    no_quits = np.zeros((n, m), dtype=np.bool_)
    everyone_known = np.ones((n, m), dtype=np.bool_)
    can_release = np.zeros((n, m), dtype=np.bool_)
    releasing = masks.shape[2] > 1 + 2 * m
    for k in range(n_inst):
        if not which[k]:
            continue
        n_rows = 0
        for i in range(n):
            sizes[i] = bundle_len[k, i]
            sizes_float[i] = bundle_len[k, i]
            if stale[k, i]:
                rows[n_rows] = i
                n_rows += 1
                stale[k, i] = False
        bid_rows(rows[:n_rows], count[k], ids[k], values[k], single[k], gain[k], quit_blocked[k], sizes,
                 equipment_match[k], fillable[k], everyone_known, capacity[k], restricted[k], required[k],
                 agent_eq[k], prereqs[k], prereq_mode, statics[k, MAX_BUNDLE], warping, strict, view_bid[k],
                 outbid[k], eligible[k], prereqs_met[k], members[k], group_total[k], lowest_bid[k], displaced[k],
                 displaced_bid[k], in_bundle[k])
        for i in range(n):
            for j in range(m):
                can_bid[i, j] = eligible[k, i, j] and outbid[k, i, j] and gain[k, i, j] > 0
        now = istate[k, ROUND]
        can_quit = no_quits                                  # Protocol.quit_options
        if task_quitting:
            can_quit = quittable(members[k], capacity[k], own[k], quit[k], single[k], assigned_at[k], now - delta)
        step_features(tasks[k], columns, fstate[k, UNIT], gain[k], can_bid, outbid[k], members[k], capacity[k],
                      lowest_bid[k], group_total[k], displaced_bid[k], in_bundle[k], own[k], quit[k], can_quit, now,
                      assigned_at[k], prereqs_met[k], own_features[k], sizes_float,
                      min(now / statics[k, MAX_ROUNDS], 1.0), passed[k])
        if silence_column >= 0:
            timeout = statics[k, SILENCE_TIMEOUT]
            for i in range(n):
                for j in range(m):
                    quiet = 0.0
                    for c in range(ids.shape[3]):
                        a = ids[k, i, j, c]
                        value = 0.0
                        if a >= 0 and a != i:
                            value = (now - stamps[k, i, a]) / timeout
                        quiet = max(quiet, value) if c > 0 else value
                    tasks[k, i, j, silence_column] = min(quiet, 1.0)
        if releasing:                                        # Protocol.release_options
            releasable(in_bundle[k], bid_round[k], released[k], now, guard, can_release)
        fill_masks(can_bid, can_quit, can_release, passed[k], masks[k])
