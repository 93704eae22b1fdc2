"""The hand-over between the oracle and a policy (``research.evaluation.handover``): who acts when, and its command
line."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from research.evaluation import handover
from research.policies.handover import Handover
from research.policies.oracle import OraclePolicy
from taskalloc.policies import Policy, make_policy, rollout
from taskalloc_env import TaskAllocEnv
from taskalloc_env.errors import run_cli

SEEDS = range(10_000, 10_006)


class Recording(Policy):
    """Delegates to ``inner`` and records the round of every step it acted on."""

    def __init__(self, inner: Policy) -> None:
        super().__init__()
        self.inner, self.name, self.rounds = inner, f"recorded {inner.name}", []

    @property
    def env_overrides(self) -> dict[str, Any]:
        return self.inner.env_overrides

    def start(self, env: Any, seed: int | None = None) -> None:
        super().start(env, seed)
        self.inner.start(env, seed)

    def act(self, observations, infos=None):
        self.rounds.append(next(iter(infos.values()))["round"])
        return self.inner.act(observations, infos)


def test_the_first_policy_acts_in_the_first_rounds_then_the_second_to_the_end():
    first, then = Recording(make_policy("cbgabi")), Recording(make_policy("cbgabi"))
    policy = Handover(first, then, 2)
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    for seed in SEEDS:
        first.rounds.clear(), then.rounds.clear()
        rollout(env, policy, seed=seed)
        assert set(first.rounds) == {0, 1} and len(first.rounds) > 2     # a round holds several steps
        assert then.rounds and min(then.rounds) == 2 and then.rounds == sorted(then.rounds)


def test_act_without_infos_is_refused():
    policy = Handover(OraclePolicy(), make_policy("cbgabi"), 1)
    env = TaskAllocEnv("train_small", **policy.env_overrides)
    observations, _ = env.reset(seed=10_000)
    policy.start(env, 10_000)
    with pytest.raises(ValueError, match="infos"):
        policy.act(observations)


def scores(policy, seeds):
    return np.array([a.score for a in handover.played(policy, "train_small", seeds)])


def test_no_round_of_the_first_policy_is_the_second_alone_and_enough_of_them_is_the_first_alone():
    seeds = list(SEEDS)
    np.testing.assert_array_equal(scores(Handover(OraclePolicy(), make_policy("cbgabi"), 0), seeds),
                                  scores(make_policy("cbgabi"), seeds))
    best = handover.reference_allocations("train_small", seeds)
    oracle = handover.played(Handover(OraclePolicy(), make_policy("cbgabi"), 50), "train_small", seeds)
    np.testing.assert_allclose([a.score for a in oracle], [b.score for b in best], rtol=1e-9)
    np.testing.assert_array_equal(handover.groups_kept(oracle, best), [b.n_valid for b in best])


def test_groups_kept_counts_the_reference_tasks_that_end_valid_with_the_same_members():
    """Instance 1: task 0 kept, task 1 has another member, task 2 is not valid in the row; instance 2: all kept."""
    def alloc(members, valid):
        return SimpleNamespace(members=members, valid_tasks=valid)

    best = [alloc(((0, 1), (2,), (3,)), (0, 1, 2)), alloc(((1,),), (0,))]
    row = [alloc(((1, 0), (3,), (3,)), (0, 1)), alloc(((1,),), (0,))]
    np.testing.assert_array_equal(handover.groups_kept(row, best), [1, 1])


def test_policies_that_need_different_environments_are_refused_by_name():
    with pytest.raises(ValueError, match=r"delta=3 against 1"):
        Handover(make_policy("cbga+tq:delta=3"), make_policy("cbgabi:delta=1"), 1)
    for rounds in (-1, True, 1.5):
        with pytest.raises(ValueError, match="rounds must be an integer >= 0"):
            Handover(OraclePolicy(), make_policy("cbgabi"), rounds)


def test_the_command_line_prints_each_row_and_a_long_oracle_start_reaches_the_optimum(capsys):
    table = handover.main(["--policy", "cbgabi", "--rounds", "1", "50", "--episodes", "3"])
    lines = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines()[2:]}
    assert set(lines) == {"exact optimum", "cbgabi", "oracle for 1 round(s), then cbgabi",
                          "cbgabi for 1 round(s), then the oracle", "oracle for 50 round(s), then cbgabi",
                          "cbgabi for 50 round(s), then the oracle"}
    assert lines["oracle for 50 round(s), then cbgabi"].split(" | ")[2:] == lines["exact optimum"].split(" | ")[2:]
    assert "train_small, seeds 10000–10002" in capsys.readouterr().out


@pytest.mark.slow
def test_the_lns_reference_divides_by_the_group_search_and_its_oracle_reaches_it():
    table = handover.main(["--policy", "cbgabi", "--rounds", "50", "--episodes", "3", "--reference", "lns"])
    lines = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines()[2:]}
    assert "% of LNS" in table.splitlines()[0]
    assert lines["LNS"].split(" | ")[2:4] == ["100.0 %", "3"]
    kept = lines["LNS"].split(" | ")[4]
    assert lines["oracle for 50 round(s), then cbgabi"].split(" | ")[2:] == ["100.0 %", "3", kept]


@pytest.mark.parametrize("argv, words", [
    (["--rounds", "0"], ("--rounds", ">= 1")),
    (["--episodes", "0"], ("--episodes", ">= 1")),
    (["--policy", "nonsense"], ("--policy nonsense", "unknown policy")),
    (["--scenario", "default"], ("--scenario default", "exact", "--reference lns")),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, words, capsys):
    assert run_cli(lambda: handover.main(argv)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert all(w in err[0] for w in words), err[0]
