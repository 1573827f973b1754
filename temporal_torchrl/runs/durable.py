"""Files that survive a kill or a power cut: each is written whole, flushed to disk and renamed
over the old one, and the rename flushed too, so a reader finds the old file or the new one."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any


def flush_to_disk(file: IO) -> None:
    file.flush()
    os.fsync(file.fileno())


def fsync_directory(path: Path) -> None:
    """Flush a directory's entries (a rename, a new file) to disk."""
    descriptor = os.open(path, os.O_RDONLY)
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def write_synced(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Create ``path`` with what ``write`` writes into it, flushed to disk before returning."""
    with path.open("wb") as file:
        write(file)
        flush_to_disk(file)


def write_file(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Write ``path`` whole: ``write`` fills a temporary file, which is flushed to disk and
    renamed over ``path``; then the rename itself is flushed (the directory entry)."""
    temporary = path.with_name(path.name + ".tmp")
    write_synced(temporary, write)
    os.replace(temporary, path)
    fsync_directory(path.parent)


def write_json(path: str | Path, payload: Mapping[str, Any]) -> None:
    """``payload`` as indented JSON, written whole (:func:`write_file`)."""
    write_file(Path(path), lambda file: file.write((json.dumps(payload, indent=2) + "\n").encode()))


def append_csv_row(path: Path, columns: Sequence[str], row: Mapping[str, Any]) -> None:
    """Append ``row`` to the CSV file at ``path`` (its header first when the file is new),
    flushed to disk before returning, so that a kill loses at most the row being written."""
    new = not path.exists()
    with path.open("a", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=columns)
        if new:
            writer.writeheader()
        writer.writerow(row)
        flush_to_disk(file)
    if new:
        fsync_directory(path.parent)


def write_csv(path: Path, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> None:
    """The CSV file at ``path``: ``columns``' header, then ``rows``, written whole
    (:func:`write_file`)."""
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=columns)
    writer.writeheader()
    writer.writerows(rows)
    write_file(path, lambda file: file.write(text.getvalue().encode()))
