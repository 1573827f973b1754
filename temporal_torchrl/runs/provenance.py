"""Where a run ran: the project's commit, the library versions, the CPU and the torch threads.

Each start of a run, fresh or resumed, records one entry in ``provenance.json``
(:data:`~temporal_torchrl.runs.layout.PROVENANCE_FILE`), and ``summary.json`` carries the list,
so that a table can say which commit and which machine each of its cells came from. No entry
holds a path: committed results must read the same wherever they were made.

Example:
    >>> entry = current_provenance(episode=0)
    >>> sorted(entry) == sorted(PROVENANCE_KEYS)
    True
    >>> "torch" in entry["versions"]
    True
"""

from __future__ import annotations

import hashlib
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

import torch

#: The distributions whose versions decide what a run computes.
TRACKED_DISTRIBUTIONS = ("torch", "torchrl", "tensordict", "metaworld", "mujoco", "numpy")
#: The keys of one provenance entry.
PROVENANCE_KEYS = ("episode", "commit", "clean", "diff_sha256", "versions", "python", "cpu",
                   "torch_threads")

_SOURCE = Path(__file__).resolve().parent


def _git(*arguments: str) -> str | None:
    """``git``'s output in the project's source tree, None outside a git checkout."""
    try:
        result = subprocess.run(["git", *arguments], cwd=_SOURCE, capture_output=True,
                                check=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return result.stdout.decode(errors="replace")


def source_revision() -> dict[str, Any]:
    """The commit the project's code was imported from, whether its tracked files match it
    (``clean``; untracked and ignored files such as run outputs do not count) and, when they do
    not, the SHA-256 of ``git diff HEAD`` so two dirty runs can be told apart. All three None
    when the code is not in a git checkout (an installed wheel)."""
    commit = _git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None, "clean": None, "diff_sha256": None}
    diff = _git("diff", "HEAD", "--no-ext-diff", "--binary") or ""
    clean = not diff
    return {"commit": commit.strip(), "clean": clean,
            "diff_sha256": None if clean else hashlib.sha256(diff.encode()).hexdigest()}


def cpu_model() -> str:
    """The CPU's model name as the kernel reports it (``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def library_versions() -> dict[str, str | None]:
    """The installed version of each of :data:`TRACKED_DISTRIBUTIONS` (None: not installed)."""
    versions: dict[str, str | None] = {}
    for name in TRACKED_DISTRIBUTIONS:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def current_provenance(episode: int) -> dict[str, Any]:
    """This process's provenance entry for a run (re)started after ``episode`` episodes."""
    return {"episode": episode, **source_revision(), "versions": library_versions(),
            "python": platform.python_version(), "cpu": cpu_model(),
            "torch_threads": torch.get_num_threads()}
