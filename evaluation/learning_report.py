"""The tables and curves of ``docs/learning.md``: learned configurations, several training seeds each, against the
baselines on held-out instances.

    taskalloc learning-report evaluate                  # every setting; writes results/learning/
    taskalloc learning-report evaluate --only train_small --episodes 200 --jobs 2 [--backend ray]
    taskalloc learning-report render                    # rewrites the generated blocks of the doc

``evaluate`` plays every row of a setting on the held-out seeds 10000 … (``taskalloc.evaluation.seeds.TEST_SEEDS``),
through the experiment runner's ``run_episodes`` (seed s is the same instance for every row; ``--backend ray`` fans out
over Ray), and writes per-seed figures to ``results/learning/heldout_<setting>.json``. Rows: the baselines (random,
CBGA, CBGABI, SGAMA, LNS (``taskalloc.policies.local_search``, a lower bound on the optimum at every size), the exact
optimum where it is tractable, the oracle that bids along the optimum through the protocol and behaviour cloning of
CBGABI — both research's, played when ``research`` is imported, else kept from the results file — and, per learned
configuration, one row per training seed,
read from ``<runs>/<config>/seed<k>`` (the training commands' ``--out-dir``; ``models/<name>`` for seeds that are
committed models). It also copies each run's ``eval.csv`` and ``summary.yaml`` to ``results/learning/runs/``, so that
``render`` needs nothing outside the repository. Rows already in the results file are kept while their weights are
unchanged, and so is the row of a training seed whose model is no longer on disk. ``loss_small`` plays the
``train_small`` instances under 20 % message loss, with the same loss draws for every row, and ``delay_small`` with
every message delayed by 0–2 extra rounds, with the same delay draws (``delay_default``: the default scenario under that
delay); their centralised rows (SGAMA, LNS, the exact optimum) are copied from the perfect-link set of the same
instances.

``render`` computes, per learned configuration, the mean over its seeds of each seed's mean score with a 95 %
t-interval across seeds (Student t, k − 1 degrees of freedom), and per seed the paired comparison with CBGABI
(and SGAMA, and the optimum) on the same instances: mean difference, paired t-test p-value and the share of the
instances where they differ that the learned policy wins. The learning curves (validation seeds, against CBGABI
on the same seeds) show the mean over seeds and the 95 % interval across seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import re
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import stats

from taskalloc.evaluation.curves import plot_bands, read_eval
from taskalloc.evaluation.distributed import BACKENDS
from taskalloc.evaluation.episodes import CENTRALISED, Episode, default_jobs, run_episodes, skip_reason
from taskalloc.evaluation.report import markdown_table
from taskalloc.evaluation.stats import format_p, paired
from taskalloc.policies.learned import named_model
from taskalloc.policies.registry import make_policy
from taskalloc_env import resolve_config
from taskalloc_env.errors import ConfigError, run_cli

OUT = Path("results") / "learning"
DOC = Path("docs") / "learning.md"
CURVES = Path("docs") / "learning_curves.png"
SEEDS = (0, 1, 2)
FIGURES = ("score", "valid_tasks", "rounds", "messages")


@dataclasses.dataclass(frozen=True)
class Config:
    """A learned configuration: its label, the folder name of its runs, and where each training seed's model is."""

    label: str
    name: str
    committed: Mapping[int, str] = dataclasses.field(default_factory=dict)    # seed → named model

    def checkpoint(self, seed: int, runs: Path) -> Path:
        """A named model's folder (committed, or in a registered folder), else ``<runs>/<name>/seed<seed>``."""
        found = named_model(self.committed[seed]) if seed in self.committed else None
        return Path(str(found)).parent if found is not None else runs / self.name / f"seed{seed}"


SB3 = Config("SB3 MaskablePPO, pooling, local critic", "train_small", {0: "train_small"})
POOLING = Config("MAPPO, pooling actor, state critic", "mappo_small_pooling", {0: "mappo_small_pooling"})
POOLING_1M = Config("MAPPO, pooling actor, state critic, 1 M steps", "mappo_small_pooling_1m",
                    {0: "mappo_small_pooling_1m"})
