"""A user's own policy by import path: ``make_policy("module:Attribute")`` and ``taskalloc compare --policy``."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from taskalloc.policies import make_policy, rollout
from taskalloc.policies.base import Policy
from taskalloc_env import taskalloc_v0
from taskalloc_env.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
SMALL = {"scenario": "train_small"}

USER_MODULE = textwrap.dedent('''
    import numpy as np
    from taskalloc.policies import Policy

    STARTED = []


    class LastBid:
        """Bids on the allowed task with the highest index, else passes."""

        def start(self, env, seed=None):
            STARTED.append(seed)

        def act(self, observations, infos=None):
            n_tasks = (len(next(iter(observations.values()))["action_mask"]) - 1) // 2
            return {agent: int(max(np.flatnonzero(obs["action_mask"][1:n_tasks + 1]) + 1, default=0))
                    for agent, obs in observations.items()}


    def last_bid(observations):
        return LastBid().act(observations)


    class NamedBid(LastBid):
        name = "last bid"


    class Quitter(LastBid):
        env_overrides = {"task_quitting": True}


    class Subclass(Policy):
        def act(self, observations, infos=None):
            return {agent: 0 for agent in observations}


    class Named(Subclass):
        name = "my pass"


    class NeedsArgument(LastBid):
        def __init__(self, width):
            self.width = width


    INSTANCE = LastBid()
    NUMBER = 3
''')


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """``user_policies.py`` in a temporary folder on ``sys.path``; its name, unique per test, is returned."""
    name = f"user_policies_{tmp_path.name.replace('-', '_')}"
    (tmp_path / f"{name}.py").write_text(USER_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield name
    sys.modules.pop(name, None)


def _score(policy: Policy, seed: int = 3) -> float:
    return rollout(taskalloc_v0.parallel_env(**SMALL, **policy.env_overrides), policy, seed=seed).score


def test_a_class_by_import_path_is_built_started_and_plays(user_module):
    policy = make_policy(f"{user_module}:LastBid")
    assert policy.name == f"{user_module}:LastBid"
    score = _score(policy)
    assert sys.modules[user_module].STARTED == [3]                      # its own start(env, seed) ran
    assert score > 0                                                    # it bid: passing only scores 0
    assert _score(make_policy(f"{user_module}:last_bid")) == score      # a function of the observations
    assert _score(make_policy(f"{user_module}:INSTANCE")) == score      # an object with act, as is
    assert make_policy(f"{user_module}:NamedBid").name == "last bid"    # a wrapped object keeps its own name


def test_policy_subclasses_are_used_as_they_are_and_keep_their_name(user_module):
    policy = make_policy(f"{user_module}:Subclass")
    assert type(policy).__name__ == "Subclass" and policy.name == f"{user_module}:Subclass"
    assert make_policy(f"{user_module}:Named").name == "my pass"
    assert _score(policy) == 0


def test_a_users_env_overrides_reach_the_runner_and_are_checked(user_module):
    policy = make_policy(f"{user_module}:Quitter")
    assert policy.env_overrides == {"task_quitting": True}
    env = taskalloc_v0.parallel_env(**SMALL)                            # built without the option it needs
    env.reset(seed=0)
    with pytest.raises(ValueError, match="task_quitting"):
        policy.start(env, 0)


@pytest.mark.parametrize(("path", "message"), [
    ("no_such_module_xyz:Policy", "module 'no_such_module_xyz' cannot be imported"),
    ("{m}:Missing", "has no attribute 'Missing'"),
    ("{m}:NUMBER", "names a int; expected a policy class"),
    ("{m}:NeedsArgument", "cannot be built with no arguments"),
    ("{m}:", "an import path is written module:attribute"),
    ("{m}:Last-Bid", "an import path is written module:attribute"),
])
def test_bad_import_paths_are_one_line_config_errors(user_module, path, message):
    with pytest.raises(ConfigError, match=message) as caught:
        make_policy(path.format(m=user_module))
    assert "\n" not in str(caught.value)


def test_an_error_raised_while_importing_the_users_module_is_a_config_error(tmp_path, monkeypatch):
    (tmp_path / "broken_user_module.py").write_text("raise RuntimeError('half written')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ConfigError, match="importing 'broken_user_module' failed: RuntimeError: half written"):
        make_policy("broken_user_module:Policy")


def test_a_module_in_the_current_directory_is_found_without_being_on_sys_path(tmp_path, monkeypatch):
    (tmp_path / "cwd_user_module.py").write_text(USER_MODULE)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    assert make_policy("cwd_user_module:LastBid").name == "cwd_user_module:LastBid"
    assert sys.path[-1] == str(tmp_path)                                # after the installed packages
    sys.modules.pop("cwd_user_module", None)


def test_scripted_names_with_parameters_still_resolve():
    assert make_policy("cbgabi:delta=3").env_overrides["delta"] == 3
    with pytest.raises(ValueError, match="takes no parameters"):
        make_policy("cbga:delta=3")


def _compare(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)]), "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "taskalloc", "compare", "--episodes", "2", "--set", "n_agents=4",
                           "--set", "n_tasks=8", "--set", "agents_per_task=1", "--no-learned", "--no-progress",
                           "--jobs", "1", *args], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_compare_adds_a_row_per_policy_given_by_import_path(tmp_path, user_module):
    done = _compare(tmp_path, "--policy", f"{user_module}:LastBid", "--policy", f"{user_module}:Named")
    assert done.returncode == 0, done.stderr
    rows = {line.split("|")[1].strip(): line for line in done.stdout.splitlines() if line.startswith("| ")}
    assert f"{user_module}:LastBid" in rows and "my pass" in rows
    assert rows["my pass"].split("|")[2].strip() == "0 ± 0"            # the passing policy's score


@pytest.mark.slow
@pytest.mark.parametrize("path", ["no_such_module_xyz:Policy", "{m}:NUMBER", "cbgx"])
def test_compare_exits_2_with_one_line_on_a_bad_policy(tmp_path, user_module, path):
    done = _compare(tmp_path, "--policy", path.format(m=user_module))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and done.stderr.startswith("error: --policy: ")
    assert done.stdout == ""


def test_compare_refuses_a_policy_that_would_be_a_second_row_of_the_same_name(capsys):
    from taskalloc.cli import main

    assert main(["compare", "--episodes", "2", "--no-learned", "--policy", "cbga"]) == 2
    assert "a row would appear twice (CBGA)" in capsys.readouterr().err
