"""``taskalloc compare``: every baseline (and a committed learned policy) on the same seeds of a scenario.

    taskalloc compare --scenario default --episodes 20 --out results/compare

Rows: random, CBBA, CBAA and PI (only where every L_j = 1), CBGA, CBGA+TQ, CBGA+TB, CBGABI, the centralised greedy SGAMA
(thesis §3.3.3, Alg 7; no rounds or messages), the centralised group search LNS (``taskalloc.policies.local_search``,
ours: a lower bound on the optimum, how much there is to take) and the default learned rows ``DEFAULT_LEARNED`` (two
committed models, when their observation layout fits the scenario; ``--learned`` names others; ``--policy`` adds rows: a
policy name, or your own policy by import path ``mypkg.mymodule:MyPolicy``). Seed s is the same instance for every
row (paired design, thesis §5.3.1). The table gives mean ± sd of the score (``scoring.team_score``), valid tasks,
consensus rounds and messages received (``msgs / agent`` = messages / N_n, the thesis's per-agent communication steps),
episodes that hit the round bound (kept, counted), and the paired comparison with CBGA (mean difference, paired t-test
p-value, share of seeds won). ``--out DIR`` writes ``compare.md``, ``compare.csv`` (the table), ``episodes.csv`` and
``compare.png`` (score bars with sd; per-seed differences against CBGA); a folder that already holds files is refused
unless ``--overwrite`` is given.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from taskalloc.evaluation.distributed import BACKENDS
from taskalloc.evaluation.episodes import Episode, default_jobs, policy_for, run_episodes, skip_reason, solver_name
from taskalloc.evaluation.report import (
    bar_and_differences,
    cell_text,
    compare_cells,
    markdown_table,
    not_converged,
    refuse_existing,
    values,
    write_csv,
)
from taskalloc.evaluation.stats import format_p, mean_sd
from taskalloc.policies.checkpoint import CheckpointError
from taskalloc_env import TaskAllocConfig, resolve_config, resources
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.errors import ConfigError

BASELINES = ("random", "cbba", "cbaa", "pi", "cbga", "cbga+tq", "cbga+tb", "cbgabi", "sgama", "lns")
REFERENCE = "CBGA"
COLUMNS = (("score", "score"), ("valid_tasks", "valid tasks"), ("rounds", "rounds"),
           ("comm_steps_to_agreement", "msgs / agent to agreement"), ("comm_steps", "msgs / agent to the end"))


# the learned rows of the default comparison (docs/decisions.md, "Product and research"): the best plain bidder
# (MAPPO, pooling actor, 1 M steps) and the SB3 PPO bidder
DEFAULT_LEARNED = ("mappo_small_pooling_1m", "train_small")


def learned_checkpoints() -> list[str]:
    """The default learned rows that are committed models (``models/<name>/model.json``)."""
    return [name for name in DEFAULT_LEARNED if (resources.folder("models") / name / "model.json").is_file()]


def start_on(solver: str, cfg: TaskAllocConfig) -> None:
    """Load ``solver``'s policy and start it on ``cfg``'s first instance (raises what loading or starting raises)."""
    policy = policy_for(solver)
    env = TaskAllocEnv(cfg, **policy.env_overrides)
    env.reset(seed=0)
    policy.start(env, 0)


def usable_learned(source: str, cfg: TaskAllocConfig) -> tuple[str | None, str]:
    """(solver name, '') if the checkpoint loads and fits ``cfg``'s observations, else (None, why not)."""
    solver = f"learned:{source}"
    try:
        start_on(solver, cfg)
    except ImportError as exc:
        return None, f"it needs the learned extra: pip install taskalloc[learned] ({exc})"
    except CheckpointError as exc:
        return None, f"the checkpoint cannot be loaded ({exc})"
    except ValueError as exc:
        return None, f"it does not fit this scenario ({exc})"
    return solver, ""


def chosen_policy(name: str, cfg: TaskAllocConfig) -> str:
    """A ``--policy`` row: a policy name or a user's import path (``mypkg.mymodule:MyPolicy``) that loads and starts on
    ``cfg``; else a ``ConfigError`` naming it (the user asked for this row, so it is not skipped)."""
    try:
        start_on(name, cfg)
    except ValueError as exc:
        raise ConfigError(f"--policy: {exc}") from None
    return name


