"""A training run's directory: config, episode rows, metrics, replay episodes, checkpoint, summary.

Layout (files written whole go through a temporary file and a rename; the two logs,
``episodes.csv`` and ``metrics.jsonl``, are appended a line at a time, so a kill never leaves
a file half-written except, at worst, the last line of a log)::

    <run>/config.json       the resolved config the run started with
    <run>/episodes.csv      one row per finished episode (:data:`EPISODE_COLUMNS`)
    <run>/metrics.jsonl     one JSON object per logged point of training metrics (below)
    <run>/replay/NNNNNN.pt  the stored rows of every episode inserted into the replay buffer
    <run>/positives/EEEEEE.pt  with train.save_positives: the rows of each successful training
                            episode, whole, by episode number (train.positives_from reads them)
    <run>/checkpoint.pt     networks, optimizers, counters, RNG states (every few episodes)
    <run>/summary.json      TTFS, TT50S, RAS, throughput (when the run has ended)
    <run>/logs/, wandb/     the files of the TorchRL logger ``logger.backend`` names, if any

``metrics.jsonl`` (:data:`METRICS_FILE`) is written whatever ``logger.backend`` is and is what
reports read: each line is one JSON object ``{"step": <env steps>, "<key>": <value>, ...}``,
e.g. ``{"step": 2000, "sac/loss_qvalue": 0.42, "sac/alpha": 0.97}``, keys as the recipe logs
them, values numbers (``null`` for a non-finite one), steps non-decreasing, each line flushed
when written. Readers skip a last line without its newline (a kill mid-write).

Guarantees: a run killed at any point resumes from its last checkpoint and loses at most the
episodes after it (``episodes.csv`` is cut back to the checkpoint, and ``metrics.jsonl`` to its
env step, so the steps the resumed run logs again are never there twice; the replay episodes
are re-inserted in order, so the buffer is rebuilt as it was); an existing run is never
replaced unless asked (``overwrite``).

Example:
    >>> import tempfile
    >>> run = RunDirectory(tempfile.mkdtemp() + "/run")
    >>> run.check(resume=False, overwrite=False)
    >>> run.create(config={"seed": 0})
    >>> run.append_episode({"episode": 1, "env_steps": 500, "success": 0, "return": -500.0,
    ...                     "mean_vlm_reward": 0.0, "stage": 1})
    >>> [row["env_steps"] for row in run.episode_rows()]
    ['500']
    >>> run.check(resume=False, overwrite=False)
    Traceback (most recent call last):
    ...
    FileExistsError: output_dir=... is not empty and holds no checkpoint.pt to resume from; ...
"""

from __future__ import annotations

import csv
import json
import math
import random
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase

EPISODE_COLUMNS = ("episode", "env_steps", "success", "return", "mean_vlm_reward", "stage")
CHECKPOINT = "checkpoint.pt"
REPLAY_DIR = "replay"
POSITIVES_DIR = "positives"
#: The run's training metrics, one JSON object per logged point (see the module doc).
METRICS_FILE = "metrics.jsonl"


