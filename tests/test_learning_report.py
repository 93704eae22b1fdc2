"""``taskalloc.evaluation.learning_report``: the message-loss and delay sets are paired draw for draw, and runs whose
weights are gone keep their archived rows and training logs."""

from __future__ import annotations

import dataclasses
import json
import shutil
from typing import Any

import numpy as np
import pytest

from taskalloc.evaluation import learning_report as lr
from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv, resolve_config, resources
from taskalloc_env import network as netmod
from taskalloc_env.scenario import generate

SEND = netmod.Network.send      # the unpatched method (each call below patches it anew)


def lost_messages(monkeypatch, policy: str, seed: int, **overrides) -> list[tuple[int, frozenset]]:
    """Per round, the (sender, receiver) pairs whose message the network lost in one episode of ``policy``."""
    log: list[tuple[int, frozenset]] = []
    send = SEND

    def spy(self, now, senders, items):
        before = self.rng.bit_generator.state
        out = send(self, now, senders, items)
        replay = np.random.Generator(type(self.rng.bit_generator)())
        replay.bit_generator.state = before
        sending = np.zeros(self.graph.n_agents, dtype=bool)
        sending[senders] = True
        s, r = np.nonzero(self.graph.adjacency & sending[:, None])
        lost = replay.random(len(s)) < self.loss.p
        assert int(lost.sum()) == out.lost
        log.append((now, frozenset(zip(s[lost].tolist(), r[lost].tolist()))))
        return out

    monkeypatch.setattr(netmod.Network, "send", spy)
    pol = make_policy(policy)
    env = TaskAllocEnv("train_small", **{**overrides, **pol.env_overrides})
    rollout(env, pol, seed=seed)
    return log