POOLING_3M = Config("MAPPO, pooling actor, state critic, 3 M steps", "mappo_small_pooling_3m")
TEAM = Config("MAPPO pooling, 1 M steps, team features (our observation option)", "mappo_small_pooling_team")
ATTENTION = Config("MAPPO, attention actor, state critic", "mappo_small", {0: "mappo_small"})
ATTENTION_1M = Config("MAPPO, attention actor, state critic, 1 M steps", "mappo_small_1m")
MIXTURE = Config("MAPPO attention, curriculum 4×8 → 10×20", "mappo_mixture")
LOSS = Config("MAPPO attention, trained under 20 % loss", "mappo_loss")
LOSS_POOLING = Config("MAPPO pooling, trained under 20 % loss", "mappo_loss_pooling")
MIXTURE_POOLING = Config("MAPPO pooling, curriculum 4×8 → 10×20", "mappo_mixture_pooling")
DELAY_POOLING = Config("MAPPO pooling, trained under message delay (0–2 rounds)", "mappo_delay_pooling")


@dataclasses.dataclass(frozen=True)
class Setting:
    """Held-out instances of one scenario (with overrides), the baselines and the configurations played on them."""

    name: str
    title: str
    scenario: str
    overrides: Mapping[str, Any]
    configs: tuple[Config, ...]
    baselines: tuple[str, ...] = ("random", "cbga", "cbgabi", "sgama", "lns", "exact", "oracle")
    behaviour_cloning: bool = False
    # a setting on the same instances with only network overrides: its centralised rows (SGAMA, LNS, the optimum)
    # send no message, so they are copied from there instead of being solved again
    centralised_from: str | None = None


SETTINGS = {s.name: s for s in (
    Setting("train_small", "training scenario, 4 × 8, L_j ∈ {1, 2}", "train_small", {},
            (SB3, POOLING, POOLING_1M, POOLING_3M, TEAM, ATTENTION, ATTENTION_1M, MIXTURE, MIXTURE_POOLING),
            behaviour_cloning=True),
    Setting("default", "default scenario, 10 × 20, L_j = 4", "default", {},
            (SB3, POOLING, POOLING_1M, POOLING_3M, TEAM, ATTENTION, ATTENTION_1M, MIXTURE, MIXTURE_POOLING)),
    Setting("size_8x16", "8 × 16, L_j = 3 (no model trained on it)", "default",
            {"n_agents": 8, "n_tasks": 16, "agents_per_task": 3}, (POOLING_1M, ATTENTION, MIXTURE)),
    Setting("size_20x40", "20 × 40, L_j = 4 (no model trained on it)", "default",
            {"n_agents": 20, "n_tasks": 40}, (POOLING, POOLING_1M, ATTENTION, MIXTURE)),
    # the same instances as train_small (the scenario is drawn before the network's generator is spawned) under
    # 20 % loss; every row sees the same loss draws: the synchronous protocol sends every alive agent's message to
    # every neighbour in every round, so the k-th draw of an episode is the same (round, sender, receiver)
    # whatever the policy (tests/test_learning_report.py). SB3 and MAPPO models were trained on perfect links.
    Setting("loss_small", "training scenario under 20 % message loss", "train_small", {"message_loss": 0.2},
            (SB3, POOLING, ATTENTION, LOSS, LOSS_POOLING), behaviour_cloning=True, centralised_from="train_small"),
    Setting("loss_default", "default scenario under 20 % message loss (a size mappo_loss never trained on)",
            "default", {"message_loss": 0.2}, (LOSS, LOSS_POOLING)),
    # the same instances again, every message delayed by 0..2 extra rounds; as under loss, every row sees the same
    # delay draws in the rounds it plays (the same messages are sent in every round, tests/test_learning_report.py)
    Setting("delay_small", "training scenario with message delays of 0–2 rounds", "train_small", {"max_delay": 2},
            (SB3, POOLING_1M, ATTENTION, LOSS_POOLING, DELAY_POOLING), behaviour_cloning=True,
            centralised_from="train_small"),
    Setting("delay_default", "default scenario with message delays of 0–2 rounds (a size no model trained on)",
            "default", {"max_delay": 2}, (POOLING_1M, DELAY_POOLING), centralised_from="default"),
)}
# every configuration of the settings, once, in the order they first appear: the rows of the training table
CONFIGS = tuple({config.name: config for setting in SETTINGS.values() for config in setting.configs}.values())
NAMES = {"random": "random", "cbga": "CBGA", "cbgabi": "CBGABI", "sgama": "SGAMA (centralised greedy)",
         "lns": "LNS (centralised group search, ours)",
         "exact": "exact optimum", "oracle": "oracle: the optimum's paths bid through the protocol (privileged)",
         "bc": "behaviour cloning of CBGABI (SB3, 1 seed)"}