def display_name(solver: str) -> str:
    if solver.startswith("learned:"):
        source = solver.split(":", 1)[1]
        path = Path(source)
        label = source if resources.is_name(source) else path.parent.name if path.name == "model.json" else path.stem
        return f"learned ({label})"
    return solver_name(solver)


def summary(rows: Sequence[dict[str, Any]], order: Sequence[str]) -> tuple[str, list[dict[str, Any]]]:
    """The markdown table and its CSV records (one per policy, in ``order``)."""
    cells = {name: [r for r in rows if r["policy"] == name] for name in order}
    reference = cells.get(REFERENCE)
    body, records = [], []
    for name in order:
        cell = cells[name]
        record: dict[str, Any] = {"policy": name, "episodes": len(cell), "not_converged": not_converged(cell)}
        texts = []
        for metric, _ in COLUMNS:
            mean, sd = mean_sd(values(cell, metric)) if cell[0].get(metric) is not None else (None, None)
            record[f"{metric}_mean"], record[f"{metric}_sd"] = mean, sd
            texts.append(cell_text(cell, metric).split(" (")[0])
        paired = ["–", "–", "–"]
        if reference is not None and name != REFERENCE:
            pc = compare_cells(cell, reference, "score")
            record.update(diff_vs_cbga=pc.mean_diff, p_t_vs_cbga=pc.p_t, p_wilcoxon_vs_cbga=pc.p_wilcoxon,
                          beats_cbga=pc.better, ties_cbga=pc.tied)
            paired = [f"{pc.mean_diff:+.0f}", format_p(pc.p_t), f"{100 * pc.better:.0f} %"]
        body.append([name, *texts, record["not_converged"], *paired])
        records.append(record)
    header = ["policy", *(label for _, label in COLUMNS), "not conv.", f"Δ vs {REFERENCE}", "p (t)",
              f"beats {REFERENCE}"]
    return markdown_table(header, body), records


def compare(scenario: str, episodes: int, overrides: dict[str, Any], jobs: int = 1, out: Path | None = None,
            learned: Sequence[str] | None = None, progress: bool = False, backend: str = "local",
            policies: Sequence[str] = ()) -> str:
    """Run the comparison; returns the report text (also written to ``out`` when given). ``learned`` None: the default
    learned rows, each skipped with a note where it does not apply; a policy named in ``learned`` that cannot run is a
    ``ConfigError``. ``policies`` adds rows: policy names or import paths (``chosen_policy``)."""
    cfg = resolve_config(scenario, **overrides)
    notes, solvers = [], []
    for solver in BASELINES:
        reason = skip_reason(solver, cfg)
        if reason:
            notes.append(f"{solver_name(solver)}: not run: {reason}.")
        else:
            solvers.append(solver)
    checkpoints = learned_checkpoints() if learned is None else list(learned)
    if not checkpoints:
        notes.append("learned policy: no committed model (models/<name>/model.json), row left out.")
    for path in checkpoints:
        solver, why = usable_learned(path, cfg)
        if solver:
            solvers.append(solver)
        elif learned is not None:           # asked for by name: an error, before any episode runs
            raise ConfigError(f"--learned {path}: {why}")
        else:                               # a committed model that does not apply here: a note
            notes.append(f"learned policy {path}: skipped, {why}.")
    solvers += [chosen_policy(name, cfg) for name in policies]
    labels = [display_name(s) for s in solvers]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise ConfigError(f"--policy: a row would appear twice ({', '.join(twice)}); give each policy once")
    names = dict(zip(solvers, labels))
    runs = [Episode(s, cfg, seed, (("policy", names[s]),)) for s in solvers for seed in range(episodes)]
    rows = run_episodes(runs, jobs=jobs, progress=progress, desc="compare", backend=backend)
    table, records = summary(rows, [names[s] for s in solvers])
    setting = (f"Scenario `{scenario}`{''.join(f', {k}={v}' for k, v in overrides.items())}: {cfg.n_agents} agents, "
               f"{cfg.n_tasks} tasks, L_j = {_agents_text(cfg)}; {episodes} paired seeds (0–{episodes - 1}).")
    legend = ("score = rewards of valid tasks − travel cost (thesis §5.3.1); msgs / agent = messages received "
              "(one per sender → receiver per round) / N_n, the thesis's communication steps, counted until the last "
              "change (to agreement: every agent then holds the final solution, the thesis's stop) and until the "
              "episode ends (D + 1 quiet rounds later); not conv. = episodes that hit the round bound (kept in the "
              "means); SGAMA and LNS (a lower bound on the optimum, ours) are centralised (no rounds or messages). "
              "Δ, p (paired t-test) and beats (share of seeds "
              f"with a higher score) are against {REFERENCE} on the same seeds.")
    text = "\n".join([setting, "", table, legend, *(f"- {n}" for n in notes)]) + "\n"
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "compare.md").write_text(f"# Policy comparison\n\n{text}\n![scores](compare.png)\n")
        write_csv(out / "compare.csv", records)
        write_csv(out / "episodes.csv", rows)
        cells = {name: [r for r in rows if r["policy"] == name] for name in names.values()}
        bar_and_differences(out / "compare.png", cells, REFERENCE if REFERENCE in cells else None, "score",
                            f"{scenario}: score over {episodes} paired seeds")
    return text


