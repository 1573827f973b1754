"""``python tests/slow_writes.py <recipe overrides>``: recipes/sac_temporal.py with every file
write of the run directory slowed down, so that a test can kill the process in the middle of
one (tests/test_faults.py).

Each write (checkpoint, replay episode, JSON file) writes the first half of its bytes, flushes
them, notes the file's path in ``$SLOW_WRITES_MARKER``, sleeps ``$SLOW_WRITES_SECONDS`` and
only then writes the rest: a SIGKILL during the sleep leaves a half-written temporary file.
"""

import io
import os
import runpy
import sys
import time
from pathlib import Path
from typing import IO

import temporal_torchrl.training.run as run_module

RECIPES = Path(__file__).resolve().parents[1] / "recipes"
MARKER = Path(os.environ["SLOW_WRITES_MARKER"])
SECONDS = float(os.environ.get("SLOW_WRITES_SECONDS", "0.2"))
write_synced = run_module.write_synced


def slow_write_synced(path: Path, write) -> None:
    def in_two_halves(file: IO[bytes]) -> None:
        whole = io.BytesIO()
        write(whole)
        data = whole.getvalue()
        file.write(data[:len(data) // 2])
        file.flush()
        MARKER.write_text(str(path))
        time.sleep(SECONDS)
        file.write(data[len(data) // 2:])

    write_synced(path, in_two_halves)
    MARKER.write_text("")


run_module.write_synced = slow_write_synced

if __name__ == "__main__":
    sys.argv[0] = str(RECIPES / "sac_temporal.py")
    runpy.run_path(sys.argv[0], run_name="__main__")  # as a script, so Hydra finds its config