# -- evaluate ----------------------------------------------------------------------------------------------------
def fingerprint(folder: Path) -> str:
    """A short hash of a checkpoint's weights (so that a retrained model is never confused with an old one)."""
    weights = folder / "model.safetensors" if folder.is_dir() else folder.with_suffix(".safetensors")
    return hashlib.sha1(weights.read_bytes()).hexdigest()[:12]


def shown(path: Path) -> str:
    """A path relative to the working directory when it lies inside it (JSON files then do not name the machine)."""
    return os.path.relpath(path) if path.resolve().is_relative_to(Path.cwd()) else str(path)


def rows_to_run(setting: Setting, runs: Path,
                archived: Mapping[tuple[str, int], Mapping[str, Any]] | None = None) -> list[dict[str, Any]]:
    """Every row of a setting: label, kind, solver name; learned rows carry their configuration and seed.

    A training seed whose model is no longer on disk keeps its row from ``archived`` (the rows of the results
    file, by label and seed), so that evaluating new seeds does not drop the figures of runs whose weights were
    not kept."""
    cfg = resolve_config(setting.scenario, **setting.overrides)
    rows = [{"label": NAMES[b], "kind": "centralised" if b in CENTRALISED else "baseline", "solver": b}
            for b in setting.baselines if not skip_reason(b, cfg)]
    if setting.behaviour_cloning:
        bc = named_model("train_small_bc")     # research's: a kept row stays when it is not registered
        where = shown(Path(str(bc)).parent / "bc.json") if bc is not None else "train_small_bc/bc.json"
        rows.append({"label": NAMES["bc"], "kind": "baseline", "solver": f"learned:{where}"})
    for config in setting.configs:
        for seed in SEEDS:
            folder = config.checkpoint(seed, runs)
            if not (folder / "model.json").is_file():
                old = (archived or {}).get((config.label, seed))
                if old is not None:
                    print(f"{setting.name}: {config.label}, seed {seed}: no model at {folder}, the archived row "
                          f"(weights {old.get('weights')}) is kept", flush=True)
                    rows.append(dict(old))
                else:
                    print(f"{setting.name}: {config.label}, seed {seed}: no model at {folder}, left out", flush=True)
                continue
            where = shown(folder)
            rows.append({"label": config.label, "kind": "learned", "config": config.name, "seed": seed,
                         "solver": f"learned:{where}", "weights": fingerprint(folder), "folder": where})
    return rows


def evaluate(setting: Setting, episodes: int, jobs: int, backend: str, runs: Path, out: Path,
             recompute: bool) -> Path:
    """Play every row of ``setting`` on the held-out seeds; rows already in the JSON (same weights) are kept."""
    from taskalloc.evaluation.seeds import TEST_SEEDS

    seeds = list(range(TEST_SEEDS.start, TEST_SEEDS.start + episodes))
    path = out / f"heldout_{setting.name}.json"
    old = json.loads(path.read_text()) if path.exists() and not recompute else {}
    kept = {_key(r): r for r in old.get("rows", [])} if old.get("seeds") == seeds else {}
    cfg = resolve_config(setting.scenario, **setting.overrides)
    results = []
    archived = {(r["label"], r["seed"]): r for r in kept.values() if r["kind"] == "learned"}
    source = out / f"heldout_{setting.centralised_from}.json" if setting.centralised_from else None
    source_data = json.loads(source.read_text()) if source is not None and source.exists() else {}
    centralised = {r["label"]: r for r in source_data.get("rows", []) if r["kind"] == "centralised"} \
        if source_data.get("seeds") == seeds else {}
    for row in rows_to_run(setting, runs, archived):
        if _key(row) in kept:
            results.append(kept[_key(row)])
            continue
        if row["kind"] == "baseline" and not playable(row["solver"]):
            print(f"{setting.name}: {row['label']}: left out, {row['solver']} is not registered (a research "
                  "policy or model: run with research imported)", flush=True)
            continue
        if row["kind"] == "centralised" and row["label"] in centralised:
            results.append({**centralised[row["label"]], "copied_from": setting.centralised_from})
            print(f"{setting.name}: {row['label']}: copied from {shown(source)} (it sends no message)", flush=True)
            continue
        played = run_episodes([Episode(row["solver"], cfg, s) for s in seeds], jobs=jobs, backend=backend,
                              desc=f"{setting.name}: {row['label']}" + (f" seed {row['seed']}" if "seed" in row
                                                                        else ""))
        results.append({**row, **{f: [e[f] for e in played] for f in FIGURES}})
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps({"setting": setting.name, "seeds": seeds, "rows": results}, indent=0) + "\n")
    for row in results:     # kept rows too: their logs are archived even if an earlier evaluation did not do it
        if row["kind"] == "learned" and (Path(row["folder"]) / "model.json").is_file():
            archive_logs(Path(row["folder"]), out / "runs" / row["config"] / f"seed{row['seed']}")
    path.write_text(json.dumps({"setting": setting.name, "seeds": seeds, "rows": results}, indent=0) + "\n")
    return path


