"""The fuzz (``taskalloc fuzz``) on a fixed budget: random scenarios over every option, every policy."""

from __future__ import annotations

import pytest

from taskalloc.evaluation import fuzz


def test_a_short_fuzz_finds_nothing():
    counts, failures = fuzz.fuzz(episodes=40, seed=11)
    assert not failures, failures[:3]
    assert counts["determinism: passed"] == 40


@pytest.mark.slow
def test_the_ci_fuzz_finds_nothing():
    counts, failures = fuzz.fuzz(episodes=1500, seed=2026, jobs=2)
    assert not failures, failures[:3]
    assert counts["spaces: passed"] == counts["return: passed"] == 1500
