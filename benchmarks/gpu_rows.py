"""The GPU node check (``benchmarks/gpu_check.sh``): its sections, each in a child process under
its own timeout, inside one overall budget (five minutes by default), written as JSON.

    python benchmarks/gpu_rows.py --out DIR [--no-install] [--cpu-rows] [--sections a,b]

Each section but install and cuda_tests runs its code from ``benchmarks/gpu_sections.py`` in a
child process (``python benchmarks/gpu_sections.py NAME --json PATH --device cuda --size full``).

Sections, in the order they run (``--sections`` picks some):

install               the wheelhouse (``benchmarks/device_wheels.sh``) into a ``--target`` folder
environment           torch, CUDA, the GPU, the carried packages' versions and paths
egl_context           one EGL context through MuJoCo: the GL renderer it gives (GPU or software)
cuda_tests            ``pytest -m cuda tests/test_cuda.py``: each test's outcome
encoder               the LIV-shaped RN50 (random weights in LIV's format), 224 px: images/s at
                      batch 1, 32 and 256, float32 and bf16 autocast + channels-last
training_step         the stage-2 training step (D = 1024) against its compute bound
sac_update            the SAC update (batch 256, (256, 256)) against its compute bound
loop_shipped_1/_8     the whole loop's env steps/s, the shipped encoder at 64 px, 1 and 8 envs
loop_liv_1/_8         the same with the LIV-shaped RN50 at 224 px
sac_update_cudagraphs the SAC update compiled and captured in a CUDA graph, against eager

A section that hangs is killed with every process it started (its whole process group) at its
timeout and written as a failed section naming the reason: with 8 rendering envs, mujoco issue
#3444 (EGL renderers hanging in ``mjr_readPixels`` with 8 spawned envs on an H200). The JSON is
rewritten after every section, so a check killed from outside keeps what it measured.

Without CUDA the sections that need a GPU are written as skipped, saying that no GPU was found,
and the check exits 0 when the rest passed; ``--cpu-rows`` runs them on the CPU at smoke sizes
instead (their figures mean nothing: it checks this script). The orchestrating process imports
nothing but the standard library, so a broken install or a crashing import is a failed section
in the JSON rather than a traceback without one.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The sections' own code, run as a child process (it imports torch and the project).
SECTIONS_SCRIPT = Path(__file__).resolve().with_name("gpu_sections.py")
#: The check's whole budget (seconds): issue 34 asks for a GPU check of at most five minutes.
BUDGET_S = 300
#: A section is not started with less left than this: it could not do anything useful.
MIN_SECTION_S = 15
#: ``--cpu-rows`` stretches the GPU sections' timeouts by this: on a small shared CPU, RN50 at
#: 224 px embeds about one frame a second, and the sections only check their code there.
CPU_TIMEOUT_FACTOR = 6
EGL_HANG = ("mujoco issue #3444 reports EGL renderers hanging in mjr_readPixels with 8 spawned "
            "envs on an H200: run this node with fewer envs (env.num_envs=2)")
NO_GPU = "no GPU found"
#: The statuses that fail the check (``not run``: the budget was spent, or the environment
#: section, itself failed, left nothing to run on).
FAILED = ("failed", "timeout")


@dataclass(frozen=True)
class Section:
    """A section of the check: its limit, whether it needs a GPU, what a hang means."""

    name: str
    timeout_s: float
    needs_gpu: bool = True
    #: Added to the reason when the section times out (what likely hung).
    hang_hint: str = ""
    #: What the section measures, for the JSON.
    about: str = ""


SECTIONS = (
    Section("install", 120, needs_gpu=False, about="the wheelhouse into the --target folder"),
    Section("environment", 60, needs_gpu=False,
            about="torch, CUDA, the GPU, the carried packages' versions and paths"),
    Section("egl_context", 30, needs_gpu=False,
            hang_hint="creating one EGL context hung: the node's EGL/GL driver libraries",
            about="one EGL context through MuJoCo and the GL renderer it gives"),
    Section("cuda_tests", 200, needs_gpu=False,
            hang_hint="a cuda test hung (the EGL probe has its own 90 s limit inside it; "
                      + EGL_HANG + ")",
            about="pytest -m cuda tests/test_cuda.py"),
    Section("encoder", 60, about="LIV-shaped RN50 (random weights in LIV's format), 224 px: "
                                 "images/s at batch 1, 32, 256"),
    Section("training_step", 60, about="the stage-2 training step against its compute bound"),
    Section("sac_update", 45, about="the SAC update against its compute bound"),
    Section("loop_shipped_1", 60, about="whole loop, shipped encoder 64 px, 1 env"),
    Section("loop_shipped_8", 75, hang_hint=EGL_HANG,
            about="whole loop, shipped encoder 64 px, 8 envs"),
    Section("loop_liv_1", 60, about="whole loop, LIV-shaped RN50 224 px, 1 env"),
    Section("loop_liv_8", 75, hang_hint=EGL_HANG,
            about="whole loop, LIV-shaped RN50 224 px, 8 envs"),
    Section("sac_update_cudagraphs", 90,
            about="the SAC update compiled and in a CUDA graph (compile.cudagraphs) vs eager"),
)
BY_NAME = {section.name: section for section in SECTIONS}


# ---- the orchestrator (standard library only)


def run_with_timeout(command: Sequence[str], timeout: float, env: dict[str, str] | None = None,
                     cwd: Path = ROOT) -> tuple[int | None, str, float]:
    """``command`` in a new process session, killed with every process it started (the
    session's group) after ``timeout`` seconds: its exit status (None when it was killed), its
    output (stdout and stderr) and its seconds."""
    start = time.monotonic()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, errors="replace", start_new_session=True, env=env,
                               cwd=cwd)
    try:
        output, _ = process.communicate(timeout=max(timeout, 1))
        status: int | None = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        output, _ = process.communicate()
        status = None
    try:  # workers that outlived a child which exited by itself
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    return status, output, time.monotonic() - start


@dataclass
class Check:
    """The check's state: its options, what each section gave, and the JSON it writes."""

    out: Path
    python: str
    budget_s: float
    started: float
    install: bool
    wheels: Path
    target: Path
    cpu_rows: bool
    selected: tuple[str, ...]
    gpu: str | None = None
    cuda: bool = False
    #: Why the environment section failed, if it did: then no section after it can run.
    broken: str = ""
    environment: dict = field(default_factory=dict)
    sections: list[dict] = field(default_factory=list)

    @property
    def deadline(self) -> float:
        return self.started + self.budget_s

    def child_env(self) -> dict[str, str]:
        """The children's environment: the installed wheels, then the checkout, first on
        ``PYTHONPATH``; headless EGL; unbuffered output (a killed child keeps its last lines)."""
        paths = [str(self.target)] if self.install else []
        paths += [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
        return {**os.environ, "PYTHONPATH": os.pathsep.join(paths), "PYTHONUNBUFFERED": "1",
                "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
                "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl"),
                "RL_WARNINGS": os.environ.get("RL_WARNINGS", "0")}

    def record(self, section: Section, status: str, seconds: float = 0.0, reason: str = "",
               output: str = "", rows: Sequence[dict] = (), info: dict | None = None) -> dict:
        entry = {"name": section.name, "about": section.about, "status": status,
                 "seconds": round(seconds, 2)}
        if reason:
            entry["reason"] = reason
        if info:
            entry["info"] = info
        entry["rows"] = [{"section": section.name, **row} for row in rows]
        if output and status not in ("ok", "skipped"):
            entry["output_tail"] = output[-4000:]
        self.sections.append(entry)
        self.write()
        print(f"gpu_check: {section.name}: {status} in {seconds:.1f} s"
              + (f" ({reason})" if reason else ""), flush=True)
        return entry

    def write(self) -> None:
        """The JSON, rewritten whole after every section (atomically)."""
        now = time.time()
        document = {
            "check": "benchmarks/gpu_check.sh",
            "started": datetime.fromtimestamp(self.started, timezone.utc).isoformat(),
            "seconds": round(now - self.started, 1),
            "budget_s": self.budget_s,
            "gpu": self.gpu,
            "cuda": self.cuda,
            "sizes": "full" if self.cuda else ("smoke, on the CPU (figures mean nothing)"
                                               if self.cpu_rows else "none"),
        }
        if not self.cuda and self.environment:
            document["no_gpu"] = (f"{NO_GPU}: torch.cuda.is_available() is False (torch "
                                  f"{self.environment.get('torch')}, built for CUDA "
                                  f"{self.environment.get('torch_cuda')}); the GPU rows were "
                                  + ("run on the CPU at smoke sizes" if self.cpu_rows
                                     else "not measured"))
        document["environment"] = self.environment
        document["sections"] = self.sections
        document["rows"] = [row for entry in self.sections for row in entry["rows"]]
        document["failed"] = [entry["name"] for entry in self.sections
                              if entry["status"] in FAILED]
        document["not_run"] = [entry["name"] for entry in self.sections
                               if entry["status"] == "not run"]
        path = self.out / "gpu_check.json"
        temporary = path.with_suffix(".json.tmp")
        temporary.write_text(json.dumps(document, indent=2, default=str) + "\n")
        temporary.replace(path)

    def time_left(self) -> float:
        return self.deadline - time.time()

    def run(self) -> int:
        """Every selected section in order; the exit status: 0 when none failed or timed out
        (sections the budget left no time for are listed, but are no failure: nothing in them
        was found wrong)."""
        self.out.mkdir(parents=True, exist_ok=True)
        for section in SECTIONS:
            if section.name not in self.selected:
                continue
            left = self.time_left()
            if left < MIN_SECTION_S:
                self.record(section, "not run", reason=f"the check's {self.budget_s:.0f} s "
                            f"budget was spent ({left:.0f} s left)")
                continue
            on_cpu = section.needs_gpu and not self.cuda
            timeout = min(section.timeout_s * (CPU_TIMEOUT_FACTOR if on_cpu else 1), left)
            if self.broken and section.name != "install":
                self.record(section, "not run", reason=self.broken)
            elif section.name == "install":
                self.run_install(section, timeout)
            elif section.name == "cuda_tests":
                self.run_cuda_tests(section, timeout)
            elif section.needs_gpu and not self.cuda and not self.cpu_rows:
                self.record(section, "skipped", reason=f"{NO_GPU} (torch.cuda.is_available() "
                            "is False); --cpu-rows runs it on the CPU at smoke sizes")
            else:
                self.run_child(section, timeout)
        self.write()
        failed = [entry["name"] for entry in self.sections if entry["status"] in FAILED]
        not_run = [entry["name"] for entry in self.sections if entry["status"] == "not run"]
        where = f"{self.gpu}" if self.cuda else f"no GPU ({NO_GPU})"
        print(f"gpu_check: {len(self.sections)} sections on {where} in "
              f"{time.time() - self.started:.0f} s; "
              + (f"failed: {', '.join(failed)}" if failed else "none failed")
              + (f"; not run: {', '.join(not_run)}" if not_run else "")
              + f"; {self.out / 'gpu_check.json'}", flush=True)
        return 1 if failed else 0

    def run_install(self, section: Section, timeout: float) -> None:
        if not self.install:
            self.record(section, "skipped", reason="--no-install: the packages this Python "
                        "has are used")
            return
        wheels = sorted(self.wheels.glob("*.whl"))
        if not wheels:
            self.record(section, "failed", reason=f"no wheels in {self.wheels}: run "
                        "benchmarks/device_wheels.sh on a machine with network and carry its "
                        "folder beside the checkout (or pass --wheels DIR)")
            return
        command = [self.python, "-m", "pip", "install", "-q", "--disable-pip-version-check",
                   "--no-index", "--no-deps", "--no-compile", "--no-cache-dir", "--upgrade",
                   "--target", str(self.target), *map(str, wheels)]
        status, output, seconds = run_with_timeout(command, timeout)
        size = sum(wheel.stat().st_size for wheel in wheels)
        info = {"wheels": len(wheels), "wheels_mib": round(size / 2**20, 1),
                "target": str(self.target)}
        if status == 0:
            self.record(section, "ok", seconds, info=info)
        else:
            self.record(section, "failed" if status is not None else "timeout", seconds,
                        reason=_failure(status, timeout, section), output=output, info=info)

    def run_child(self, section: Section, timeout: float) -> None:
        """``section`` in a child process (``gpu_sections.py``) under ``timeout``."""
        with tempfile.TemporaryDirectory(prefix=f"gpu_check_{section.name}_") as tmp:
            result = Path(tmp) / "result.json"
            device = "cuda" if self.cuda else "cpu"
            size = "full" if self.cuda else "smoke"
            command = [self.python, str(SECTIONS_SCRIPT), section.name, "--json", str(result),
                       "--device", device, "--size", size]
            status, output, seconds = run_with_timeout(command, timeout, self.child_env())
            if status == 0 and result.exists():
                done = json.loads(result.read_text())
                if section.name == "environment":
                    self.environment = done["info"]
                    self.cuda = bool(done["info"].get("cuda_available"))
                    self.gpu = done["info"].get("gpu")
                self.record(section, "ok", seconds, rows=done.get("rows", ()),
                            info=done.get("info"), output=output)
            else:
                self.record(section, "failed" if status is not None else "timeout", seconds,
                            reason=_failure(status, timeout, section), output=output)
                if section.name == "environment":
                    self.broken = ("the environment section failed: torch or the carried "
                                   "packages do not import (see its output_tail)")

    def run_cuda_tests(self, section: Section, timeout: float) -> None:
        """pytest on the cuda tests, in one process (no xdist: the image may lack it, and the
        project's ``-n auto`` addopts with it), no cache (the checkout may be read-only)."""
        with tempfile.TemporaryDirectory(prefix="gpu_check_pytest_") as tmp:
            junit = Path(tmp) / "junit.xml"
            command = [self.python, "-m", "pytest", "-p", "no:cacheprovider", "-o", "addopts=",
                       "-ra", "-q", "-m", "cuda", f"--junitxml={junit}", "tests/test_cuda.py"]
            status, output, seconds = run_with_timeout(command, timeout, self.child_env())
            (self.out / "cuda_tests.log").write_text(output)
            tests = _junit_outcomes(junit) if junit.exists() else []
        counts: dict[str, int] = {}
        for test in tests:
            counts[test["outcome"]] = counts.get(test["outcome"], 0) + 1
        summary = next((line.strip("= ") for line in reversed(output.splitlines())
                        if " in " in line and any(word in line for word in (
                            "passed", "failed", "skipped", "error", "deselected"))), "")
        info = {"summary": summary, "counts": counts, "tests": tests, "log": "cuda_tests.log"}
        if status == 0:
            self.record(section, "ok", seconds, info=info)
        else:
            reason = _failure(status, timeout, section)
            if status == 5:
                reason = "pytest collected no cuda test (exit status 5)"
            self.record(section, "failed" if status is not None else "timeout", seconds,
                        reason=reason, output=output, info=info)


def _failure(status: int | None, timeout: float, section: Section) -> str:
    if status is None:
        return (f"did not finish in {timeout:.0f} s and was killed with its workers"
                + (f": {section.hang_hint}" if section.hang_hint else ""))
    return f"exit status {status} (its output's end is in output_tail)"


def _junit_outcomes(path: Path) -> list[dict]:
    """Each test case of a JUnit XML report: its name, outcome, seconds and message."""
    tests = []
    for case in ElementTree.parse(path).getroot().iter("testcase"):
        outcome, message = "passed", ""
        for tag in ("failure", "error", "skipped"):
            element = case.find(tag)
            if element is not None:
                outcome = {"failure": "failed"}.get(tag, tag)
                message = (element.get("message") or "")[:500]
                break
        tests.append({"test": case.get("name"), "outcome": outcome,
                      "seconds": round(float(case.get("time") or 0), 2),
                      **({"message": message} if message else {})})
    return tests


# ---- the command line


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, help="the folder of gpu_check.json and "
                        "cuda_tests.log (default: $OUT)")
    parser.add_argument("--no-install", action="store_true",
                        help="use the packages this Python has; no wheelhouse")
    parser.add_argument("--wheels", type=Path, default=ROOT / "wheelhouse",
                        help="the wheelhouse (default: wheelhouse/ beside benchmarks/)")
    parser.add_argument("--target", type=Path,
                        default=Path(tempfile.gettempdir()) / "temporal-torchrl-site",
                        help="where the wheels are installed (default: $TMPDIR/"
                             "temporal-torchrl-site)")
    parser.add_argument("--budget", type=float, default=BUDGET_S,
                        help=f"the whole check's seconds (default {BUDGET_S})")
    parser.add_argument("--started", type=float, default=None,
                        help="when the check began (seconds since the epoch; gpu_check.sh's)")
    parser.add_argument("--cpu-rows", action="store_true",
                        help="without CUDA: run the GPU sections on the CPU at smoke sizes")
    parser.add_argument("--sections", default=",".join(BY_NAME),
                        help=f"comma-separated, from: {', '.join(BY_NAME)}")
    args = parser.parse_args(argv)
    args.out = args.out or (Path(os.environ["OUT"]) if os.environ.get("OUT") else None)
    if args.out is None:
        parser.error("name the output folder: --out DIR (gpu_check.sh: its first argument "
                     "or $OUT)")
    selected = args.sections.split(",")
    if unknown := sorted(set(selected) - set(BY_NAME)):
        parser.error(f"unknown sections {unknown}; choose from {', '.join(BY_NAME)}")
    # install puts the packages there (or says --no-install) and environment decides
    # whether there is a GPU: every check runs both
    args.sections = tuple(dict.fromkeys(["install", "environment", *selected]))
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    check = Check(out=args.out, python=sys.executable, budget_s=args.budget,
                  started=args.started or time.time(), install=not args.no_install,
                  wheels=args.wheels, target=args.target, cpu_rows=args.cpu_rows,
                  selected=args.sections)
    return check.run()


if __name__ == "__main__":
    sys.exit(main())
