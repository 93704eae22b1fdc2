"""The config's field facts (taskalloc_env.fields, taskalloc_env/options/): the docs tables, the messages, the loss
models answering for themselves, named generators, and our limits (docs/decisions.md "config limits")."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from taskalloc_env import Agent, ConfigError, Scenario, Task, TaskAllocEnv, generate, resolve_config
from taskalloc_env.config import FACTS, FIELD_GROUPS, TaskAllocConfig
from taskalloc_env.faults import GilbertElliott
from taskalloc_env.fields import render_docs, table
from taskalloc_env.generators import GENERATORS, register_generator
from taskalloc_env.memory import memory_estimate
from taskalloc_env.scenario import uniform

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "configuration.md"


def test_every_field_has_a_fact_and_the_docs_tables_are_the_facts():
    """docs/configuration.md's tables are generated from the facts: a missing field or a row that differs fails
    (regenerate with ``python -m taskalloc_env.options --docs docs/configuration.md``)."""
    assert [f.name for f in dataclasses.fields(TaskAllocConfig)] == list(FACTS)
    text = DOCS.read_text(encoding="utf-8")
    assert render_docs(text, FIELD_GROUPS) == text, "docs/configuration.md differs from the field facts"
    rows = set(re.findall(r"^\| `([a-z_0-9]+)` \|", text, re.M))
    assert set(FACTS) <= rows
    for name, fields in FIELD_GROUPS.items():
        assert f"<!-- fields:{name} -->\n{table(fields)}<!-- /fields:{name} -->" in text
    assert all(f.default == getattr(TaskAllocConfig(), f.name) for f in FACTS.values())


def test_unknown_field_is_one_short_line_with_a_did_you_mean():
    with pytest.raises(ConfigError) as info:
        TaskAllocEnv(n_agent=5)
    message = str(info.value)
    assert "'n_agent' (did you mean 'n_agents'?)" in message and "\n" not in message and len(message) < 160
    with pytest.raises(ConfigError, match="and 2 more") as info:
        resolve_config({f"x{'y' * 10**5}{i}": 1 for i in range(5)})
    assert len(str(info.value)) < 400


def test_the_loss_model_answers_for_itself(monkeypatch):
    """The config asks the loss model whether it loses messages (no test of its name): a bursty model that says it
    cannot makes the network perfect and the confirmations 0."""
    bursty = TaskAllocConfig(loss_model="gilbert_elliott")
    assert bursty.loses_messages and bursty.faulty and bursty.confirmation_count == 2
    assert not TaskAllocConfig().loses_messages and TaskAllocConfig(message_loss=0.1).loses_messages
    monkeypatch.setattr(GilbertElliott, "loses_messages", classmethod(lambda cls, cfg: False))
    assert not bursty.faulty and bursty.confirmation_count == 0


def test_a_registered_generator_is_the_one_the_env_uses(monkeypatch):
    """The seam for new instance families: ``generator`` names a registered function; an unknown name is refused
    listing the names; the default ``uniform`` is the thesis's generator."""
    monkeypatch.setitem(GENERATORS, "uniform", GENERATORS["uniform"])
    calls = []

    def clustered(cfg, rng):
        calls.append(cfg.n_agents)
        s = uniform(cfg, rng)
        return dataclasses.replace(s, task_pos=np.zeros_like(s.task_pos))
    register_generator("clustered", clustered)
    try:
        env = TaskAllocEnv(n_agents=3, n_tasks=4, agents_per_task=1, generator="clustered")
        env.reset(seed=0)
        assert calls and (env.scenario.task_pos == 0).all()
        assert resolve_config().generator == "uniform"
        drawn = generate(resolve_config(), np.random.default_rng(0))
        assert (drawn.task_pos == uniform(resolve_config(), np.random.default_rng(0)).task_pos).all()
    finally:
        GENERATORS.pop("clustered")
    with pytest.raises(ConfigError, match=r"'generator': got 'clustered'; allowed: a registered generator: uniform"):
        resolve_config(generator="clustered")


# -- our limits: each a one-line ConfigError before any cost ------------------------------------------------------
HUGE = 2**63
LIMITS = {
    "pop-up at 10^9": ({"popup_tasks": 1, "popup_times": [10**9]}, "'popup_times'"),
    "popup_period 2^62": ({"popup_tasks": 1, "popup_period": 2**62}, "'popup_period'"),
    "last release past the horizon": ({"popup_tasks": 20, "popup_period": 10**4}, "popup_tasks × popup_period"),
    "delta 2^63": ({"delta": HUGE}, "'delta'"),
    "max_bundle 2^63": ({"max_bundle": HUGE}, "'max_bundle'"),
    "max_delay 2^63": ({"max_delay": HUGE}, "'max_delay'"),
    "separation_time 2^63": ({"separation_time": HUGE}, "'separation_time'"),
    "dropout_rounds 2^63": ({"dropout_rounds": [1, HUGE]}, "'dropout_rounds'"),
    "build_ticks 2^63": ({"build_ticks": [0, HUGE]}, "'build_ticks'"),
    "max_rounds 2^63": ({"max_rounds": HUGE}, "'max_rounds'"),
    "L_j 2^63": ({"agents_per_task": HUGE}, "'agents_per_task'"),
    "task_mix agents 2^63": ({"n_tasks": 1, "task_mix": [{"count": 1, "agents": HUGE}]}, "'task_mix.agents'"),
    "speed 2^2000": ({"speed": 2**2000}, "'speed'"),
    "arena NaN": ({"arena": [float("nan"), 5, 2]}, "'arena'"),
    "arena 0": ({"arena": [0, 0, 0]}, "'arena'"),
    "every agent fails": ({"n_agents": 2, "dropout_schedule": [[0, 1], [1, 2]]}, "one agent must stay"),
}


