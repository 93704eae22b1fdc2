"""The ``perfect`` network gives exactly the pre-network results (same seeds, identical
allocations and counters).

``tests/data/perfect_network_04b92bb.json`` holds CBGA, CBGABI and CBBA episodes on the default scenario and with
``comm_range=2.0`` (two seeds each), computed with the code at commit 04b92bb, the last one before the network layer
(``taskalloc_env/network.py``). To regenerate it::

    git worktree add --detach /tmp/wt-04b 04b92bb
    PYTHONPATH=/tmp/wt-04b python tests/test_perfect_network.py > /tmp/pinned.json
    mv /tmp/pinned.json tests/data/perfect_network_04b92bb.json

Every field the two versions share has the same default, so the same keywords build the same configuration.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from taskalloc.policies import make_policy, rollout
from taskalloc_env import TaskAllocEnv

FIXTURE = Path(__file__).parent / "data" / "perfect_network_04b92bb.json"
PINNED = json.loads(FIXTURE.read_text())["episodes"] if FIXTURE.exists() else []


def cases() -> list[dict[str, Any]]:
    """(policy, env keywords, seed) of the pinned episodes; CBBA on single-agent tasks."""
    out = []
    for scenario in ({}, {"comm_range": 2.0}):
        for name in ("cbga", "cbgabi", "cbba"):
            extra = {"agents_per_task": 1} if name == "cbba" else {}
            out += [{"policy": name, "env": {**scenario, **extra}, "seed": seed} for seed in (0, 1)]
    return out


def episode(case: dict[str, Any]) -> dict[str, Any]:
    """The figures pinned for one case: paths, score, rounds, messages, data items, convergence."""
    p = make_policy(case["policy"])
    a = rollout(TaskAllocEnv(**case["env"], **p.env_overrides), p, seed=case["seed"])
    return {**case, "paths": [[int(j) for j in path] for path in a.paths], "score": a.score,
            "rounds": a.counters.rounds, "messages": a.counters.messages, "data_items": a.counters.data_items,
            "converged": a.converged}


def test_fixture_covers_the_cases():
    assert [{k: e[k] for k in ("policy", "env", "seed")} for e in PINNED] == cases()


@pytest.mark.parametrize("pinned", PINNED, ids=lambda e: f"{e['policy']}-{'-'.join(map(str, e['env'].values()))}"
                                                      f"-{e['seed']}")
def test_perfect_network_reproduces_the_pre_network_episodes(pinned):
    got = episode({k: pinned[k] for k in ("policy", "env", "seed")})
    assert got["paths"] == pinned["paths"]
    assert (got["rounds"], got["messages"], got["data_items"], got["converged"]) == (
        pinned["rounds"], pinned["messages"], pinned["data_items"], pinned["converged"])
    assert got["score"] == pytest.approx(pinned["score"], rel=1e-12)


if __name__ == "__main__":
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__import__("taskalloc_env").__file__).parent).stdout.strip()
    comment = (f"perfect-network episodes computed with the code at commit {commit} (before the network layer): "
               "PYTHONPATH=<a worktree of that commit> python tests/test_perfect_network.py; read by "
               "tests/test_perfect_network.py")
    rows = ",\n".join(" " + json.dumps(episode(c)) for c in cases())
    print(f'{{"comment": {json.dumps(comment)},\n"episodes": [\n{rows}\n]}}')
