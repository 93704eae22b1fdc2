"""One step of the bundle phase for every agent: the action masks and the application of a joint action.

The environment (``TaskAllocEnv.step``) and the direct solver (``taskalloc.policies.fast.solve``) both drive a
protocol through a ``StepEngine``, so the step logic exists once; a batched environment holds one engine per
instance. A step applies the agents' decisions in agent order against the bid view taken before the first of them
(a bid changes only its bidder's row), then ends the round when it is due: under ``sync`` once every agent has
passed, under ``every_step`` after every step (thesis §3.2.2–3.2.3: the bundle phase, then the consensus phase),
under ``acbba`` every step is one tick (Johnson §4.1, ``async_protocol``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from taskalloc_env import kernels
from taskalloc_env.actions import PASS, ActionKind, bid_columns, decode, n_actions, quit_columns, release_columns
from taskalloc_env.kernels.masks import fill_masks
from taskalloc_env.protocol import Protocol

_PASS, _BID, _QUIT = ActionKind.PASS, ActionKind.BID, ActionKind.QUIT   # looked up once: ``apply``'s loop compares


def action_masks(can_bid: np.ndarray, can_quit: np.ndarray, passed: np.ndarray,
                 can_release: np.ndarray | None = None) -> np.ndarray:
    """(N, 1 + 2M) int8: pass always; the valid bids and the allowed quits of every agent that has not ``passed``
    (a passed agent may only pass until the round ends; under ``acbba``, until its builder is ready); with
    ``can_release`` (``release_actions``), (N, 1 + 3M) with the allowed releases too. Compiled
    (``kernels.masks.fill_masks``) when numba is there, else ``action_masks_reference``."""
    if not kernels.COMPILED:
        return action_masks_reference(can_bid, can_quit, passed, can_release)
    n, m = can_bid.shape
    mask = np.empty((n, n_actions(m, can_release is not None)), dtype=np.int8)
    fill_masks(can_bid, can_quit, can_quit if can_release is None else can_release, passed, mask)
    return mask


def action_masks_reference(can_bid: np.ndarray, can_quit: np.ndarray, passed: np.ndarray,
                           can_release: np.ndarray | None = None) -> np.ndarray:
    """``action_masks`` in numpy (the reference of ``kernels.masks.fill_masks``)."""
    n, m = can_bid.shape
    mask = np.empty((n, n_actions(m, can_release is not None)), dtype=np.int8)
    mask[:, PASS] = 1
    acting = ~passed[:, None]
    np.logical_and(can_bid, acting, out=mask[:, bid_columns(m)])
    np.logical_and(can_quit, acting, out=mask[:, quit_columns(m)])
    if can_release is not None:
        np.logical_and(can_release, acting, out=mask[:, release_columns(m)])
    return mask


class StepEngine:
    """A protocol, the agents that may only pass, and the steps taken: masks now, and one joint action at a time."""

    def __init__(self, protocol: Protocol) -> None:
        self.protocol = protocol
        self.asynchronous = protocol.cfg.asynchronous
        self.every_step = protocol.cfg.consensus == "every_step"
        self.steps = 0
        self.passed = self.waiting()
        m = protocol.scenario.n_tasks
        self.release = protocol.cfg.release_actions
        self._decoded = [decode(action, m) for action in range(n_actions(m, self.release))]   # a lookup beats a call

    def waiting(self) -> np.ndarray:
        """(N,) agents that may only pass: at the start of a synchronous round only those not present (late joiners
        before their round); under ``acbba`` every agent whose bundle builder is not ready this tick."""
        if self.asynchronous:
            return ~self.protocol.ready
        return ~self.protocol.alive

    def masks(self) -> np.ndarray:
        """(N, 1 + 2M) int8 action masks of every agent now (``action_masks``); (N, 1 + 3M) with ``release_actions``."""
        protocol = self.protocol
        releases = protocol.release_options() if self.release else None
        return action_masks(protocol.view().can_bid, protocol.quit_options(), self.passed, releases)

    def acting(self) -> np.ndarray:
        """The agents that may do more than pass, in agent order."""
        return np.flatnonzero(~self.passed)

    def apply(self, decisions: Iterable[tuple[int, int]]) -> None:
        """Apply (agent, action) pairs, each a valid action of its agent's mask, in the order given (agent order),
        then end the round (tick) if it is due."""
        protocol = self.protocol
        view = protocol.view()
        decoded = self._decoded
        passed = self.passed
        ready = protocol.ready if self.asynchronous else None
        for i, action in decisions:
            kind, task = decoded[action]
            if kind is _PASS:
                if ready is not None and ready[i]:
                    protocol.finish(i)                      # the build completes: rebroadcast (Johnson l. 763)
                passed[i] = True
            elif kind is _BID:
                protocol.bid(i, task, view=view)
                passed[i] = False
            elif kind is _QUIT:
                protocol.quit(i, task)
                passed[i] = False
            else:
                protocol.release(i, task)
                passed[i] = False
        self.steps += 1
        if self.asynchronous:
            protocol.advance()
            self.passed = self.waiting()
        elif self.every_step or bool(passed.all()):
            protocol.end_round()
            passed[:] = ~protocol.alive                     # an agent not present (failed, not joined) passes

    def ended(self, max_cycles: int | None = None) -> tuple[bool, bool]:
        """(terminated, truncated): converged; or not, and ``max_cycles`` steps taken, the round bound reached or the
        protocol halted (it cannot reach agreement under its faults, ``protocol.unresolved`` says why)."""
        protocol = self.protocol
        terminated = protocol.converged
        truncated = not terminated and ((max_cycles is not None and self.steps >= max_cycles)
                                        or protocol.round >= protocol.max_rounds or protocol.halted)
        return terminated, truncated
