"""Every benchmark script at ``--smoke`` sizes: it runs, and its rows have their fields and
finite figures (positive where they are rates, times, sizes or ratios).

The scripts' ``main`` runs in this process on one torch thread, with ``torch.compile`` disabled
so that a compiled row runs eager: compiling takes minutes, and is tested against eager in
``test_throughput.py``. The soak and the default loop's fresh process run as subprocesses, as
they do for their users.
"""

from __future__ import annotations

import importlib
import json
import math
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import pytest
import torch

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture
def benchmark_module(monkeypatch: pytest.MonkeyPatch) -> Iterator[Callable[[str], ModuleType]]:
    """Imports a module of ``benchmarks/``, with compilation off here and in subprocesses."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    monkeypatch.setenv("TORCH_COMPILE_DISABLE", "1")
    with torch._dynamo.config.patch(disable=True):
        yield importlib.import_module


def report_rows(path: Path, fields: list[str]) -> list[dict]:
    """The rows of a script's ``--json`` report, checked to have ``fields`` in that order."""
    report = json.loads(path.read_text())
    assert report["title"] and report["machine"]
    assert report["rows"], f"{path.name}: no rows"
    for row in report["rows"]:
        assert list(row) == fields, row
    return report["rows"]


def assert_positive(rows: list[dict], fields: list[str]) -> None:
    for row in rows:
        for field in fields:
            value = row[field]
            assert isinstance(value, int | float) and math.isfinite(value) and value > 0, (
                f"{field} = {value!r} in {row}")


def run_main(module: ModuleType, tmp_path: Path, *argv: str) -> Path:
    out = tmp_path / f"{module.__name__}.json"
    module.main([*argv, "--json", str(out)])
    return out


def test_bench_envs(benchmark_module, tmp_path):
    rows = report_rows(run_main(benchmark_module("bench_envs"), tmp_path, "--smoke"),
                       ["benchmark", "project", "raw", "ratio"])
    assert len(rows) == 5
    assert_positive(rows, ["project", "raw", "ratio"])


def test_bench_encoders(benchmark_module, tmp_path):
    fields = ["device", "batch", "precision", "frames from", "transform img/s",
              "raw forward img/s", "ratio"]
    rows = report_rows(run_main(benchmark_module("bench_encoders"), tmp_path, "--smoke"), fields)
    assert [row["batch"] for row in rows if row["device"] == "cpu"] == [1, 2]
    assert_positive(rows, ["transform img/s", "raw forward img/s", "ratio"])


def test_bench_rewards(benchmark_module, tmp_path):
    rows = report_rows(run_main(benchmark_module("bench_rewards"), tmp_path, "--smoke"),
                       ["case", "project_ms", "raw_ms", "ratio", "transforms_ms_per_step"])
    assert len(rows) == 2  # the relabelling and the rollout
    assert_positive(rows, ["project_ms", "raw_ms", "ratio"])
    assert math.isnan(rows[0]["transforms_ms_per_step"])
    assert math.isfinite(rows[1]["transforms_ms_per_step"])  # a difference: either sign


def test_bench_small_encoder(benchmark_module, tmp_path):
    fields = ["batch", "small input", "metaworld_small img/s", "LIV RN50 (random) img/s at 224",
              "ratio"]
    rows = report_rows(run_main(benchmark_module("bench_small_encoder"), tmp_path, "--smoke"),
                       fields)
    images, text = rows[:-1], rows[-1]
    assert [row["batch"] for row in images] == [1, 1, 2, 2]
    assert_positive(images, fields[2:])
    assert_positive([text], ["metaworld_small img/s"])


#: bench_training's sections and the rows each gives at --smoke (the grid: the state encoder,
#: one env, eager and compiled).
TRAINING_ROWS = {"sac_update": 6, "head_update": 6, "training_step": 5, "default_loop": 4,
                 "d_sequence": 5, "loop_grid": 2, "plain_loop": 1, "replay": 3,
                 "default_loop_rate": 1}


@pytest.mark.parametrize("section", TRAINING_ROWS)
def test_bench_training_section(benchmark_module, tmp_path, section):
    bench_training = benchmark_module("bench_training")
    out = run_main(bench_training, tmp_path, "--smoke", "--sections", section, "--threads", "1",
                   "--repeats", "1", "--rounds", "1", "--skip-liv")
    rows = report_rows(out, ["measure", "project", "reference", "reference is", "ratio"])
    assert len(rows) == TRAINING_ROWS[section]
    if section == "default_loop_rate":  # one rate, without a reference
        assert_positive(rows, ["project"])
    else:
        assert_positive(rows, ["project", "reference", "ratio"])


def test_bench_training_short_names(benchmark_module):
    parse_args = benchmark_module("bench_training").parse_args
    assert parse_args(["--sections", "sac,grid,replay"]).sections == [
        "sac_update", "loop_grid", "replay"]
    with pytest.raises(SystemExit):
        parse_args(["--sections", "nonsense"])


def test_default_loop_in_a_fresh_process(benchmark_module, tmp_path):
    """What the default_loop section runs for each of its rates: bench_training.py itself on the
    tree that TEMPORAL_TORCHRL_TREE names (here this checkout)."""
    default_loop = benchmark_module("training.default_loop")
    common = benchmark_module("training.common")
    rate = default_loop.fresh_default_loop(tmp_path, common.SMOKE, default_loop.TREE)
    assert math.isfinite(rate) and rate > 0


def test_soak(benchmark_module, tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the soak's run directory
    out = tmp_path / "soak.json"
    benchmark_module("soak").main(["--episodes", "8", "--steps", "5", "--warmup", "2",
                                   "--interval", "0.05", "--logger", "none", "--json", str(out)])
    (summary,) = json.loads(out.read_text())["rows"]
    assert summary["episodes"] == 8
    assert all(math.isfinite(value) for value in summary.values())
    assert_positive([summary], ["wall s", "resident MB after warm-up", "resident MB, last episode",
                                "s/episode, mean after warm-up", "run dir MB, end"])