def playable(solver: str) -> bool:
    """Whether a baseline's policy can be built here (a plug-in's only once it is registered)."""
    try:
        make_policy(solver)
    except ValueError:
        return False
    return True


def _key(row: Mapping[str, Any]) -> tuple:
    return row["label"], row.get("seed"), row.get("weights")


def archive_logs(folder: Path, target: Path) -> None:
    """A run's learning curve (``eval.csv``; a planner's ``planner.csv``) and summary, kept in the repository for
    ``render``."""
    target.mkdir(parents=True, exist_ok=True)
    for name in ("eval.csv", "planner.csv", "summary.yaml", "config.yaml"):
        if (folder / name).is_file():
            shutil.copyfile(folder / name, target / name)


# -- render ------------------------------------------------------------------------------------------------------
def across_seeds(values: Sequence[float]) -> tuple[float, float]:
    """Mean over training seeds and the half-width of its 95 % t-interval (nan for a single seed)."""
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        return float(x.mean()), float("nan")
    return float(x.mean()), float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size))


def _pm(mean: float, half: float, digits: int = 1, unit: str = "") -> str:
    return f"{mean:.{digits}f}{unit}" if np.isnan(half) else f"{mean:.{digits}f} ± {half:.{digits}f}{unit}"


def wins_where_different(a: np.ndarray, b: np.ndarray) -> str:
    """Wins of a over b among the instances where they differ, as ``w / (w + l)``."""
    d = a - b
    wins, losses = int((d > 1e-9).sum()), int((d < -1e-9).sum())
    return f"{wins}/{wins + losses}" if wins + losses else "–"


def heldout_table(data: Mapping[str, Any]) -> str:
    """Baselines: mean ± sd over instances. Learned configurations: mean ± 95 % CI across training seeds, and per
    seed the paired comparison with CBGABI (Δ, p, wins where they differ) and with SGAMA. Where the optimum is out
    of reach, the share of the optimum gives way to the share of the LNS score, the best allocation known."""
    rows = data["rows"]
    ref = {r["label"]: np.asarray(r["score"], dtype=float) for r in rows if r["kind"] != "learned"}
    cbgabi, sgama = ref[NAMES["cbgabi"]], ref.get(NAMES["sgama"])
    opt = ref.get(NAMES["exact"])
    best = opt if opt is not None else ref.get(NAMES["lns"])
    head = ["policy", "seeds", "score", "% of CBGABI", "% of optimum" if opt is not None else "% of LNS",
            "Δ vs CBGABI per seed (p)",
            "wins vs CBGABI where they differ", "Δ vs SGAMA per seed (p)"] + \
        ([] if opt is None else ["Δ vs optimum per seed (p)"]) + ["rounds", "messages"]
    body = []
    for r in rows:
        if r["kind"] == "learned":
            continue
        s = np.asarray(r["score"], dtype=float)
        pc = paired(s, cbgabi)
        vs_sgama = "–" if sgama is None or r["label"] == NAMES["sgama"] else \
            f"{paired(s, sgama).mean_diff:+.1f} ({format_p(paired(s, sgama).p_t)})"
        body.append([r["label"], "–", f"{s.mean():.1f} ± {s.std(ddof=1):.1f} sd", f"{100 * pc.ratio:.1f} %",
                     "–" if best is None else f"{100 * s.mean() / best.mean():.1f} %",
                     "–" if r["label"] == NAMES["cbgabi"] else f"{pc.mean_diff:+.1f} ({format_p(pc.p_t)})",
                     "–" if r["label"] == NAMES["cbgabi"] else wins_where_different(s, cbgabi),
                     vs_sgama, *_versus(s, opt, r["label"] == NAMES["exact"]), *_protocol(r)])
    for label in dict.fromkeys(r["label"] for r in rows if r["kind"] == "learned"):
        runs = [r for r in rows if r["label"] == label]
        means = [float(np.mean(r["score"])) for r in runs]
        scores = [np.asarray(r["score"], dtype=float) for r in runs]
        vs = [paired(s, cbgabi) for s in scores]
        of_best = "–" if best is None else _pm(*across_seeds([100 * m / best.mean() for m in means]), unit=" %")
        body.append([f"**{label}**", len(runs), _pm(*across_seeds(means)) + " (95 % CI, seeds)",
                     _pm(*across_seeds([100 * p.ratio for p in vs]), unit=" %"), of_best,
                     "; ".join(f"{p.mean_diff:+.1f} ({format_p(p.p_t)})" for p in vs),
                     "; ".join(wins_where_different(s, cbgabi) for s in scores),
                     "–" if sgama is None else "; ".join(f"{paired(s, sgama).mean_diff:+.1f} "
                                                          f"({format_p(paired(s, sgama).p_t)})" for s in scores),
                     *([] if opt is None else ["; ".join(_versus(s, opt)[0] for s in scores)]), *_protocol_mean(runs)])
    seeds = data["seeds"]
    copied = [r for r in rows if r.get("copied_from")]
    labels = [r["label"] for r in copied]
    note = "" if not copied else (" " + ", ".join(labels[:-1]) + " and " * (len(labels) > 1) + labels[-1]
                                  + f": the rows of the "
                                  f"`{copied[0]['copied_from']}` set (they send no message, so the network "
                                  "cannot change them).")
    return (f"Held-out seeds {seeds[0]}–{seeds[-1]} ({len(seeds)} instances, the same for every row).{note}\n\n"
            + markdown_table(head, body, align="lr" + "r" * (len(head) - 2)))


