"""Fault injection: the smoke workflow killed at random moments, resumed after each kill.

Run from the repository root::

    .venv/bin/python benchmarks/bench_faults.py [--kills 20] [--seed 0]

1. An uninterrupted workflow (the CI's config, ``.test/config.yaml``: 6 smoke runs) to
   ``results/smoke/dataset.csv`` in a scratch folder: the reference and its wall time T.
2. The same workflow in a second folder, killed ``--kills`` times (SIGKILL to the whole
   process group: Snakemake and LIGGGHTS) after a delay uniform in [2 s, 2T/kills] (so the
   kills fall over the whole workflow, not only its start), each time
   resumed with the README's command (``--unlock``, then the same command), then run to its end.
3. Checks: ``dataset.csv`` has every run once; runs never interrupted have final dumps
   bit-identical to the reference's; interrupted runs are bit-identical (restarted from
   scratch) or, resumed from a checkpoint, within 4 seed-to-seed sds of the smoke scene
   (benchmarks/measured/noise_smoke.csv); no half-written file anywhere under ``results/``.

Writes ``benchmarks/measured/faults.md`` and ``faults.csv`` (one row per attempt); exits 1
if a check fails.
"""
import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.columns import METRICS  # noqa: E402
from analysis.metrics.noise_floor import pooled_seed_sd, two_run_tolerance  # noqa: E402
from benchmarks.faults import campaign, compare_runs, half_written_files  # noqa: E402
from benchmarks.machine import machine  # noqa: E402

TARGET = "results/smoke/dataset.csv"


def snakemake(workdir):
    return [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--configfile",
            str(ROOT / "config.yaml"), str(ROOT / ".test/config.yaml"), "--cores", "2", "--rerun-incomplete",
            "--", TARGET]


def seed_tolerance(k=4.0):
    """k sds of a two-run difference on the smoke scene per metric (noise_smoke.csv; two_run_tolerance)."""
    return two_run_tolerance(pooled_seed_sd(pd.read_csv(ROOT / "benchmarks/measured/noise_smoke.csv")), k)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kills", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keep", action="store_true", help="keep the scratch folders")
    args = parser.parse_args(argv)
    scratch = Path(tempfile.mkdtemp(prefix="spreadmap-faults-"))
    reference, faulted = scratch / "reference", scratch / "faulted"
    try:
        start = time.perf_counter()
        subprocess.run(snakemake(reference), check=True, capture_output=True)
        t_ref = time.perf_counter() - start
        print(f"uninterrupted: {t_ref:.0f} s", flush=True)
        max_delay = max(2 * t_ref / args.kills, 10.0)
        result = campaign(snakemake(faulted), faulted, faulted / "results/smoke/runs", args.kills, max_delay,
                          seed=args.seed, log=lambda line: print(line, flush=True))
        data = pd.read_csv(faulted / TARGET)
        names = sorted(p.name for p in (reference / "results/smoke/runs").iterdir())
        tolerance = seed_tolerance()
        runs = compare_runs(faulted / "results/smoke/runs", reference / "results/smoke/runs", names, tolerance)
        half = half_written_files(faulted / "results")
    finally:
        if not args.keep:
            shutil.rmtree(scratch, ignore_errors=True)
    interrupted = set(result["interrupted"])
    once = len(data) == len(names) and not data.duplicated(["U_mm_s", "omega_rad_s", "replicate"]).any()
    never = [n for n in names if n not in interrupted]
    resumed = [n for n in names if runs[n]["resumed_from_step"] > 0]
    checks = {
        "dataset.csv has every run once": once and result["final"]["returncode"] == 0,
        "runs never interrupted are bit-identical": all(runs[n]["identical"] for n in never),
        "interrupted runs: bit-identical, or (resumed) within 4 sds of a two-run difference": all(
            runs[n]["identical"] or runs[n].get("within_tolerance", False) for n in interrupted),
        "no half-written file under results/": not half,
    }
    attempts = pd.DataFrame([{**a, "interrupted": " ".join(a["interrupted"])} for a in result["attempts"]])
    attempts.to_csv(ROOT / "benchmarks/measured/faults.csv", index=False)
    redone = sum(len(a["interrupted"]) for a in result["attempts"])
    table = pd.DataFrame([{"run": n, "interrupted": n in interrupted, "resumed_from_step": runs[n]["resumed_from_step"],
                           "bit_identical": runs[n]["identical"],
                           **{f"d_{m}": runs[n].get("differences", {}).get(m, 0.0) for m in METRICS}}
                          for n in names])
    text = "\n".join([
        "# Fault injection: the smoke workflow killed and resumed",
        "",
        f"Measured {machine()} by `.venv/bin/python benchmarks/bench_faults.py --kills {args.kills} "
        f"--seed {args.seed}`.",
        "",
        f"- Uninterrupted workflow ({len(names)} smoke runs to `{TARGET}`): {t_ref:.0f} s.",
        f"- Kills survived: {result['kills']} of {args.kills} planned (a workflow that finished before its kill "
        f"ends the campaign), delays uniform in [2, {max_delay:.0f}] s.",
        f"- Runs started but unfinished at a kill: {redone} (kill, run) pairs over {len(interrupted)} distinct "
        f"runs (each resumed from its newest checkpoint or started over); {len(resumed)} finished from a checkpoint.",
        f"- Wall time of the killed attempts and the final run: {result['wall_s']:.0f} s, "
        f"i.e. {result['wall_s'] - t_ref:.0f} s ({result['wall_s'] / t_ref - 1:.0%}) lost to the kills.",
        "- Tolerance for a resumed run: 4 sds of a two-run difference, 4 x sqrt(2) pooled seed sds of the "
        "smoke scene (noise_smoke.csv): "
        + ", ".join(f"{m} {v:.3g}" for m, v in tolerance.items()) + ".",
        "",
        "| check | passed |",
        "|---|---|",
        *[f"| {name} | {'yes' if ok else '**no**'} |" for name, ok in checks.items()],
        "",
        "Per run (differences: the faulted workflow's minus the uninterrupted one's):",
        "",
        table.to_markdown(index=False, floatfmt=".3g"),
        "",
        *([f"Half-written files: {json.dumps(half)}", ""] if half else []),
    ])
    (ROOT / "benchmarks/measured/faults.md").write_text(text)
    print(text)
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