class RunDirectory:
    """One training run's files (see the module doc)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    @property
    def checkpoint_path(self) -> Path:
        return self.path / CHECKPOINT

    def has_checkpoint(self) -> bool:
        return self.checkpoint_path.exists()

    def check(self, *, resume: bool, overwrite: bool) -> None:
        """Raise before any work unless the directory may be resumed, started, or replaced."""
        holds_files = self.path.exists() and any(self.path.iterdir())
        checkpointed = self.has_checkpoint()
        if resume and not checkpointed:
            if holds_files:
                raise FileNotFoundError(
                    f"resume=true but {self.checkpoint_path} does not exist: the run stopped "
                    "before its first checkpoint, so there is nothing to resume. Start it again "
                    "with overwrite=true instead of resume=true.")
            raise FileNotFoundError(f"resume=true but {self.checkpoint_path} does not exist; "
                                    "start the run without resume=true.")
        if not resume and holds_files and not overwrite:
            if checkpointed:
                raise FileExistsError(
                    f"output_dir={str(self.path)!r} already holds a run; pass resume=true to "
                    "continue it, overwrite=true to replace it, or another output_dir.")
            raise FileExistsError(
                f"output_dir={str(self.path)!r} is not empty and holds no {CHECKPOINT} to resume "
                "from; pass overwrite=true to replace its contents, or another output_dir.")

    def create(self, config: dict[str, Any]) -> None:
        """Start the run afresh (after :meth:`check` allowed it): an empty directory, the config."""
        if self.path.exists():
            shutil.rmtree(self.path)
        (self.path / REPLAY_DIR).mkdir(parents=True)
        write_json(self.path / "config.json", config)

    def config(self) -> dict[str, Any]:
        return json.loads((self.path / "config.json").read_text())

    # ------------------------------------------------------------------ episode rows
    def append_episode(self, row: dict[str, Any]) -> None:
        path = self.path / "episodes.csv"
        new = not path.exists()
        with path.open("a", newline="") as file:
            writer = csv.DictWriter(file, fieldnames=EPISODE_COLUMNS)
            if new:
                writer.writeheader()
            writer.writerow(row)

    def episode_rows(self) -> list[dict[str, str]]:
        path = self.path / "episodes.csv"
        if not path.exists():
            return []
        with path.open(newline="") as file:
            return list(csv.DictReader(file))

    def truncate_episodes(self, episodes: int) -> None:
        """Keep the first ``episodes`` rows (those the checkpoint covers) after a kill."""
        rows = self.episode_rows()[:episodes]
        temporary = self.path / "episodes.csv.tmp"
        with temporary.open("w", newline="") as file:
            writer = csv.DictWriter(file, fieldnames=EPISODE_COLUMNS)
            writer.writeheader()
            writer.writerows(rows)
        temporary.replace(self.path / "episodes.csv")

    # ------------------------------------------------------------------ training metrics
    @property
    def metrics_path(self) -> Path:
        return self.path / METRICS_FILE

    def append_metrics(self, step: int, metrics: Mapping[str, float]) -> None:
        """Append one point, ``{"step": step, **metrics}``, to ``metrics.jsonl``; the line is on
        disk (flushed, the file closed) when this returns."""
        if "step" in metrics:
            raise ValueError(f"a metric named 'step' clashes with {METRICS_FILE}'s step field; "
                             "log it under another key (e.g. 'train/step').")
        point = {"step": int(step)}
        for key, value in metrics.items():
            value = float(value)
            point[key] = value if math.isfinite(value) else None  # NaN is not JSON
        with self.metrics_path.open("a") as file:
            file.write(json.dumps(point) + "\n")

    def metric_points(self) -> list[dict[str, Any]]:
        """The points of ``metrics.jsonl`` in the order written (empty when there is none);
        a last line cut short by a kill is skipped, any other bad line raises."""
        path = self.metrics_path
        if not path.exists():
            return []
        text = path.read_text()
        lines = text.split("\n")
        points = []
        for number, line in enumerate(lines, start=1):
            if not line.strip():
                continue
            try:
                point = json.loads(line)
            except json.JSONDecodeError as error:
                if number == len(lines):  # no newline after it: the write was cut short
                    break
                raise ValueError(f"{path}:{number} is not JSON ({error}); expected one object "
                                 'per line, {"step": <env steps>, "<key>": <number>, ...}.'
                                 ) from error
            if (not isinstance(point, dict) or isinstance(point.get("step"), bool)
                    or not isinstance(point.get("step"), int)
                    or not all(value is None or (isinstance(value, int | float)
                                                 and not isinstance(value, bool))
                               for value in point.values())):
                raise ValueError(f"{path}:{number}: {line!r}; expected an object with an "
                                 'integer "step" and numbers (or null) as values, '
                                 'e.g. {"step": 2000, "sac/alpha": 0.97}.')
            points.append(point)
        return points

    def truncate_metrics(self, step: int) -> None:
        """Keep the points up to env step ``step`` (those the checkpoint covers) after a kill,
        so that the steps the resumed run logs again are not there twice."""
        if not self.metrics_path.exists():
            return
        kept = [point for point in self.metric_points() if point["step"] <= step]
        temporary = self.metrics_path.with_suffix(".tmp")
        temporary.write_text("".join(json.dumps(point) + "\n" for point in kept))
        temporary.replace(self.metrics_path)

    # ------------------------------------------------------------------ replay
    def save_replay_episode(self, index: int, rows: TensorDictBase) -> None:
        """Save the stored rows of the ``index``-th inserted episode (resume re-inserts them)."""
        path = self.path / REPLAY_DIR / f"{index:06d}.pt"
        torch.save(rows.cpu().to_dict(), path.with_suffix(".tmp"))
        path.with_suffix(".tmp").replace(path)

    def replay_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` inserted episodes, in insertion order."""
        for index in range(count):
            data = torch.load(self.path / REPLAY_DIR / f"{index:06d}.pt", weights_only=True)
            yield TensorDict(data, [data["step"].shape[0]])

    # ------------------------------------------------------------------ saved positives
    def save_positive_episode(self, episode: int, rows: TensorDictBase) -> None:
        """Save the rows of training episode ``episode`` (1-based), a successful one."""
        directory = self.path / POSITIVES_DIR
        directory.mkdir(exist_ok=True)
        path = directory / f"{episode:06d}.pt"
        torch.save(rows.cpu().to_dict(), path.with_suffix(".tmp"))
        path.with_suffix(".tmp").replace(path)

    def _positive_paths(self) -> list[Path]:
        directory = self.path / POSITIVES_DIR
        return sorted(directory.glob("*.pt")) if directory.is_dir() else []

    def saved_positive_count(self) -> int:
        return len(self._positive_paths())

    def positive_episodes(self, count: int) -> Iterator[TensorDict]:
        """The rows of the first ``count`` saved positives, in episode order."""
        for path in self._positive_paths()[:count]:
            data = torch.load(path, weights_only=True)
            yield TensorDict(data, [data["step"].shape[0]])

    def truncate_positives(self, episodes: int) -> None:
        """Drop the positives saved after the checkpoint's ``episodes`` (they are re-run)."""
        for path in self._positive_paths():
            if int(path.stem) > episodes:
                path.unlink()

    # ------------------------------------------------------------------ checkpoint, summary
    def save_checkpoint(self, state: dict[str, Any]) -> None:
        temporary = self.path / (CHECKPOINT + ".tmp")
        torch.save(state, temporary)
        temporary.replace(self.checkpoint_path)

    def load_checkpoint(self) -> dict[str, Any]:
        """The saved state, on the CPU (``load_state_dict`` copies it to the modules' devices)."""
        return torch.load(self.checkpoint_path, map_location="cpu", weights_only=True)

    def write_summary(self, summary: dict[str, Any]) -> None:
        write_json(self.path / "summary.json", summary)

    def summary(self) -> dict[str, Any] | None:
        path = self.path / "summary.json"
        return json.loads(path.read_text()) if path.exists() else None


def write_json(path: Path, payload: dict[str, Any]) -> None:
    temporary = path.with_suffix(".tmp")
    temporary.write_text(json.dumps(payload, indent=2))
    temporary.replace(path)


def rng_state() -> dict[str, Any]:
    """torch (CPU and every GPU), Python and NumPy generator states, as tensors and plain
    values (``torch.load(..., weights_only=True)`` reads them back)."""
    _, keys, position, has_gauss, cached = np.random.get_state()
    return {"torch": torch.get_rng_state(), "python": random.getstate(),
            "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
            "numpy": {"keys": torch.from_numpy(keys.astype(np.int64)), "position": position,
                      "has_gauss": has_gauss, "cached": cached}}


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if state.get("cuda") and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    random.setstate(state["python"])
    numpy_state = state["numpy"]
    np.random.set_state(("MT19937", numpy_state["keys"].numpy().astype(np.uint32),
                         numpy_state["position"], numpy_state["has_gauss"],
                         numpy_state["cached"]))