def _versus(s: np.ndarray, opt: np.ndarray | None, itself: bool = False) -> list[str]:
    """The paired difference with the exact optimum and its p-value (nothing when there is no optimum)."""
    if opt is None:
        return []
    if itself:
        return ["–"]
    p = paired(s, opt)
    return [f"{p.mean_diff:+.1f} ({format_p(p.p_t)})"]


def _protocol(row: Mapping[str, Any]) -> list[str]:
    if row["kind"] == "centralised":
        return ["–", "–"]
    return [f"{np.mean(row['rounds']):.2f}", f"{np.mean(row['messages']):.1f}"]


def _protocol_mean(runs: Sequence[Mapping[str, Any]]) -> list[str]:
    return [f"{np.mean([np.mean(r['rounds']) for r in runs]):.2f}",
            f"{np.mean([np.mean(r['messages']) for r in runs]):.1f}"]


def plot_curves(out: Path, runs_dir: Path, configs: Sequence[Config]) -> None:
    """Validation score / CBGABI's against agent steps: mean over seeds and the 95 % interval across seeds."""
    every = {config.label: [read_eval(p) for p in sorted((runs_dir / config.name).glob("seed*/eval.csv"))]
             for config in configs}
    entries = [e for e in ("train_small", "6x12", "default", "train_small_loss20")
               if any(e in c for curves in every.values() for c in curves)] or ["train_small"]
    plot_bands(out, every, entries)


def training_table(runs_dir: Path, configs: Sequence[Config]) -> str:
    """Per run: agent steps, wall and CPU seconds, agent steps per second, the load average when it started."""
    body = []
    for config in configs:
        for path in sorted((runs_dir / config.name).glob("seed*/summary.yaml")):
            s = yaml.safe_load(path.read_text())
            ppo = s.get("ppo", {})
            steps = s.get("steps", ppo.get("steps"))
            seconds = s.get("train_seconds", ppo.get("seconds"))
            # a planner (research.training.planner) learns from labelled states, not from agent steps
            body.append([config.label, path.parent.name.removeprefix("seed"),
                         "–" if steps is None else f"{steps:,}".replace(",", " "),
                         f"{s['wall_seconds'] / 60:.1f}", f"{s['cpu_seconds'] / 60:.1f}" if "cpu_seconds" in s else
                         "–", "–" if steps is None else f"{steps / seconds:.0f}", s.get("load_average_at_start", "–"),
                         ", ".join(s.get("init_from", [])) or "–"])
    return markdown_table(["configuration", "seed", "agent steps", "wall min", "CPU min", "agent steps/s",
                           "load at start", "continues (actor, critic)"], body)


