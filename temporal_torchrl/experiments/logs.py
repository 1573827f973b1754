"""Training metrics a run logged: TorchRL's CSVLogger files or wandb's offline run files.

``recipes/sac_temporal.py`` logs through TorchRL's loggers into its run directory:

- ``logger.backend=csv``: ``logs/<exp_name>/scalars/<key>.csv``, lines ``step,value`` (keys such
  as ``sac/loss_qvalue`` make sub-directories);
- ``logger.backend=wandb`` (offline by default): ``wandb/offline-run-*/run-*.wandb``, wandb's
  record log, whose history rows carry each key with its step under ``<prefix>/step`` (TorchRL's
  ``WandbLogger`` convention).

Both read into ``{key: Series}`` with steps in increasing order. A resumed run re-logs the steps
after its last checkpoint; the later value of a step wins. The wandb file is read with wandb's
own protobuf ``Record`` definition; its container is the LevelDB log format (32 KiB blocks of
CRC-checked chunks), read here so that no wandb process or network is needed.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CSV_LOG_DIR = "logs"
WANDB_DIR = "wandb"


@dataclass(frozen=True)
class Series:
    """One logged scalar: ``values[i]`` at env step ``steps[i]``, steps increasing."""

    steps: np.ndarray
    values: np.ndarray

    @classmethod
    def from_points(cls, points: dict[float, float]) -> Series:
        steps = np.array(sorted(points), dtype=float)
        return cls(steps, np.array([points[step] for step in steps], dtype=float))


def csv_scalars(run_dir: Path) -> dict[str, Series]:
    """Every scalar of the run's CSV logs (``logs/*/scalars/**.csv``)."""
    points: dict[str, dict[float, float]] = {}
    for scalars in sorted((run_dir / CSV_LOG_DIR).glob("*/scalars")):
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


# The LevelDB log format wandb writes: a 7-byte file header (":W&B", magic, version), then
# 32 KiB blocks of chunks, each with a 7-byte header (CRC-32 of type byte + data, length, type).
_FILE_HEADER = struct.Struct("<4sHB")
_CHUNK_HEADER = struct.Struct("<IHB")
_BLOCK_SIZE = 32 * 1024
_FULL, _FIRST, _MIDDLE, _LAST = 1, 2, 3, 4


def wandb_records(path: Path) -> Iterator[bytes]:
    """The serialized records of one ``.wandb`` file, stopping at a truncated or corrupt tail
    (a run still writing, or killed mid-chunk)."""
    data = path.read_bytes()
    if len(data) < _FILE_HEADER.size or data[:4] != b":W&B":
        raise ValueError(f"{path} is not a wandb run file (no ':W&B' header).")
    position, record = _FILE_HEADER.size, b""
    while True:
        space = _BLOCK_SIZE - position % _BLOCK_SIZE
        if space < _CHUNK_HEADER.size:  # the rest of a block too small for a header is padding
            position += space
            continue
        if position + _CHUNK_HEADER.size > len(data):
            return
        checksum, length, kind = _CHUNK_HEADER.unpack_from(data, position)
        chunk = data[position + _CHUNK_HEADER.size:position + _CHUNK_HEADER.size + length]
        if len(chunk) < length or zlib.crc32(chunk, zlib.crc32(bytes([kind]))) != checksum:
            return
        position += _CHUNK_HEADER.size + length
        if kind == _FULL:
            yield chunk
        elif kind == _FIRST:
            record = chunk
        elif kind == _MIDDLE:
            record += chunk
        elif kind == _LAST:
            yield record + chunk
        else:
            return


def _step_key(key: str) -> str:
    """TorchRL's WandbLogger logs ``a/b`` with its step under ``a/step`` (``step`` at top)."""
    prefix, separator, _ = key.rpartition("/")
    return f"{prefix}{separator}step"


def wandb_scalars(run_dir: Path) -> dict[str, Series]:
    """Every numeric scalar of the run's offline wandb runs (``wandb/offline-run-*``, in the
    order they were started, so a resumed run's later values win)."""
    from wandb.proto import wandb_internal_pb2  # wandb is heavy; only runs logged with it

    points: dict[str, dict[float, float]] = {}
    for path in sorted((run_dir / WANDB_DIR).glob("offline-run-*/run-*.wandb")):
        for data in wandb_records(path):
            record = wandb_internal_pb2.Record()
            record.ParseFromString(data)
            if record.WhichOneof("record_type") != "history":
                continue
            row = {}
            for item in record.history.item:
                key = item.key or "/".join(item.nested_key)
                kind = item.WhichOneof("value")
                row[key] = (json.loads(item.value_json) if item.value_json
                            else getattr(item, kind) if kind else None)
            for key, value in row.items():
                step = row.get(_step_key(key))
                if (key.startswith("_") or key == _step_key(key) or step is None
                        or isinstance(value, bool) or not isinstance(value, int | float)):
                    continue
                points.setdefault(key, {})[float(step)] = float(value)
    return {key: Series.from_points(each) for key, each in points.items()}


def logged_scalars(run_dir: Path) -> dict[str, Series]:
    """The run's logged scalars, from its CSV logs and its offline wandb runs (a run has one or
    the other; were both there, the CSV's series of a key wins)."""
    scalars = wandb_scalars(run_dir) if (run_dir / WANDB_DIR).is_dir() else {}
    scalars.update(csv_scalars(run_dir))
    return scalars
