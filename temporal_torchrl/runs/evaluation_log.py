"""``eval.csv``: one row per evaluation of the deterministic policy (:data:`EVALUATION_COLUMNS`),
appended and flushed to disk as each evaluation ends."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from temporal_torchrl.runs.durable import append_csv_row, write_csv
from temporal_torchrl.runs.layout import EVALUATION_COLUMNS


class EvaluationLog:
    """The ``eval.csv`` at ``path``: after training episode ``episode`` (``env_steps`` training
    env steps), ``episodes`` evaluation episodes, their ``success_rate`` (success at any step,
    as training episodes count it), ``final_success_rate`` (success at the last step, as FuRL's
    evaluation counts it), mean ``return`` (sparse task reward) and mean ``episode_length``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def append(self, row: dict[str, Any]) -> None:
        append_csv_row(self.path, EVALUATION_COLUMNS, row)

    def rows(self) -> list[dict[str, float]]:
        """The evaluations so far, values as numbers; a ``ValueError`` naming a bad line."""
        if not self.path.exists():
            return []
        with self.path.open(newline="") as file:
            rows = list(csv.DictReader(file))
        parsed = []
        for number, row in enumerate(rows, start=2):
            try:
                values = {column: float(row[column]) for column in EVALUATION_COLUMNS}
            except (KeyError, TypeError, ValueError) as error:
                raise ValueError(f"{self.path}, line {number}: unreadable ({error}); expected "
                                 f"{','.join(EVALUATION_COLUMNS)}.") from error
            if not all(math.isfinite(value) for value in values.values()):
                raise ValueError(f"{self.path}, line {number}: a value is not finite.")
            parsed.append(values)
        return parsed

    def truncate(self, episodes: int) -> None:
        """Keep the evaluations taken after at most ``episodes`` training episodes (those the
        checkpoint covers): after a kill the resumed run evaluates the later ones again."""
        if not self.path.exists():
            return
        with self.path.open(newline="") as file:
            rows = list(csv.DictReader(file))
        kept = [row for row in rows if float(row["episode"]) <= episodes]
        if len(kept) < len(rows):
            write_csv(self.path, kept, EVALUATION_COLUMNS)


def evaluation_summary(rows: list[dict[str, float]]) -> dict[str, Any] | None:
    """``summary.json``'s ``evaluation``: the last and the best success rate, with the training
    episode each was taken after (None without evaluations)."""
    if not rows:
        return None
    best = max(rows, key=lambda row: row["success_rate"])  # the first of equal rates
    return {"evaluations": len(rows),
            "last_success_rate": rows[-1]["success_rate"],
            "last_episode": int(rows[-1]["episode"]),
            "best_success_rate": best["success_rate"],
            "best_episode": int(best["episode"]),
            "last_final_success_rate": rows[-1]["final_success_rate"]}

