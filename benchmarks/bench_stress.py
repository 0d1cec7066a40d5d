"""Numerical stability under stress: where does a spreading run break?

Usage::

    .venv/bin/python benchmarks/bench_stress.py [--level smoke] [--jobs 2] [--name stress] [--cases "a;b"] [--out DIR]

Pushes one knob at a time past the configured range -- the time step as a
fraction of the Rayleigh time (with the wrapper's own guard lifted, to see
the physics break), the spreader speeds past the sweep, the particles'
stiffness -- and runs each case through real LIGGGHTS (geometry, settle,
spread) exactly as the workflow does. A case "breaks" when the run wrapper
refuses it; the table records which check fired (lost particles, particles
through the substrate or the roller, kinetic-energy blow-up, overlaps above
the limit, or LIGGGHTS' own refusal) and the health figures of the cases that
pass (largest overlap, peak particle speed).

Writes ``<out>/<name>.csv`` and ``<name>.md`` (machine, date; ``--out`` default ``benchmarks/measured``).
No case retries at a smaller step (``timestep.unstable_retry_fraction``): what breaks is the finding.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.fidelity import youngs_modulus  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from benchmarks.bench_fidelity import run_scene, variant_config  # noqa: E402

UNGUARDED = {"timestep.max_rayleigh_fraction": 100.0}  # lift the wrapper's time-step guard
NO_RETRY = {"timestep.unstable_retry_fraction": None}
BASE_POINT = [(100.0, 0.0)]
#: name -> (config overrides, [(U mm/s, omega rad/s), ...], what is stressed)
CASES = {
    "as configured": ({}, [(100.0, -10.0), (100.0, 0.0), (100.0, 10.0)], "baseline"),
    "dt 0.3 T_R": ({"timestep.rayleigh_fraction": 0.3}, BASE_POINT, "time step"),
    "dt 0.6 T_R, guarded": ({"timestep.rayleigh_fraction": 0.6}, BASE_POINT, "time step"),
    **{f"dt {f:g} T_R": ({"timestep.rayleigh_fraction": f, **UNGUARDED}, BASE_POINT, "time step")
       for f in (0.5, 0.8, 1.2, 2.0, 3.0)},
    "U 200": ({}, [(200.0, 0.0)], "speed"),
    "omega +60": ({}, [(100.0, 60.0)], "speed"),
    "omega -60": ({}, [(100.0, -60.0)], "speed"),
    "U 200, omega +-60, dt 0.3": ({"timestep.rayleigh_fraction": 0.3}, [(200.0, 60.0), (200.0, -60.0)], "speed"),
    "E 1 MPa (softer)": ({"LEVEL.youngs_modulus_dem_Pa": 1.0e6}, BASE_POINT, "stiffness"),
    "E 50 MPa (stiffer)": ({"LEVEL.youngs_modulus_dem_Pa": 5.0e7}, BASE_POINT, "stiffness"),
    "E 500 MPa (stiffer)": ({"LEVEL.youngs_modulus_dem_Pa": 5.0e8}, BASE_POINT, "stiffness"),
    # the configured time step in seconds, kept for 10x stiffer particles: main() sets the fraction
    "E 50 MPa at the configured step": ({"LEVEL.youngs_modulus_dem_Pa": 5.0e7, **UNGUARDED}, BASE_POINT,
                                        "stiffness"),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", default="smoke")
    parser.add_argument("--cases", help="case names separated by ; (some hold commas; default: all)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default="stress")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    parser.add_argument("--update", action="store_true",
                        help="re-run only --cases and replace their rows in the existing <name>.csv")
    args = parser.parse_args(argv)
    base = load_config(ROOT / "config.yaml")
    names = [n.strip() for n in args.cases.split(";")] if args.cases else list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        parser.error(f"unknown case(s) {unknown}; known: {list(CASES)}")
    # T_R scales as E^-1/2: the configured step in seconds is sqrt(E'/E) configured fractions of the stiffer T_R
    same_step = CASES["E 50 MPa at the configured step"][0]
    same_step["timestep.rayleigh_fraction"] = base["timestep"]["rayleigh_fraction"] * (
        same_step["LEVEL.youngs_modulus_dem_Pa"] / youngs_modulus(base, args.level)) ** 0.5
    # no second attempt at a smaller step (timestep.unstable_retry_fraction): what breaks is the finding
    tasks = [(n, variant_config(base, args.level, {**NO_RETRY, **CASES[n][0]}), args.level, 0, CASES[n][1], None, 0.0)
             for n in names]
    started = time.perf_counter()
    with ProcessPoolExecutor(args.jobs) as pool:
        runs = pd.DataFrame([row for rows in pool.map(run_scene, tasks) for row in rows])
    runs.insert(1, "stressed", runs["variant"].map(lambda n: CASES[n][2]))
    if "error" not in runs:
        runs["error"] = None
    runs["outcome"] = runs["error"].fillna("passes all checks")
    out = args.out
    if args.update and (out / f"{args.name}.csv").exists():
        old = pd.read_csv(out / f"{args.name}.csv")
        runs = pd.concat([old[~old["variant"].isin(names)], runs], ignore_index=True)
        runs = runs.sort_values("variant", key=lambda v: v.map(list(CASES).index), kind="stable")
    runs.to_csv(out / f"{args.name}.csv", index=False)
    cols = ["variant", "stressed", "U_mm_s", "omega_rad_s", "timestep_s", "cpu_s", "max_overlap_fraction",
            "max_overlap_anywhere", "peak_speed_m_s", "heap_exhausted", "outcome"]
    shown = runs.reindex(columns=cols)
    header = (f"# Stress test at the `{args.level}` level\n\n"
              f"Machine: {platform.node()} ({platform.processor() or platform.machine()}), "
              f"date: {time.strftime('%Y-%m-%d')}, {args.jobs} jobs, "
              + (f"rows of {names} re-run with --update. " if args.update else
                 f"{time.perf_counter() - started:.0f} s in all. ")
              + f"Command: `.venv/bin/python benchmarks/bench_stress.py --level {args.level}`\n\n"
              "Overlaps are fractions of the smaller radius (limits: 5 % in the sampling region, 50 % anywhere); "
              "peak speed is the fastest particle in the thermo output over the whole run.\n\n")
    (out / f"{args.name}.md").write_text(header + shown.to_markdown(index=False, floatfmt=".4g") + "\n")
    print(header + shown.to_markdown(index=False, floatfmt=".4g"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
