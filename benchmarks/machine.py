"""The machine a benchmark ran on, for the header of its table in ``benchmarks/measured/``."""
from __future__ import annotations

import datetime
import platform
import subprocess
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


ROOT = Path(__file__).resolve().parent.parent


def commit() -> str:
    """This checkout's short commit hash, with " with uncommitted changes" if tracked files differ from it."""
    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()
        except OSError:
            return ""
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    return head + (" with uncommitted changes" if git("status", "--porcelain", "--untracked-files=no") else "")


def machine() -> str:
    """One line naming the machine: architecture, CPU model, Python, NumPy, date."""
    return f"{platform.machine()}, {cpu_model()}, Python {platform.python_version()}, NumPy {np.__version__}, " \
           f"{datetime.date.today().isoformat()}"
