"""``metrics.jsonl``: the training metrics a run logs, whatever ``logger.backend`` is, and what
reports read. Each line is one JSON object ``{"step": <env steps>, "<key>": <value>, ...}``, e.g.
``{"step": 2000, "sac/loss_qvalue": 0.42, "sac/alpha": 0.97}``, values numbers (``null`` for a
non-finite one), steps non-decreasing, each line flushed when written. Readers skip a last line
without its newline (a kill mid-write)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from temporal_torchrl.runs.durable import write_file
from temporal_torchrl.runs.layout import METRICS_FILE


class MetricsLog:
    """The ``metrics.jsonl`` at ``path``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def append(self, step: int, metrics: Mapping[str, float]) -> None:
        """Append one point, ``{"step": step, **metrics}``, to ``metrics.jsonl``; the line is on
        disk (flushed, the file closed) when this returns."""
        if "step" in metrics:
            raise ValueError(f"a metric named 'step' clashes with {METRICS_FILE}'s step field; "
                             "log it under another key (e.g. 'train/step').")
        point = {"step": int(step)}
        for key, value in metrics.items():
            value = float(value)
            point[key] = value if math.isfinite(value) else None  # NaN is not JSON
        with self.path.open("a") as file:
            file.write(json.dumps(point) + "\n")

    def points(self) -> list[dict[str, Any]]:
        """The points of ``metrics.jsonl`` in the order written (empty when there is none);
        a last line cut short by a kill is skipped, any other bad line raises."""
        path = self.path
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

    def truncate(self, step: int) -> None:
        """Keep the points up to env step ``step`` (those the checkpoint covers) after a kill,
        so that the steps the resumed run logs again are not there twice."""
        if not self.path.exists():
            return
        kept = "".join(json.dumps(point) + "\n" for point in self.points()
                       if point["step"] <= step)
        write_file(self.path, lambda file: file.write(kept.encode()))
