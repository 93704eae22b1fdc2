"""Johnson's asynchronous replan (Johnson §4.2) on ACBBA, with a scripted trigger of ours: an agent releases bundle
tasks when a pop-up task it can reach would enter its rebuilt bundle ahead of them, then rebuilds greedily.

Johnson §4.2 (extraction l. 947–967): "tasks in an agents' bundle can only be dropped if another agent outbids him
for a task, or if a replan is called"; "an individual agent can decide to drop its entire bundle and rebuild it from
scratch, so that it can re-optimize for these new local changes in situational awareness", "especially attractive
when the change to a decentralized agent's situational awareness will change that agent's bundle severely, but keep
all the other agents' bundles unchanged. This is a typical scenario that might happen if a pop-up task is discovered
near a remote agent". Johnson names the event but gives no trigger; the trigger below is ours.

**Trigger (ours).** Agent i evaluates each pop-up task j once, at its first step with a ready builder after j's
release (the release wakes every builder, docs/algorithm.md §9.7). Let s = b_i under ``release_order = bundle`` (p_i
under ``path``), and for each position k of s let the kept path p_i^{<k} be the tasks of s before s_k in path order
(what a release of s_k leaves, ``LocalKnowledge.release``). The replan fires at the first k where all of these hold:

1. *within reach*: j is released, i's equipment matches, its prerequisites are met in i's table, some team can
   complete it, i is not blocked from it, and its marginal gain on the kept path c_ij(p_i^{<k}) ((3.11); Johnson
   (4.1)–(4.2)) is positive, i.e. i can arrive before the window closes ((3.7)); condition 3 implies the latter,
   since no gain is negative;
2. *i would win it*: the bid i would share, c_ij(p_i^{<k}) (warped below the kept bids with ``bid_warping``), beats
   the winning bid i knows for j, h_ij (Johnson (4.3), ``outbid_ties``);
3. *it would enter the rebuilt bundle first*: c_ij(p_i^{<k}) > c_it(p_i^{<k}) for every task t = s_k, s_{k+1}, …
   it would displace. The greedy rebuild compares these values (Johnson (4.3): the largest c_ij h_ij; the displaced
   tasks are free again after the release), so this is the test that the pop-up is picked before any of them; for
   s_k under ``release_order = bundle`` c_it(p_i^{<k}) is exactly the bid s_k was given when it entered the bundle,
   before warping (the bundle then was s_1 … s_{k−1}, and the scenario is static). Ties go to the displaced task, as
   the greedy's lowest-id rule gives them to the earlier (lower-id) task. Tasks outside the bundle are not compared:
   one of them can still come first (the study counts how often).

Several new pop-ups are evaluated together: the first k any of them passes decides.

**Release (``scope``).** ``scope = "bundle"`` (default, Johnson's "drop its entire bundle and rebuild it from
scratch") releases s_1, so the whole bundle goes; ``scope = "suffix"`` (ours) releases s_k and what follows it: the
tasks before s_k are the ones the greedy rebuild would pick again ahead of the pop-up (condition 3 failed for every
earlier k), so keeping them saves their withdrawals and the messages those cause. Either way the release is the
release action (``release_actions``, docs/algorithm.md §10.1): the released tasks go out as empty bids with the current
time (§9.5), and the agent then bids greedily as ACBBA does (``CBGAPolicy.choose``, one bid per tick) and passes
when none is left, which rebroadcasts.

Like PI (``policies/pi.py``) the trigger reads the agent's own row of ``protocol.knowledge`` (its bundle, path, own
bids and its record of j) and the scenario's tasks through the environment's scoring model; nothing of another
agent's table. ``replans`` records each replan for the studies.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from taskalloc.policies.scripted import ACBBAPolicy
from taskalloc_env.actions import encode_release
from taskalloc_env.cbba_table import NONE, outbids

SCOPES = ("bundle", "suffix")


@dataclasses.dataclass(frozen=True)
class Replan:
    """One replan: who, at which tick, for which pop-up, which bundle task it released, and the trigger's values."""

    agent: int
    tick: int
    popup: int
    released: int               # the task the release action names (s_1 with scope "bundle", s_k with "suffix")
    precedes: int               # s_k, the first task the pop-up would precede
    dropped: tuple[int, ...]    # every task the release removes: ``released`` and what follows it
    gain: float                 # c_ij(p_i^{<k}) of the pop-up
    rival: float                # max c_it(p_i^{<k}) over the displaced tasks