@pytest.mark.parametrize("case", list(LIMITS))
def test_values_that_never_finish_or_wrap_are_refused(case):
    values, words = LIMITS[case]
    with pytest.raises(ConfigError) as info:
        TaskAllocEnv(**values)
    message = str(info.value)
    assert words in message and "\n" not in message and len(message) < 300


def test_directly_built_scenarios_are_checked():
    agent = Agent(position=(0.0, 0.0, 0.0), speed=1.0)
    task = Task(position=(1.0, 1.0, 0.0), reward=100.0, start=0.0, end=5.0, duration=1.0)
    base = Scenario.from_entities([agent], [task])
    with pytest.raises(ConfigError, match="task_agents"):
        dataclasses.replace(base, task_agents=np.array([1.5]))
    for arena in [(0.0, 0.0, 0.0), (float("nan"), 5.0, 2.0)]:
        with pytest.raises(ConfigError, match="arena"):
            dataclasses.replace(base, arena=arena)
    with pytest.raises(ConfigError, match=r"at most .* tasks"):
        Scenario.from_entities([agent], [task] * 10**6)


def test_memory_estimate_counts_the_agent_by_agent_arrays():
    """20 000 agents and one task allocate about 3 GiB of N × N arrays; the estimate sees them, and the limit is a
    number (NaN would disable the check)."""
    assert memory_estimate(20_000, 1, None) > 3 * 2**30
    with pytest.raises(ConfigError, match="20000 agents × 1 tasks need about"):
        TaskAllocEnv(n_agents=20_000, n_tasks=1, agents_per_task=1, memory_limit_gb=2.0)
    with pytest.raises(ConfigError, match="memory_limit_gb"):
        TaskAllocEnv(memory_limit_gb=float("nan"))


def test_a_billion_laughs_scenario_is_refused_with_a_short_message(tmp_path):
    path = tmp_path / "laughs.yaml"
    lines, prev = ["start_time_range:", "- &a [1,1,1,1,1,1,1,1,1]"], "a"
    for name in "bcdefghi":
        lines.append(f"- &{name} [" + ",".join([f"*{prev}"] * 9) + "]")
        prev = name
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match="start_time_range") as info:
        resolve_config(path)
    assert len(str(info.value)) < 300


REFUSALS = {
    "billion laughs": "resolve_config(LAUGHS)",
    "pop-up at 10^9": "TaskAllocEnv(popup_tasks=1, popup_times=[10**9])",
    "N x N": "TaskAllocEnv(n_agents=20_000, n_tasks=1, agents_per_task=1, memory_limit_gb=2.0)",
    "10^6 tasks built": ("Scenario.from_entities([Agent((0.0, 0.0, 0.0), 1.0)], "
                         "[Task((1.0, 1.0, 0.0), 100.0, 0.0, 5.0, 1.0)] * 10**6)"),
    "n_agent typo": "TaskAllocEnv(n_agent=5)",
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(REFUSALS))
def test_a_refusal_costs_less_than_100_mb(case, tmp_path):
    """Peak memory of the refusal above the import's, measured in a child process (docs/decisions.md)."""
    laughs = tmp_path / "laughs.yaml"
    lines, prev = ["start_time_range:", "- &a [1,1,1,1,1,1,1,1,1]"], "a"
    for name in "bcdefghi":
        lines.append(f"- &{name} [" + ",".join([f"*{prev}"] * 9) + "]")
        prev = name
    laughs.write_text("\n".join(lines) + "\n")
    code = textwrap.dedent(f"""
        import resource, time
        from pathlib import Path
        from taskalloc_env import Agent, ConfigError, Scenario, Task, TaskAllocEnv, resolve_config
        LAUGHS = Path({str(laughs)!r})
        before, start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, time.perf_counter()
        try:
            {REFUSALS[case]}
        except ConfigError:
            pass
        else:
            raise SystemExit("not refused")
        print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before, time.perf_counter() - start)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    grown_kb, seconds = out.stdout.split()
    assert int(grown_kb) < 100 * 1024 and float(seconds) < 10
