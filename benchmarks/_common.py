"""Shared helpers for the benchmark scripts: timing, the machine's name, and a report table.

Every benchmark script measures the project's code next to its raw reference in the same run and
prints one markdown table headed by the machine it ran on; ``--json PATH`` also saves the rows.
``--quick`` shortens the timings; ``--smoke`` runs at tiny sizes, only to check that the script
runs and gives its rows (the tests run every script so; its figures mean nothing).
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from temporal_torchrl.machine import machine_description


def rate(fn: Callable[[], object], items_per_call: int, min_seconds: float = 2.0,
         warmup_calls: int = 2, sync: Callable[[], None] | None = None) -> float:
    """Items per second of ``fn``, timed over ``min_seconds`` after ``warmup_calls`` calls."""
    for _ in range(warmup_calls):
        fn()
    if sync is not None:
        sync()
    calls = 0
    start = time.perf_counter()
    while True:
        fn()
        calls += 1
        if sync is not None:
            sync()
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return calls * items_per_call / elapsed


def seconds_per_call(fn: Callable[[], object], min_seconds: float = 2.0, warmup_calls: int = 2,
                     sync: Callable[[], None] | None = None) -> float:
    """Mean wall-clock seconds of one call of ``fn``."""
    return 1.0 / rate(fn, 1, min_seconds, warmup_calls, sync)


def report(title: str, rows: list[dict], json_path: str | None = None) -> None:
    """Print ``rows`` (dicts with the same keys) as a markdown table under the machine's name."""
    print(f"\n## {title}\nmachine: {machine_description()}\n")
    if rows:
        keys = list(rows[0])
        print("| " + " | ".join(keys) + " |")
        print("|" + "---|" * len(keys))
        for row in rows:
            cells = [f"{v:.4g}" if isinstance(v, float) else str(v) for v in row.values()]
            print("| " + " | ".join(cells) + " |")
    if json_path:
        Path(json_path).write_text(json.dumps(
            {"title": title, "machine": machine_description(), "rows": rows}, indent=2))


def parse_args(description: str, argv: Sequence[str] | None = None) -> argparse.Namespace:
    """``--json``, and ``--quick`` or ``--smoke``, from ``argv`` (the command line's if None)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--json", default=None, help="also write the rows to this JSON file")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--quick", action="store_true", help="shorter timings")
    size.add_argument("--smoke", action="store_true",
                      help="tiny sizes: checks that the script runs (for the tests)")
    return parser.parse_args(argv)
