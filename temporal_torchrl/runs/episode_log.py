"""``episodes.csv``: one row per finished episode (:data:`EPISODE_COLUMNS`), appended and flushed
to disk as each episode ends, and the one set of rules a row must meet, which the resume and the
reports both apply."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from temporal_torchrl.runs.checkpoint import START_OVER, UnreadableRunFile
from temporal_torchrl.runs.durable import append_csv_row, write_csv
from temporal_torchrl.runs.layout import EPISODE_COLUMNS


class EpisodeLog:
    """The ``episodes.csv`` at ``path``."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def append(self, row: dict[str, Any]) -> None:
        append_csv_row(self.path, EPISODE_COLUMNS, row)

    def rows(self) -> list[dict[str, str]]:
        if not self.path.exists():
            return []
        with self.path.open(newline="") as file:
            return list(csv.DictReader(file))

    def checked_rows(self) -> list[dict[str, str]]:
        """:meth:`rows`, each checked (:func:`row_problem`); a ``ValueError`` naming the first
        bad one."""
        if self.path.exists():
            with self.path.open(newline="") as file:
                header = next(csv.reader(file), None)
            if header is not None and header != list(EPISODE_COLUMNS):
                raise ValueError(f"{self.path} has columns {header}; expected the recipe's "
                                 f"{','.join(EPISODE_COLUMNS)}.")
        rows = self.rows()
        for number, row in enumerate(rows, start=1):
            problem = row_problem(row, number)
            if problem is not None:
                raise ValueError(f"{self.path}, line {number + 1}: {problem}; expected "
                                 f"{','.join(EPISODE_COLUMNS)} of episode {number} (episodes in "
                                 "order, none missing).")
        return rows

    def successes(self) -> tuple[bool, ...]:
        """The ``success`` column (empty when the file does not exist)."""
        return tuple(row["success"] == "1" for row in self.checked_rows())

    def truncate(self, episodes: int) -> None:
        """Keep the first ``episodes`` rows (those the checkpoint covers) after a kill; raise
        :class:`UnreadableRunFile` when one of them is missing or unreadable."""
        rows = self.rows()
        for number, row in enumerate(rows[:episodes], start=1):
            problem = row_problem(row, number)
            if problem is not None:
                shown = ",".join("" if value is None else str(value) for value in row.values())
                raise UnreadableRunFile(
                    f"{self.path}, line {number + 1} ({shown!r}), is unreadable: {problem}; "
                    f"expected {','.join(EPISODE_COLUMNS)} of episode {number}, which the "
                    "checkpoint covers. Repair that line (or restore the file from a backup) and "
                    f"resume again, or {START_OVER}.")
        if len(rows) < episodes:
            raise UnreadableRunFile(
                f"{self.path} holds {len(rows)} episode rows but the checkpoint covers "
                f"{episodes} episodes: rows were lost. Restore the file from a backup and resume "
                f"again, or {START_OVER}.")
        if len(rows) == episodes and self.path.exists():
            return
        write_csv(self.path, rows[:episodes], EPISODE_COLUMNS)


def row_problem(row: dict[str | None, Any], number: int) -> str | None:
    """What is wrong with the ``number``-th episode row, None when nothing is."""
    if None in row:
        return "it has more columns than the header"
    missing = [column for column in EPISODE_COLUMNS if row.get(column) in (None, "")]
    if missing:
        return f"{', '.join(missing)} missing (the line was cut short)"
    try:
        values = [float(row[column]) for column in EPISODE_COLUMNS]
    except ValueError as error:
        return f"a value is not a number ({error})"
    if values[0] != number:
        return f"it is numbered {row['episode']}, not {number}"
    if row["success"] not in ("0", "1"):
        return f"success is {row['success']!r}, not 0 or 1"
    return None

