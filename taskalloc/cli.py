"""The ``taskalloc`` console command: one subcommand per tool, each the ``main`` of the module that implements it.

``taskalloc --help`` lists them; ``taskalloc SUBCOMMAND --help`` shows one. Modules are imported only when their
subcommand runs, so ``taskalloc compare`` never loads the training stack. Bad input is one line and exit status 2.
"""

from __future__ import annotations

import difflib
import importlib
import sys
from collections.abc import Sequence

# subcommand -> (module with main(argv), one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "compare": ("taskalloc.evaluation.compare", "every baseline (and committed learned policies) on paired seeds"),
    "experiments": ("taskalloc.evaluation.experiments", "run, report and list the sources' experiments (YAML)"),
    "benchmark": ("taskalloc.evaluation.benchmark", "any policy on the task suite v0: normalised scores, one protocol"),
    "fuzz": ("taskalloc.evaluation.fuzz", "random scenarios over every option and policy against the invariants"),
    "robustness": ("taskalloc.evaluation.robustness", "each algorithm under message loss, episode by episode"),
    "dropout": ("taskalloc.evaluation.dropout", "one agent fails mid-auction against a team it was never in"),
    "convergence": ("taskalloc.evaluation.convergence", "how often greedy CBGA converges under each bid option"),
    "acbba-experiments": ("taskalloc.evaluation.acbba_experiments", "Johnson's ACBBA experiments (Figs 4-2 to 4-5)"),
    "acbba-check": ("taskalloc.evaluation.acbba_check", "ACBBA against synchronous CBBA on random static scenarios"),
    "figures": ("taskalloc.evaluation.figures", "figures of single instances: ranges, links, the assignment"),
    "heldout": ("taskalloc.evaluation.heldout", "baselines, solvers and learned checkpoints on held-out seeds"),
    "learning-report": ("taskalloc.evaluation.learning_report", "the tables and curves of docs/learning.md"),
    "train": ("taskalloc.training.train", "train a shared bidding policy with SB3 (Maskable)PPO"),
    "mappo": ("taskalloc.training.mappo", "train with MAPPO: decentralised actors, a centralised critic"),
    "rllib": ("taskalloc.training.rllib_ppo", "train with RLlib PPO (the ray extra)"),
    "benchmarl": ("taskalloc.training.benchmarl_mappo", "train with BenchMARL MAPPO (its own venv), export the actor"),
    "curves": ("taskalloc.training.curves", "learning curves from training runs' eval.csv"),
    "checkpoint": ("taskalloc.policies.checkpoint", "inspect or convert a learned policy's checkpoint"),
}

# top-level packages of the optional extras (pyproject.toml) -> the extra that installs them
EXTRAS = {"torch": "learned", "safetensors": "learned", "stable_baselines3": "train", "sb3_contrib": "train",
          "tensorboard": "train", "ray": "ray"}


def usage() -> str:
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items())
    return f"usage: taskalloc SUBCOMMAND [ARGS ...]\n\nsubcommands:\n{rows}\n\n'taskalloc SUBCOMMAND --help' for one."


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``argv`` (default ``sys.argv[1:]``) to its subcommand; exit status as the subcommand returns it."""
    from taskalloc_env.errors import run_cli

    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in {"-h", "--help"}:
        print(usage())
        return 0 if args else 2
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        close = difflib.get_close_matches(name, COMMANDS, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        print(f"taskalloc: unknown subcommand {name!r}{hint}; choose from: {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(COMMANDS[name][0])
    except ModuleNotFoundError as exc:         # an optional extra (ray for rllib) that is not installed
        extra = EXTRAS.get(exc.name or "")
        if extra is None:
            raise
        print(f"taskalloc {name}: needs the Python package {exc.name!r}, which is not installed "
              f"(pip install 'taskalloc[{extra}]')", file=sys.stderr)
        return 1
    return run_cli(lambda: module.main(rest))


if __name__ == "__main__":
    raise SystemExit(main())
