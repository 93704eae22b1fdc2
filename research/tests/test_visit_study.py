"""The visit study (``research.evaluation.visit_study``): its channels at their nominal loss, CBAA re-auctioned after
each visit (``research.evaluation.reauction``), and a quick run of the whole study."""

from __future__ import annotations

import numpy as np
import pytest

from research.evaluation.reauction import reauction
from research.evaluation.visit_study import (
    BURST_LEAVE,
    CHANNELS,
    SOLVERS,
    channel_overrides,
    conditions,
    main,
    rayleigh_distance,
    read_rows,
)
from taskalloc.evaluation.episodes import Episode, run_episode
from taskalloc.policies import make_policy, rollout
from taskalloc_env import ConfigError, TaskAllocEnv, resolve_config
from taskalloc_env.faults import GilbertElliott
from taskalloc_env.scenario import visit_starts


@pytest.mark.parametrize("level", [0.05, 0.2, 0.4, 0.7])
def test_the_rayleigh_fading_distance_loses_the_level_on_average_over_the_instances_links(level):
    """d0 solves mean over the 12 directed links of the edge layout (distances 6, 12, 18) of 1 − exp(−(d/d0)^3) = ℓ,
    and the channel built from it delivers that share (300 messages per link)."""
    cfg = resolve_config("visit")
    starts = visit_starts(cfg)
    d0 = rayleigh_distance(level, starts)
    d = np.linalg.norm(starts[:, None] - starts[None], axis=2)[~np.eye(4, dtype=bool)]
    assert sorted(set(d.tolist())) == [6.0, 12.0, 18.0]
    assert np.mean(1 - np.exp(-((d / d0) ** 3))) == pytest.approx(level, abs=1e-9)
    env = TaskAllocEnv("visit", **channel_overrides("rayleigh", level, cfg))
    env.reset(seed=0)
    sender, receiver = np.nonzero(~np.eye(4, dtype=bool))
    rng = np.random.default_rng(0)
    lost = np.mean([env.unwrapped.protocol.network.loss.lost(sender, receiver, rng) for _ in range(300)])
    assert lost == pytest.approx(level, abs=0.03)


@pytest.mark.parametrize("level", [0.05, 0.2, 0.4, 0.7])
def test_the_burst_channel_has_the_stationary_loss_and_mean_burst_it_was_set_for(level):
    """``ge_burst``: a loss-free good state, an all-losing bad one left with probability 0.2 per message; over
    4,000 links × 400 messages the share lost is ℓ and bursts last 5 messages on average."""
    kw = channel_overrides("ge_burst", level, resolve_config("visit"))
    model = GilbertElliott(64, kw["message_loss"], kw["burst_loss"], kw["burst_enter"], kw["burst_leave"])
    sender, receiver = np.nonzero(~np.eye(64, dtype=bool))
    rng = np.random.default_rng(1)
    for _ in range(100):                                 # the chain starts good: let it reach its stationary share
        model.lost(sender, receiver, rng)
    lost = np.stack([model.lost(sender, receiver, rng) for _ in range(400)], axis=1)
    assert lost.mean() == pytest.approx(level, abs=0.01)
    ends = (lost[:, :-1] & ~lost[:, 1:]).sum()           # bursts that ended inside the window
    assert lost[:, :-1].sum() / max(ends, 1) == pytest.approx(1 / BURST_LEAVE, rel=0.05)


def test_a_loss_the_channel_cannot_reach_is_one_line():
    cfg = resolve_config("visit")
    for channel, level in (("ge_burst", 0.9), ("bernoulli", 0.0), ("rayleigh", 1.0)):
        with pytest.raises(ConfigError) as error:
            channel_overrides(channel, level, cfg)
        assert "\n" not in str(error.value)


def test_every_cell_plays_the_same_instance_per_seed():
    """The channel never changes the instance: every cell's config draws the same scenario from a seed."""
    cells = conditions([0.2, 0.7])
    assert [c.channel for c in cells] == ["ideal"] + [c for c in CHANNELS[1:] for _ in range(2)]
    fingerprints = {run_episode(Episode("cbba", c.config, 5))["instance"] for c in cells}
    assert len(fingerprints) == 1


def test_the_reauction_begins_with_the_one_shot_auction_and_visits_every_target_once_on_perfect_links():
    """Stage 0 is the ``cbaa`` episode of the same seed (each agent's first visit is the task it won there); on
    perfect links every target is visited exactly once, by the agents' own flights."""
    cfg = resolve_config("visit")
    for seed in range(5):
        first = rollout(TaskAllocEnv(cfg), make_policy("cbaa"), seed=seed)
        outcome = reauction(cfg, seed)
        visits = outcome.allocation.paths
        assert [p[:1] for p in visits] == [p[:1] for p in first.paths]
        assert sorted(j for p in visits for j in p) == list(range(10))
        assert outcome.allocation.completion == 1.0 and outcome.duplicate_visits == 0
        assert outcome.stages >= 3 and outcome.max_agent_messages >= first.counters.max_agent_messages


def test_a_quick_run_writes_every_cell_and_the_tables(tmp_path):
    """Two seeds, one level: every (channel, solver) cell has both seeds, the rows are paired, CBGA equals CBBA on
    single-agent targets, and ``--report`` rewrites the same tables from the CSV."""
    text = main(["--episodes", "2", "--levels", "0.4", "--out", str(tmp_path), "--no-progress"])
    rows = read_rows(tmp_path / "episodes.csv")
    assert len(rows) == 5 * len(SOLVERS) * 2
    assert len({r["instance"] for r in rows if r["seed"] == "0"}) == 1
    by = {(r["channel"], r["solver"], r["seed"]): r for r in rows}
    for channel in CHANNELS:
        for seed in ("0", "1"):
            assert by[(channel, "CBGA", seed)]["max_travel"] == by[(channel, "CBBA", seed)]["max_travel"]
            assert float(by[(channel, "CBAA", seed)]["completion"]) == 0.4           # one target per agent
            assert float(by[(channel, "CBAA re-auctioned", seed)]["completion"]) == 1.0
    assert "DCTA benchmark's three impaired channels" in text
    assert main(["--report", "--out", str(tmp_path)]) == text


def test_a_lone_agent_re_auctioned_flies_the_nearest_neighbour_tour():
    """One agent: every stage it wins the free target nearest to where its last visit left it (CBAA's bid falls
    with the distance), so its visits are a nearest-neighbour tour from its start."""
    cfg = resolve_config("visit", n_agents=1, n_tasks=6, arena=[6.0, 6.0, 1.0])
    for seed in range(10):
        outcome = reauction(cfg, seed)
        s = outcome.instance
        here, left = s.agent_pos[0], set(range(6))
        for task in outcome.allocation.paths[0]:
            distance = {j: np.abs(s.task_pos[j] - here).sum() for j in left}
            assert distance[task] == min(distance.values())
            here, left = s.task_pos[task], left - {task}
        assert not left and outcome.stages == 6
