"""Training metrics a run logged, from the file the run writes for them: ``metrics.jsonl``.

``recipes/sac_temporal.py`` writes ``metrics.jsonl`` into its run directory whatever
``logger.backend`` is (csv, wandb or none); its format is documented in
:mod:`temporal_torchrl.runs.directory` (one JSON object per logged point, ``{"step": <env steps>,
"<key>": <value>, ...}``). A run written before that file existed has only its TorchRL CSVLogger
files, ``logs/<exp_name>/scalars/<key>.csv`` with lines ``step,value``, which are read instead.
wandb's files are never read: wandb is a sink for those who watch runs there.

Both read into ``{key: Series}`` with steps in increasing order. A resumed run's file is cut back
to its checkpoint (so a step is logged once); were a key's step there twice (a CSV log of a
resumed run), the later value wins.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from temporal_torchrl.runs import METRICS_FILE, RunDirectory
from temporal_torchrl.runs.layout import LOGS_DIR


@dataclass(frozen=True)
class Series:
    """One logged scalar: ``values[i]`` at env step ``steps[i]``, steps increasing."""

    steps: np.ndarray
    values: np.ndarray

    @classmethod
    def from_points(cls, points: dict[float, float]) -> Series:
        steps = np.array(sorted(points), dtype=float)
        return cls(steps, np.array([points[step] for step in steps], dtype=float))


def jsonl_scalars(run_dir: Path) -> dict[str, Series]:
    """Every scalar of the run's ``metrics.jsonl`` (``null`` values read as NaN)."""
    points: dict[str, dict[float, float]] = {}
    for point in RunDirectory(run_dir).metric_points():
        step = float(point["step"])
        for key, value in point.items():
            if key != "step":
                points.setdefault(key, {})[step] = np.nan if value is None else float(value)
    return {key: Series.from_points(each) for key, each in points.items()}


def csv_scalars(run_dir: Path) -> dict[str, Series]:
    """Every scalar of the run's CSV logs (``logs/*/scalars/**.csv``)."""
    points: dict[str, dict[float, float]] = {}
    for scalars in sorted((run_dir / LOGS_DIR).glob("*/scalars")):
        for path in sorted(scalars.rglob("*.csv")):
            key = path.relative_to(scalars).with_suffix("").as_posix()
            for number, line in enumerate(path.read_text().splitlines(), start=1):
                if not line.strip():
                    continue
                try:
                    step, value = line.split(",")
                    points.setdefault(key, {})[float(step)] = float(value)
                except ValueError as error:
                    raise ValueError(f"{path}:{number}: {line!r} is not 'step,value' (TorchRL's "
                                     "CSVLogger format).") from error
    return {key: Series.from_points(each) for key, each in points.items()}


def logged_scalars(run_dir: Path) -> dict[str, Series]:
    """The run's logged scalars: from its ``metrics.jsonl`` when it has one, else from its CSV
    logs (runs from before the file existed); empty when it has neither."""
    if (Path(run_dir) / METRICS_FILE).exists():
        return jsonl_scalars(run_dir)
    return csv_scalars(run_dir)