class AsyncReplanPolicy(ACBBAPolicy):
    """ACBBA whose agents replan (Johnson §4.2) when a released pop-up task would enter their rebuilt bundle first
    (the trigger is ours); ``scope`` says what goes: the whole bundle (Johnson) or the tasks from the first one the
    pop-up would precede (ours)."""

    def __init__(self, scope: str = "bundle") -> None:
        super().__init__()
        if scope not in SCOPES:
            raise ValueError(f"scope {scope!r} is not one of {SCOPES}")
        self.scope = scope
        self.name = "ACBBA+replan" if scope == "bundle" else "ACBBA+replan (suffix)"
        self.evaluated = np.zeros((0, 0), dtype=bool)
        self.replans: list[Replan] = []

    @property
    def env_overrides(self) -> dict[str, Any]:
        return {"consensus": "acbba", "release_actions": True}

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        protocol = self.env.protocol
        self.evaluated = np.broadcast_to(protocol.release_tick <= 0, (self.env.config.n_agents, self.n_tasks)).copy()
        self.replans = []

    def act(self, observations: Mapping[str, Mapping[str, np.ndarray]],
            infos: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, int]:
        protocol = self.env.protocol
        actions, rest = {}, {}
        for name, observation in observations.items():
            agent = self.env.agent_index[name]
            replan = None
            if protocol.ready[agent]:
                new = np.flatnonzero(protocol.released & ~self.evaluated[agent])
                self.evaluated[agent, new] = True
                replan = self.trigger(agent, new) if new.size else None
            if replan is None:
                rest[name] = observation
                continue
            self.replans.append(replan)
            actions[name] = int(encode_release(replan.released, self.n_tasks))
        return {**actions, **super().act(rest, infos)}

    def trigger(self, agent: int, popups: np.ndarray) -> Replan | None:
        """The replan ``agent`` makes for the newly released ``popups`` (conditions 1–3 of the module docstring at
        the first position k where any pop-up passes), or None."""
        protocol = self.env.protocol
        cfg = protocol.cfg
        kn = protocol.knowledge
        view = protocol.view()
        sequence = kn.bundles[agent] if cfg.release_order == "bundle" else kn.paths[agent]
        own = kn.own_bids()[agent]
        reach = (protocol.released & view.equipment_match[agent] & view.prereqs_met[agent] & protocol.fillable
                 & ~kn.quit_blocked[agent] & ~view.in_bundle[agent] & kn.single)
        popups = popups[reach[popups]]
        if not popups.size:
            return None
        winner, held = kn.winner[agent, popups], kn.winning_bid()[agent, popups]
        for k, cut in enumerate(sequence):
            kept = sequence[:k]
            gain, _ = protocol.model.insertion_gains(agent, [t for t in kn.paths[agent] if t in kept])
            bid = np.minimum(gain[popups], own[kept].min()) if cfg.bid_warping and kept else gain[popups]
            wins = (winner == NONE) | (bid > held if cfg.outbid_ties == "strict"
                                       else outbids(bid, agent, held, winner))
            rival = float(gain[sequence[k:]].max())
            passing = wins & (gain[popups] > rival)         # every gain is ≥ 0: this implies c_ij > 0
            if passing.any():
                best = int(np.argmax(np.where(passing, gain[popups], -np.inf)))
                dropped = tuple(sequence if self.scope == "bundle" else sequence[k:])
                return Replan(agent, protocol.round, int(popups[best]), dropped[0], cut, dropped,
                              float(gain[popups[best]]), rival)
        return None
