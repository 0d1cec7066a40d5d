"""Fault injection: kill a workflow at random moments, resume it, and check what survives.

The tests (a short campaign) and ``benchmarks/bench_faults.py`` (a long one) use it:
Snakemake and its LIGGGHTS children are killed together (SIGKILL to the process group:
a crash, no clean-up), the README's command resumes, and at the end the results are
compared with an uninterrupted workflow's.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.metrics.dump import read_dump

#: What a half-written file looks like: LIGGGHTS' unpublished outputs, the atomic writer's temporaries.
HALF_WRITTEN_PATTERNS = ("*.part", ".*.tmp-*")


def _with_flags(cmd, *flags):
    """``cmd`` with ``flags`` added before its targets (after a ``--``, flags would be targets)."""
    cmd = list(cmd)
    at = cmd.index("--") if "--" in cmd else len(cmd)
    return [*cmd[:at], *flags, *cmd[at:]]


def _runs_in_progress(runs: Path) -> set[str]:
    """Run folders whose spread has started (an input is written) but not finished."""
    return {p.parent.name for p in runs.glob("*/spread.in") if not (p.parent / "health.json").exists()}


def kill_at_random(cmd, workdir, runs, delay_s: float, timeout_s: float = 3600) -> dict:
    """Start ``cmd`` in its own process group; SIGKILL the group after ``delay_s``.

    Returns ``killed`` (False if the workflow finished first), the wall time, and
    the runs whose spread was under way at the kill.
    """
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=workdir, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        proc.wait(timeout=delay_s)
        killed, interrupted = False, set()
    except subprocess.TimeoutExpired:
        interrupted = _runs_in_progress(Path(runs))
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=timeout_s)
        killed = True
    return {"killed": killed, "delay_s": delay_s, "wall_s": time.perf_counter() - start,
            "interrupted": sorted(interrupted), "returncode": proc.returncode}


def resume(cmd, workdir, timeout_s: float = 3600) -> dict:
    """Unlock the working directory and run ``cmd`` to its end (the README's resume)."""
    start = time.perf_counter()
    subprocess.run(_with_flags(cmd, "--unlock"), cwd=workdir, capture_output=True, timeout=timeout_s)
    proc = subprocess.run(cmd, cwd=workdir, capture_output=True, text=True, timeout=timeout_s)
    log = proc.stdout + proc.stderr
    return {"returncode": proc.returncode, "wall_s": time.perf_counter() - start,
            "spread_jobs": log.count("rule spread:"), "log_tail": log[-3000:]}


def campaign(cmd, workdir, runs, n_kills: int, max_delay_s: float, seed: int = 0, min_delay_s: float = 2.0,
             log=print) -> dict:
    """Kill ``cmd`` up to ``n_kills`` times at delays uniform in [min, max] s, then run it to its end.

    Each attempt after a kill resumes with ``--unlock`` and the same command. Returns
    the attempts, the final run, the runs that were ever interrupted, and the total wall time.
    """
    rng = np.random.default_rng(seed)
    attempts, interrupted = [], set()
    Path(workdir).mkdir(parents=True, exist_ok=True)
    for k in range(n_kills):
        subprocess.run(_with_flags(cmd, "--unlock"), cwd=workdir, capture_output=True, timeout=600)
        attempt = kill_at_random(cmd, workdir, runs, float(rng.uniform(min_delay_s, max_delay_s)))
        attempts.append(attempt)
        interrupted.update(attempt["interrupted"])
        log(f"attempt {k + 1}: {'killed' if attempt['killed'] else 'finished'} after {attempt['wall_s']:.1f} s"
            f"{'; runs under way: ' + ', '.join(attempt['interrupted']) if attempt['interrupted'] else ''}")
        if not attempt["killed"]:
            break
    final = resume(cmd, workdir)
    log(f"final run: exit {final['returncode']} after {final['wall_s']:.1f} s, {final['spread_jobs']} spread jobs")
    return {"attempts": attempts, "final": final, "interrupted": sorted(interrupted),
            "kills": sum(a["killed"] for a in attempts),
            "wall_s": sum(a["wall_s"] for a in attempts) + final["wall_s"]}


def half_written_files(results: Path) -> list[str]:
    """Files under ``results`` that a crash left half-written: temporaries, unpublished
    LIGGGHTS outputs, and JSON, CSV or dump files that do not read."""
    results = Path(results)
    bad = [str(p) for pattern in HALF_WRITTEN_PATTERNS for p in results.rglob(pattern)]
    for path in results.rglob("*"):
        if not path.is_file() or "checkpoint" in path.parts:
            continue
        try:
            if path.suffix == ".json":
                json.loads(path.read_text())
            elif path.suffix == ".csv":
                pd.read_csv(path)
            elif path.suffix == ".dump":
                read_dump(path)
        except (ValueError, OSError) as err:
            bad.append(f"{path} ({err})")
    return bad


def compare_runs(runs: Path, reference_runs: Path, names, tolerance: dict) -> dict:
    """Each run of ``names`` against the uninterrupted workflow's run of the same name.

    Returns per run: ``identical`` (final dump bit-identical), ``resumed_from_step``
    (from its health), and, for runs that are not identical, the metric differences and
    whether each is within ``tolerance`` (``{metric: largest allowed |difference|}``).
    """
    out = {}
    for name in names:
        run, ref = Path(runs) / name, Path(reference_runs) / name
        identical = (run / "final.dump").read_bytes() == (ref / "final.dump").read_bytes()
        row = {"identical": identical,
               "resumed_from_step": json.loads((run / "health.json").read_text())["resumed_from_step"]}
        if not identical:
            a, b = (json.loads((p / "metrics.json").read_text()) for p in (run, ref))
            row["differences"] = {k: a[k] - b[k] for k in tolerance}
            row["within_tolerance"] = all(abs(a[k] - b[k]) <= tol for k, tol in tolerance.items())
        out[name] = row
    return out