def assert_same_instance(overrides: dict[str, Any]) -> None:
    """The instance is drawn before the network's generator is spawned: the network options do not change it."""
    perfect = generate(resolve_config("train_small"), np.random.default_rng(10000))
    faulty = generate(resolve_config("train_small", **overrides), np.random.default_rng(10000))
    for field in dataclasses.fields(perfect):
        a, b = getattr(perfect, field.name), getattr(faulty, field.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, field.name


def test_every_row_of_the_loss_set_sees_the_same_losses(monkeypatch):
    """Same seed: the same instance and, in every round both play, the same lost (sender, receiver) messages."""
    overrides = dict(lr.SETTINGS["loss_small"].overrides)
    assert overrides == {"message_loss": 0.2}
    for seed in (10000, 10001, 10002):
        logs = [lost_messages(monkeypatch, p, seed, **overrides) for p in ("random", "cbga", "cbgabi")]
        assert any(lost for _, lost in logs[0])
        for other in logs[1:]:
            assert [r for r, _ in other[:len(logs[0])]] == [r for r, _ in logs[0][:len(other)]]
            assert all(a == b for a, b in zip(logs[0], other))
    assert_same_instance(overrides)


def network_draws(monkeypatch, policy: str, seed: int, **overrides) -> tuple[list[tuple[int, list, dict]], Any]:
    """Per message batch of one episode of ``policy``: (round, senders, the network generator's state before the
    batch draws its losses and delays), and the episode's allocation."""
    log: list[tuple[int, list, dict]] = []
    send = SEND

    def spy(self, now, senders, items):
        log.append((now, np.asarray(senders).tolist(), self.rng.bit_generator.state))
        return send(self, now, senders, items)

    monkeypatch.setattr(netmod.Network, "send", spy)
    pol = make_policy(policy)
    env = TaskAllocEnv("train_small", **{**overrides, **pol.env_overrides})
    return log, rollout(env, pol, seed=seed)


def test_every_row_of_the_delay_set_sees_the_same_delays(monkeypatch):
    """Same seed: the same instance and, in every round both play, the same senders and generator state, so the
    same delay (and loss) draws for every (sender, receiver) message."""
    overrides = dict(lr.SETTINGS["delay_small"].overrides)
    assert overrides == {"max_delay": 2} and lr.SETTINGS["delay_small"].centralised_from == "train_small"
    for seed in (10000, 10001, 10002):
        runs = [network_draws(monkeypatch, p, seed, **overrides) for p in ("random", "cbga", "cbgabi")]
        assert all(allocation.counters.messages_delayed > 0 for _, allocation in runs)
        first = runs[0][0]
        for other, _ in runs[1:]:
            common = min(len(first), len(other))
            assert common > 1 and other[:common] == first[:common]
    assert_same_instance(overrides)


def test_a_run_without_weights_keeps_its_archived_row(tmp_path, monkeypatch):
    """Re-evaluating plays only what is missing; a seed whose model is gone keeps its row, a new one is added."""
    config = lr.Config("test config", "cfg_gone")
    setting = lr.Setting("tiny", "tiny", "train_small", {}, (config,), baselines=("cbgabi",))
    archived = {"label": config.label, "kind": "learned", "config": config.name, "seed": 1,
                "solver": "learned:gone", "weights": "0123456789ab", "folder": "gone",
                **{f: [1.0, 2.0] for f in lr.FIGURES}}
    out = tmp_path / "results"
    out.mkdir()
    (out / "heldout_tiny.json").write_text(json.dumps({"setting": "tiny", "seeds": [10000, 10001],
                                                       "rows": [archived]}))
    runs = tmp_path / "runs"
    model = runs / config.name / "seed2"
    model.mkdir(parents=True)
    for name in ("model.json", "model.safetensors", "summary.yaml", "config.yaml", "eval.csv"):
        shutil.copyfile(resources.folder("models") / "train_small" / name, model / name)
    monkeypatch.setattr(lr, "SEEDS", (0, 1, 2))
    lr.evaluate(setting, 2, 1, "local", runs, out, recompute=False)
    rows = json.loads((out / "heldout_tiny.json").read_text())["rows"]
    assert [(r["label"], r.get("seed")) for r in rows] == [("CBGABI", None), (config.label, 1), (config.label, 2)]
    assert rows[1]["score"] == [1.0, 2.0]
    assert (out / "runs" / config.name / "seed2" / "eval.csv").is_file()
    assert not (out / "runs" / config.name / "seed1").exists()


@pytest.mark.parametrize("name", ["train_small", "default", "size_20x40", "size_8x16", "delay_small"])
def test_committed_results_render(name):
    data = json.loads((lr.OUT / f"heldout_{name}.json").read_text())
    table = lr.heldout_table(data)
    assert table.count("\n") >= len({(r["label"], r["kind"] == "learned") for r in data["rows"]})


def test_the_room_table_measures_the_learned_share_against_the_best_allocation_known():
    """CBGABI 100, LNS 110, a configuration whose seeds average 105 (104, 105, 106), a weaker one and a better one
    with a single seed: half the room to LNS; with an optimum of 120 the room is measured to it (a quarter)."""
    def row(label, kind, score, **extra):
        return {"label": label, "kind": kind, "score": [score, score], **extra}

    rows = [row("CBGABI", "baseline", 100.0), row(lr.NAMES["lns"], "centralised", 110.0),
            row("weak", "learned", 101.0, seed=0), row("lucky", "learned", 108.0, seed=0),
            *(row("strong", "learned", score, seed=k) for k, score in enumerate((104.0, 105.0, 106.0)))]
    table = lr.room_table({"a": {"rows": rows}, "b": {"rows": [*rows, row(lr.NAMES["exact"], "centralised", 120.0)]}})
    a, b = table.splitlines()[2:]
    assert a == "| `a` | 100.0 | 110.0 % | – | strong (3 seeds) | 105.0 % | 50 % |"
    assert b == "| `b` | 100.0 | 110.0 % | 120.0 % | strong (3 seeds) | 105.0 % | 25 % |"


@pytest.mark.slow
@pytest.mark.parametrize("setting", ["loss_small", "delay_small"])
def test_the_centralised_rows_do_not_depend_on_the_network(setting):
    """Why the loss and delay sets copy SGAMA, LNS and the exact optimum from the perfect-link set: they send no
    message."""
    from taskalloc.evaluation.episodes import Episode, run_episodes

    perfect = resolve_config("train_small")
    faulty = resolve_config("train_small", **lr.SETTINGS[setting].overrides)
    for solver in lr.CENTRALISED:
        a, b = (run_episodes([Episode(solver, cfg, s) for s in (10000, 10001)], jobs=1, progress=False)
                for cfg in (perfect, faulty))
        assert [e["score"] for e in a] == [e["score"] for e in b]
    assert lr.SETTINGS[setting].centralised_from == "train_small"
