"""The machine a benchmark ran on, for the header of its table in ``benchmarks/measured/``."""
from __future__ import annotations

import datetime
import platform
from pathlib import Path

import numpy as np


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :func:`platform.processor` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine() -> str:
    """One line naming the machine: architecture, CPU model, Python, NumPy, date."""
    return f"{platform.machine()}, {cpu_model()}, Python {platform.python_version()}, NumPy {np.__version__}, " \
           f"{datetime.date.today().isoformat()}"
