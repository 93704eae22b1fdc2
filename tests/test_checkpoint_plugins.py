"""The product's plug-in points (ours): ``register_policy``, checkpoint loaders chosen by the checkpoint's meta, the
partner hook of the MAPPO loop; and what a checkpoint's JSON may ask for (hardening): names in its meta only for
what its own folder holds (no privileged policy, no outside path, no recursion), ``env_overrides`` only the options
a policy plays by, committed models before folders of the working directory, finite weights."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("safetensors")

from taskalloc.policies import checkpoint, learned, make_policy, registry
from taskalloc.policies.base import Policy
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc.policies.learned import LearnedPolicy, resolve
from taskalloc.policies.scripted import CBGAPolicy
from taskalloc_env import ConfigError


@pytest.fixture
def fresh_registry(monkeypatch):
    """Registrations made by a test are undone after it."""
    monkeypatch.setattr(registry, "FACTORIES", dict(registry.FACTORIES))
    monkeypatch.setattr(registry, "PRIVILEGED", set(registry.PRIVILEGED))
    monkeypatch.setattr(registry, "LOADERS", dict(registry.LOADERS))


def write(stem: Path, meta: dict | None = None, env_overrides: dict | None = None) -> Path:
    """The committed ``train_small`` bidder saved at ``stem`` with other meta (and env_overrides)."""
    ck = checkpoint.load(resolve("train_small"))
    return checkpoint.save(stem, ck.actor, ck.own_features, ck.task_features,
                           ck.env_overrides if env_overrides is None else env_overrides, meta or {})


# -- register_policy ---------------------------------------------------------------------------------------------
def test_a_registered_policy_is_made_by_name_once_and_only_with_a_valid_name(fresh_registry):
    registry.register_policy("my-cbga", lambda **kw: CBGAPolicy(**kw))
    assert isinstance(make_policy("my-cbga"), CBGAPolicy) and "my-cbga" in registry.policy_names()
    with pytest.raises(ValueError, match="already registered"):
        registry.register_policy("my-cbga", CBGAPolicy)
    with pytest.raises(ValueError, match="already registered"):
        registry.register_policy("cbgabi", CBGAPolicy)          # the baselines are registered the same way
    for bad in ("learned", "My Policy", "", "x:y", 3):
        with pytest.raises(ValueError, match="policy name"):
            registry.register_policy(bad, CBGAPolicy)
    with pytest.raises(ValueError, match="not callable"):
        registry.register_policy("other", "cbga")


def test_the_product_registers_no_privileged_or_research_policy():
    assert "oracle" not in registry.FACTORIES or "oracle" in registry.PRIVILEGED
    assert {"random", "pass", "cbba", "acbba", "cbga", "cbga+tq", "cbga+tb", "cbgabi"} <= set(registry.FACTORIES)


# -- checkpoint loaders ------------------------------------------------------------------------------------------
def test_the_loader_is_chosen_by_the_meta_algo(tmp_path, fresh_registry):
    assert isinstance(make_policy(f"learned:{write(tmp_path / 'a', {'algo': 'mappo'})}"), LearnedPolicy)
    path = write(tmp_path / "b", {"algo": "mine"})
    with pytest.raises(CheckpointError, match="no loader for checkpoints of algo 'mine'"):
        make_policy(f"learned:{path}")
    seen = []

    def mine(request: registry.LoadRequest, **options) -> Policy:
        seen.append((request.checkpoint.meta["algo"], request.name, options))
        return CBGAPolicy()

    registry.register_checkpoint_loader("mine", mine)
    assert isinstance(make_policy(f"learned:{path}", deterministic=False), CBGAPolicy)
    assert seen == [("mine", f"learned:{path}", {"deterministic": False})]
    with pytest.raises(ValueError, match="already registered"):
        registry.register_checkpoint_loader("mine", mine)


# -- what a checkpoint's meta may name ---------------------------------------------------------------------------
@pytest.fixture
def naming_loader(fresh_registry):
    """A loader for meta algo ``named`` that plays the policy its meta ``then`` names."""
    registry.register_checkpoint_loader("named", lambda request, **_: request.policy("then"))


def test_meta_names_no_privileged_policy(tmp_path, naming_loader):
    registry.register_policy("peek", CBGAPolicy, privileged=True)
    path = write(tmp_path / "m", {"algo": "named", "then": "peek"})
    with pytest.raises(CheckpointError, match="privileged"):
        make_policy(f"learned:{path}")
    write(tmp_path / "m", {"algo": "named", "then": "cbgabi"})
    assert isinstance(make_policy(f"learned:{path}"), CBGAPolicy)


def test_meta_names_no_path_outside_the_checkpoints_folder(tmp_path, naming_loader):
    write(tmp_path / "outside" / "model")
    inner = tmp_path / "run"
    for then in (f"learned:{tmp_path / 'outside'}", "learned:../outside"):
        path = write(inner / "model", {"algo": "named", "then": then})
        with pytest.raises(CheckpointError, match="inside its own folder"):
            make_policy(f"learned:{path}")
    write(inner / "partner" / "model")
    path = write(inner / "model", {"algo": "named", "then": "learned:partner"})
    assert isinstance(make_policy(f"learned:{path}"), LearnedPolicy)
    write(inner / "model", {"algo": "named", "then": "learned:train_small"})     # a committed model by name
    assert isinstance(make_policy(f"learned:{path}"), LearnedPolicy)


def test_a_checkpoint_naming_itself_is_refused_at_once(tmp_path, naming_loader, monkeypatch):
    path = write(tmp_path / "run" / "model", {"algo": "named", "then": "learned:model.json"})
    with pytest.raises(CheckpointError, match="names it again"):
        make_policy(f"learned:{path}")
    # named models of a registered folder that name each other in a loop
    monkeypatch.setattr(learned, "MODEL_FOLDERS", [])
    write(tmp_path / "named" / "ping" / "model", {"algo": "named", "then": "learned:pong"})
    write(tmp_path / "named" / "pong" / "model", {"algo": "named", "then": "learned:ping"})
    learned.register_model_folder(tmp_path / "named")
    with pytest.raises(CheckpointError, match=r"ping.*pong.*ping"):
        make_policy("learned:ping")


# -- env_overrides, named models, weights ------------------------------------------------------------------------
@pytest.mark.parametrize("option", [{"comm_range": 5.0}, {"max_rounds": 3}, {"message_loss": 0.5},
                                    {"popup_tasks": 2, "popup_period": 3}, {"max_delay": 2}])
def test_env_overrides_may_not_set_the_network_the_round_bound_or_the_instance(tmp_path, option):
    path = write(tmp_path / "m")
    spec = json.loads(path.read_text())
    spec["env_overrides"] = {**spec["env_overrides"], **option}
    path.write_text(json.dumps(spec))
    with pytest.raises(CheckpointError, match="options a policy plays by"):
        make_policy(f"learned:{path}")
    with pytest.raises(CheckpointError, match="options a policy plays by"):
        write(tmp_path / "n", env_overrides={"task_quitting": True, **option})


def test_a_folder_of_the_working_directory_does_not_shadow_a_committed_model(tmp_path, monkeypatch):
    write(tmp_path / "train_small" / "model", {"name": "impostor"})
    monkeypatch.chdir(tmp_path)
    assert make_policy("learned:train_small").meta.get("name") == "train_small"
    assert make_policy("learned:./train_small").meta["name"] == "impostor"
    os.rename(tmp_path / "train_small", tmp_path / "not_committed")
    with pytest.raises(CheckpointError, match=r"learned:\./not_committed"):
        make_policy("learned:not_committed")


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_non_finite_weights_are_refused(tmp_path, value):
    from safetensors.torch import load_file, save_file

    path = write(tmp_path / "m")
    weights = load_file(str(path.with_suffix(".safetensors")))
    name = sorted(weights)[0]
    weights[name].view(-1)[0] = float(value)
    save_file(weights, str(path.with_suffix(".safetensors")))
    with pytest.raises(CheckpointError, match=f"{name}.*NaN or infinite"):
        make_policy(f"learned:{path}")


def test_a_checkpoint_error_is_a_config_error():
    assert issubclass(CheckpointError, ConfigError)


# -- the partner hook of the MAPPO loop ---------------------------------------------------------------------------
def test_the_mappo_loop_plays_a_hooks_partner_and_runs_without_one(tmp_path):
    """A partner that plays every round after round 0 (here CBGABI): the actor acts only on round-0 states and its
    return at an episode's first step is the whole episode's score; without a partner the actor plays every round.
    The hook's config class and its configs folder are what ``load_config`` reads, and ``load_weights`` lets it
    adjust an actor started from a checkpoint."""
    import dataclasses

    import torch as th

    from taskalloc.training import mappo
    from taskalloc.training.config import opt
    from taskalloc.training.critic import StateCritic

    @dataclasses.dataclass
    class Config(mappo.MappoConfig):
        partner: str = opt("cbgabi", "the policy after round 0")

    class Later:
        def __init__(self, name: str) -> None:
            self.policy, self.meta = make_policy(name), {"then": name}

        def plays(self, round_: int) -> bool:
            return round_ > 0

        def with_actor(self, bidder: Policy) -> Policy:
            return bidder

    class Hook:
        config, configs, prog = Config, tmp_path, "test"

        def __init__(self) -> None:
            self.adjusted: list[str] = []

        def partner(self, cfg: Config) -> Later:
            return Later(cfg.partner)

        def init_actor(self, actor, meta) -> None:
            self.adjusted.append(meta.get("name"))

    (tmp_path / "mine.yaml").write_text("name: mine\npartner: cbga+tq\nhidden: 32\nheads: 2\nlayers: 1\n")
    hook = Hook()
    cfg = mappo.load_config(["--config", "mine", "--out-dir", str(tmp_path / "run")], hook)
    assert type(cfg) is Config and cfg.partner == "cbga+tq" and cfg.name == "mine"
    with pytest.raises(SystemExit):
        mappo.load_config(["--partner", "cbgabi"])             # the product's config has no partner field
    cfg.partner = "cbgabi"
    group = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0, hook.partner(cfg))
    group.reset()
    th.manual_seed(0)
    model = mappo.ActorCritic(mappo.make_actor(cfg, group.layout.own_size, group.layout.task_size),
                              StateCritic(group.n_equipment, cfg.hidden, cfg.heads))
    r = mappo.collect(model, group, n_steps=20, gamma=1.0, gae_lambda=1.0)
    assert (r.obs[:, group.layout.own_names.index("round")] == 0).all() and len(group.scores) >= 2
    assert float(r.returns[0]) == pytest.approx(group.scores[0] / group.reward_scale, abs=1e-4)
    plain = mappo.Group({"scenario": "train_small"}, cfg.env_overrides, cfg.max_cycles, 0)
    plain.reset()
    r = mappo.collect(model, plain, n_steps=10, gamma=1.0, gae_lambda=1.0)
    assert (r.obs[:, plain.layout.own_names.index("round")] > 0).any()
    path = mappo.save_actor(tmp_path / "start" / "model", model.actor, group, cfg, {"name": "start"})
    assert mappo.load_weights(model, str(path), hook) == ["actor"] and hook.adjusted == ["start"]
