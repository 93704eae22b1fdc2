"""Research studies on top of the taskalloc product (research/README.md): the round-0 planner, the local plan, the
hand-over, the oracle, the square's symmetries and distillation. Outside the wheel; the product never imports it.

Importing ``research`` registers its pieces with the product's plug-in points (``research.plugins.register``): the
``oracle`` policies, the loaders of its checkpoints, and ``research/models`` as a folder of named models, so that
``learned:planner_small_attention`` loads after ``import research``.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent
CONFIGS = ROOT / "configs"      # the research training configs (names resolve here first)
MODELS = ROOT / "models"        # the research models (``learned:<name>`` after the committed ones)

from research.plugins import register  # noqa: E402  (needs ROOT, CONFIGS and MODELS)

register()