def _agents_text(cfg: TaskAllocConfig) -> str:
    if cfg.task_mix:
        return "/".join(str(m.required_agents) for m in cfg.task_mix) + " (task mix)"
    apt = cfg.agents_per_task
    return "{" + ", ".join(map(str, apt)) + "}" if isinstance(apt, tuple) else str(apt)


def _override(text: str) -> tuple[str, Any]:
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"--set takes FIELD=VALUE, got {text!r}")
    key, value = text.split("=", 1)
    try:
        return key.strip(), yaml.safe_load(value)
    except yaml.YAMLError as exc:                   # a tag such as !!python/object, or a parse error
        raise argparse.ArgumentTypeError(f"--set {key.strip()}: not a plain YAML value "
                                         f"({str(exc).splitlines()[0]})") from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="default", help="scenario name (configs/scenarios) or YAML path")
    parser.add_argument("--episodes", type=int, default=20, help="paired seeds 0..N-1 (default 20)")
    parser.add_argument("--set", dest="overrides", type=_override, action="append", default=[],
                        metavar="FIELD=VALUE", help="config override, e.g. --set agents_per_task=1 (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="write compare.md/.csv/.png and episodes.csv here "
                        "(a folder that holds files is refused unless --overwrite)")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an existing --out folder")
    parser.add_argument("--jobs", type=int, default=default_jobs(),
                        help=f"worker processes (default: every core, {default_jobs()} here)")
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help="local: --jobs processes on this machine; ray: Ray tasks on a local Ray instance, or on "
                             "the cluster RAY_ADDRESS names (pip install taskalloc[ray]); the same table either way")
    parser.add_argument("--learned", action="append", default=None, metavar="NAME_OR_PATH",
                        help="a learned policy to include: a committed model's name or a checkpoint path "
                             "(repeatable; default: " + " and ".join(DEFAULT_LEARNED) + ")")
    parser.add_argument("--policy", dest="policies", action="append", default=[], metavar="NAME_OR_PATH",
                        help="add a row: a policy name (cbgabi:delta=3, learned:NAME) or your own policy by import "
                             "path, mypkg.mymodule:MyPolicy (a class, an object with act, or a function of the "
                             "observations; repeatable)")
    parser.add_argument("--no-learned", action="store_true", help="leave learned policies out")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True,
                        help="show a progress bar on stderr (default: yes)")


def run(args: argparse.Namespace) -> int:
    if args.episodes < 2:
        raise ConfigError(f"--episodes: got {args.episodes}; allowed: an integer >= 2 (standard deviations and paired "
                          "tests need two seeds)")
    if args.jobs < 1:
        raise ConfigError(f"--jobs: got {args.jobs}; allowed: an integer >= 1")
    if args.out is not None:
        refuse_existing(args.out, args.overwrite)
    started = time.perf_counter()
    learned = [] if args.no_learned else args.learned
    text = compare(args.scenario, args.episodes, dict(args.overrides), args.jobs, args.out, learned, args.progress,
                   args.backend, args.policies)
    print(text, end="")
    if args.out is not None:
        print(f"written: {args.out}/compare.md, compare.csv, episodes.csv, compare.png")
    print(f"({time.perf_counter() - started:.1f} s)", file=sys.stderr)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``taskalloc compare [ARGS]``."""
    parser = argparse.ArgumentParser(prog="taskalloc compare", description=__doc__.split("\n\n")[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))
