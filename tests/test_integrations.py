"""The recipes of docs/integrations.md run as written, with the environment's default arguments.

Each recipe is a file in ``docs/integrations/``; a test here runs it when its library is installed (``pip install
-e .[integrations]``, which CI does). The heavy stacks (Ray RLlib, AgileRL, BenchMARL) run from
``bash scripts/heavy_integrations.sh``; their last results are recorded in the doc.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

RECIPES = Path(__file__).resolve().parent.parent / "docs" / "integrations"


def recipe(name: str):
    spec = importlib.util.spec_from_file_location(f"recipe_{name}", RECIPES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_pettingzoo_test_utilities_pass_with_default_arguments():
    assert len(recipe("pettingzoo_tests").main()) == 7


@pytest.mark.slow
def test_sb3_ppo_and_maskable_ppo_train_on_supersuit():
    pytest.importorskip("supersuit")
    pytest.importorskip("sb3_contrib")
    assert recipe("sb3_supersuit").main(steps=512) == {"PPO": 512, "MaskablePPO": 512}


@pytest.mark.slow
def test_maskable_ppo_trains_on_the_projects_own_vec_env():
    pytest.importorskip("sb3_contrib")
    result = recipe("sb3_taskalloc_vec_env").main(steps=512)
    assert result["MaskablePPO"] == 512 and result["episodes"] > 0


@pytest.mark.slow
def test_torchrl_checks_specs_and_rolls_out_batched():
    pytest.importorskip("torchrl")
    shapes = recipe("torchrl_wrapper").main(steps=40)
    assert shapes["random (2 envs)"] == (2, 40)
    assert 0 < shapes["mlp actor"][0] <= 40


@pytest.mark.slow
def test_maskable_ppo_trains_on_the_batched_env():
    pytest.importorskip("sb3_contrib")
    result = recipe("sb3_batched").main(steps=512)
    assert result["MaskablePPO"] == 512 and result["episodes"] > 0


@pytest.mark.slow
def test_torchrl_rolls_out_the_batched_env():
    pytest.importorskip("torchrl")
    result = recipe("torchrl_batched").main(steps=60)
    assert result["rollout"] == (8, 60) and result["episodes"] > 0


@pytest.mark.slow
def test_torchrl_mappo_trains_on_the_batched_env():
    pytest.importorskip("torchrl")
    result = recipe("torchrl_mappo").main(iterations=2, instances=8, steps=16)
    assert result["frames"] == 2 * 8 * 16 and result["episodes"] > 0


@pytest.mark.slow
def test_the_shipped_benchmarl_task_trains_where_benchmarl_is_installed():
    pytest.importorskip("benchmarl")           # its own venv: bash scripts/heavy_integrations.sh benchmarl
    assert recipe("benchmarl_task").main() == {"MappoConfig": 400, "IppoConfig": 400}


@pytest.mark.slow
def test_tianshou_plays_the_aec_view():
    pytest.importorskip("tianshou")
    result = recipe("tianshou_aec").main(episodes=2, dqn_steps=64)
    assert result["random episodes"] == 2 and result["dqn steps"] == 64 and result["random team return"] > 0


def test_the_doc_shows_the_recipes_as_they_are():
    """Every code block of docs/integrations.md that names a recipe file is a verbatim excerpt of that file."""
    text = (RECIPES.parent / "integrations.md").read_text()
    blocks = re.findall(r"<!-- recipe: (\w+) -->\n```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) >= 7
    for name, code in blocks:
        assert code.strip() in (RECIPES / f"{name}.py").read_text(), f"docs/integrations.md drifted from {name}.py"