def room_table(datas: Mapping[str, Mapping[str, Any]]) -> str:
    """Per setting: how far above CBGABI the best allocation known lies (the optimum, else LNS, a lower bound on it)
    and how much of that room the best learned configuration (by its mean over seeds; among those with every
    training seed when there are any) takes."""
    body = []
    for name, data in datas.items():
        rows = data["rows"]
        ref = {r["label"]: np.mean(r["score"]) for r in rows if r["kind"] != "learned"}
        cbgabi, lns, opt = ref[NAMES["cbgabi"]], ref.get(NAMES["lns"]), ref.get(NAMES["exact"])
        best = opt if opt is not None else lns
        learned = {}
        for r in rows:
            if r["kind"] == "learned":
                learned.setdefault(r["label"], []).append(float(np.mean(r["score"])))
        complete = {k: v for k, v in learned.items() if len(v) == len(SEEDS)} or learned
        label, mean = max(((f"{k} ({len(v)} seed{'s' if len(v) > 1 else ''})", float(np.mean(v)))
                           for k, v in complete.items()), key=lambda kv: kv[1], default=("–", float("nan")))
        share = "–" if best is None or best <= cbgabi or np.isnan(mean) else \
            f"{100 * (mean - cbgabi) / (best - cbgabi):.0f} %"
        body.append([f"`{name}`", f"{cbgabi:.1f}", "–" if lns is None else f"{100 * lns / cbgabi:.1f} %",
                     "–" if opt is None else f"{100 * opt / cbgabi:.1f} %", label,
                     "–" if np.isnan(mean) else f"{100 * mean / cbgabi:.1f} %", share])
    return markdown_table(["held-out set", "CBGABI", "LNS, % of CBGABI", "optimum, % of CBGABI",
                           "best learned configuration (mean over seeds)", "its % of CBGABI",
                           "share of the room above CBGABI it takes (to the optimum, else to LNS)"], body,
                          align="l" + "r" * 3 + "l" + "rr")


def replace_block(text: str, name: str, block: str) -> str:
    begin, end = f"<!-- learning:{name}:begin -->", f"<!-- learning:{name}:end -->"
    if begin not in text or end not in text:
        raise ConfigError(f"the doc has no {begin} … {end} block")
    return re.sub(re.escape(begin) + ".*?" + re.escape(end), lambda _: f"{begin}\n{block}\n{end}", text, flags=re.S)


def render(out: Path, doc: Path, curves: Path) -> None:
    text = doc.read_text()
    datas = {name: json.loads(path.read_text()) for name in SETTINGS
             if (path := out / f"heldout_{name}.json").exists()}
    for name, data in datas.items():
        text = replace_block(text, name, heldout_table(data))
    text = replace_block(text, "room", room_table(datas))
    text = replace_block(text, "training", training_table(out / "runs", CONFIGS))
    plot_curves(curves, out / "runs", CONFIGS)
    doc.write_text(text)
    print(f"rewrote {doc} and {curves}")


# -- command line ------------------------------------------------------------------------------------------------
def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="taskalloc learning-report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    ev = sub.add_parser("evaluate", help="play every row on the held-out seeds, write results/learning/*.json")
    ev.add_argument("--only", nargs="+", choices=sorted(SETTINGS), default=None, help="settings (default: all)")
    ev.add_argument("--episodes", type=int, default=200, help="held-out instances per setting (default 200)")
    ev.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes (default: every core)")
    ev.add_argument("--backend", choices=BACKENDS, default="local", help="local processes or Ray tasks")
    ev.add_argument("--runs", type=Path, default=Path("runs"),
                    help="folder of the training runs: <runs>/<config>/seed<k> (default runs)")
    ev.add_argument("--recompute", action="store_true", help="replay rows already in the JSON files")
    for p in (ev, sub.add_parser("render", help="rewrite the generated blocks of the doc and the curves")):
        p.add_argument("--out", type=Path, default=OUT, help=f"results folder (default {OUT})")
    rd = sub.choices["render"]
    rd.add_argument("--doc", type=Path, default=DOC, help=f"the markdown file to rewrite (default {DOC})")
    rd.add_argument("--curves", type=Path, default=CURVES, help=f"the learning-curve PNG (default {CURVES})")
    args = parser.parse_args(argv)
    if args.command == "render":
        render(args.out, args.doc, args.curves)
        return 0
    if args.episodes < 2 or args.jobs < 1:
        raise ConfigError("--episodes needs at least 2 instances and --jobs at least 1")
    for name in args.only or SETTINGS:
        path = evaluate(SETTINGS[name], args.episodes, args.jobs, args.backend, args.runs, args.out, args.recompute)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_cli(main))
