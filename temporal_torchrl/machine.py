"""The machine a measurement ran on, as one line for reports and benchmark rows."""

from __future__ import annotations

import os
import platform
from pathlib import Path

import torch


def machine_description() -> str:
    """The CPU model, core count, GPU if any, and torch's version and threads.

    >>> "CPU cores" in machine_description()
    True
    """
    model = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    gpu = f", GPU {torch.cuda.get_device_name(0)}" if torch.cuda.is_available() else ", no GPU"
    return (f"{model}, {os.cpu_count()} CPU cores{gpu}; torch {torch.__version__}, "
            f"{torch.get_num_threads()} torch threads")
