"""SB3 callbacks: episode metrics to TensorBoard, periodic evaluation against a scripted baseline, checkpoints, the
progress bar."""

from __future__ import annotations

import csv
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, ProgressBarCallback
from tqdm.rich import tqdm

from taskalloc.evaluation.episodes import evaluate, summarise
from taskalloc.policies.registry import make_policy
from taskalloc.policies.teams import with_teammates
from taskalloc.training.sb3_policy import as_learned, save_checkpoint
from taskalloc_env.env import TaskAllocEnv
from taskalloc_env.observation import ObservationLayout
from taskalloc_env.rewards import EPISODE_FIGURES

EVAL_COLUMNS = ("timesteps", "wall_time", "score", "score_std", "valid_tasks", "rounds", "messages",
                "baseline_score", "ratio")


class EpisodeMetricsCallback(BaseCallback):
    """Logs ``episode/<metric>`` means of finished episodes: every figure of the env's episode record
    (``taskalloc_env.rewards.EPISODE_FIGURES``: score, valid tasks, conflicts, rounds, messages, converged) that SB3's
    own ``rollout/ep_rew_mean`` and ``ep_len_mean`` (from ``r`` and ``l``) leave out."""

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", ()):
            record = info.get("episode")
            if record:
                for key in EPISODE_FIGURES:
                    self.logger.record_mean(f"episode/{key}", float(record[key]))
        return True


class PeriodicEvalCallback(BaseCallback):
    """Every ``eval_freq`` steps: the deterministic policy on fixed seeds vs ``baseline`` on the same seeds.

    Logs ``eval/score``, ``eval/baseline_score``, ``eval/ratio`` (and valid tasks, rounds, messages), appends a row
    to ``csv_path`` and saves the best model so far as a checkpoint at ``best_path`` (a stem).
    """

    def __init__(self, env_kwargs: Mapping[str, Any], seeds: Sequence[int], eval_freq: int, csv_path: Path,
                 best_path: Path | None = None, baseline: str = "cbgabi",
                 scripted_agents: Mapping[str, str] | None = None, meta: Mapping[str, Any] | None = None,
                 start_steps: int = 0, layout: ObservationLayout | None = None) -> None:
        super().__init__()
        self.env_kwargs, self.seeds, self.eval_freq = dict(env_kwargs), list(seeds), eval_freq
        self.csv_path, self.best_path, self.scripted_agents = Path(csv_path), best_path, dict(scripted_agents or {})
        self.meta = dict(meta or {})
        self.layout = layout or TaskAllocEnv(**self.env_kwargs).observation_layout
        self.start_steps = start_steps
        baseline_policy = with_teammates(make_policy(baseline), self.scripted_agents)
        self.baseline_score = summarise(evaluate(baseline_policy, self.env_kwargs, self.seeds))["score"]
        self.best = -np.inf
        self._next = 0
        self._t0 = time.perf_counter()

    def _on_training_start(self) -> None:
        self._t0 = time.perf_counter()
        if not self.csv_path.exists():
            self.csv_path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.csv_path, "w", newline="") as fh:
                csv.writer(fh).writerow(EVAL_COLUMNS)
        self._next = self.num_timesteps

    def evaluate_now(self) -> dict[str, float]:
        learned = as_learned(self.model.policy, self.layout, self.env_kwargs, name="current")
        stats = summarise(evaluate(with_teammates(learned, self.scripted_agents), self.env_kwargs, self.seeds))
        ratio = stats["score"] / self.baseline_score if self.baseline_score else float("nan")
        steps = self.start_steps + self.num_timesteps
        row = {"timesteps": steps, "wall_time": round(time.perf_counter() - self._t0, 2), **stats,
               "baseline_score": self.baseline_score, "ratio": ratio}
        with open(self.csv_path, "a", newline="") as fh:
            csv.writer(fh).writerow([row[c] for c in EVAL_COLUMNS])
        for key in ("score", "valid_tasks", "rounds", "messages"):
            self.logger.record(f"eval/{key}", stats[key])
        self.logger.record("eval/baseline_score", self.baseline_score)
        self.logger.record("eval/ratio", ratio)
        if stats["score"] > self.best:
            self.best = stats["score"]
            if self.best_path is not None:
                save_checkpoint(self.best_path, self.model.policy, self.layout, self.env_kwargs,
                                {**self.meta, "timesteps": steps, "validation_score": stats["score"]})
        return row

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.num_timesteps >= self._next:
            self.evaluate_now()
            self._next = self.num_timesteps + self.eval_freq
        return True

    def _on_training_end(self) -> None:
        self.evaluate_now()


class RolloutProgressBar(ProgressBarCallback):
    """SB3's progress bar with the total PPO reaches: the steps asked for rounded up to whole rollouts of
    ``rollout`` steps (SB3's own bar counts to the steps asked for and runs past its total)."""

    def __init__(self, rollout: int) -> None:
        super().__init__()
        self.rollout = rollout

    def _on_training_start(self) -> None:
        wanted = self.locals["total_timesteps"] - self.model.num_timesteps
        self.pbar = tqdm(total=-(-wanted // self.rollout) * self.rollout)
