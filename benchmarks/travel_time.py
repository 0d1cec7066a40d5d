"""Where along the roller's travel a spread's time goes: the run-in, the sampling region, the run-out.

Usage (no DEM: it reads finished runs)::

    .venv/bin/python benchmarks/travel_time.py --runs results/default/runs [--level default]
        [--name travel_time] [--out benchmarks/measured]

Every folder under ``--runs`` (at any depth) holding a ``spread.in`` and its ``spread.log`` is read:
the thermo rows give the step, the particles integrated and LIGGGHTS' thermo ``cpu`` (its elapsed
seconds, counted from 0 in each ``run`` segment: the CPU seconds of a run alone on its core); the input
gives where the roller's axis is at each step (its line ``variable roller_stop_x equal x0+dx*step``)
and the point (its first line). Each thermo interval is put in the phase of the travel the axis is in
at its end:

* ``run_in``: from the roller's start to the sampling region's start (the heap pushed into a pile);
* ``region``: over the sampling region;
* ``run_out``: from the region's end to ``run_out_mm`` past it (where the layer-laid checks begin);
* ``laid_checks``: from there until the roller stops.

Writes ``<name>.csv`` (one row per run and phase: travel [mm], elapsed time [s], particle-steps) and
``<name>.md`` (per group of omega, forward rolling < 0, still, counter-rotating > 0: each phase's share of
the time and of the travel, and its seconds per mm of travel).

Where the runs keep their ``final.dump``, the layer laid before the sampling region (its particles'
final x more than 1 mm short of it) is counted too, with the share of the run's particle-steps it
takes after the roller's axis is ``--laid-lag-mm`` past each of its particles: what deleting that layer
behind the roller would save (``<name>_laid.csv``, and a table in ``<name>.md``).
"""
from __future__ import annotations

import argparse
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: this checkout's `analysis` importable

from analysis.config.fidelity import scene  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.dem.liggghts import read_log  # noqa: E402
from analysis.metrics.dump import read_dump  # noqa: E402

PHASES = ("run_in", "region", "run_out", "laid_checks")
ROLLER = re.compile(r"^variable roller_stop_x equal (\S+)\+(\S+)\*step", re.MULTILINE)
POINT = re.compile(r"U = (\S+) mm/s, omega = (\S+) rad/s")
GROUPS = {-1: "forward rolling (omega < 0)", 0: "still (omega = 0)", 1: "counter-rotating (omega > 0)"}


def phase_edges(sampling_region: tuple, travel_end: float) -> np.ndarray:
    """Axis positions [m] where the phases of :data:`PHASES` begin, after the first."""
    return np.array([sampling_region[0], sampling_region[1], travel_end])


def read_run(folder: Path) -> dict:
    """A finished spread, read once: its folder, point (``U_mm_s``, ``omega_rad_s``), the roller's axis
    ``x0 + dx * step`` [m] and the log's thermo rows."""
    text = (folder / "spread.in").read_text()
    axis = ROLLER.search(text)
    point = POINT.search(text.splitlines()[0])
    if axis is None or point is None:
        raise ValueError(f"{folder / 'spread.in'}: no roller_stop_x line or no 'U = .. mm/s, omega = ..' header")
    thermo = read_log((folder / "spread.log").read_text())["thermo"]
    if len(thermo) < 2 or "CPU" not in thermo:
        raise ValueError(f"{folder / 'spread.log'}: fewer than 2 thermo rows with a CPU column")
    return {"folder": folder, "U_mm_s": float(point.group(1)), "omega_rad_s": float(point.group(2)),
            "x0": float(axis.group(1)), "dx": float(axis.group(2)), "thermo": thermo}


def run_phases(run: dict, edges: np.ndarray) -> list[dict]:
    """One row per phase of a run (:func:`read_run`): travel [mm], elapsed time [s] and particle-steps in it.

    The ``CPU`` column restarts at each ``run`` segment: an interval's time is the rise since the previous
    thermo row, or the row's own value where the column fell (a new segment's first row)."""
    x0, dx = run["x0"], run["dx"]
    step, atoms, cpu = (run["thermo"][c].to_numpy(float) for c in ("Step", "Atoms", "CPU"))
    rise = np.diff(cpu)
    d_time = np.where(rise >= 0, rise, cpu[1:])
    d_steps = np.clip(np.diff(step), 0, None)
    x_end = x0 + dx * step[1:]
    phase = np.searchsorted(edges, x_end, side="left")  # an interval ending on an edge: the phase before
    x_start = np.concatenate([[x0 + dx * step[0]], x_end[:-1]])
    rows = []
    for k, name in enumerate(PHASES):
        sel = phase == k
        rows.append({"run": run["folder"].name, "U_mm_s": run["U_mm_s"], "omega_rad_s": run["omega_rad_s"],
                     "phase": name, "travel_mm": float(np.sum(x_end[sel] - x_start[sel]) * 1e3),
                     "time_s": float(d_time[sel].sum()),
                     "particle_steps": float(np.sum(d_steps[sel] * atoms[1:][sel]))})
    return rows


def laid_before_region(run: dict, sampling_start: float, lag: float) -> dict:
    """The layer a run (:func:`read_run`) laid before the sampling region (``sampling_start`` [m]; its
    particles' final x more than 1 mm short of it, from ``final.dump``): their number, and the share of the
    run's particle-steps they take after the roller's axis is ``lag`` [m] past each one's final x."""
    step, atoms = (run["thermo"][c].to_numpy(float) for c in ("Step", "Atoms"))
    total = float(np.sum(np.clip(np.diff(step), 0, None) * atoms[1:]))
    x = read_dump(run["folder"] / "final.dump").atoms["x"].to_numpy()
    before = x[x < sampling_start - 1e-3]
    past = np.clip(step[-1] - (before + lag - run["x0"]) / run["dx"], 0.0, None)  # from the axis lag past to the stop
    return {"run": run["folder"].name, "U_mm_s": run["U_mm_s"], "omega_rad_s": run["omega_rad_s"],
            "laid_before_region": int(before.size), "particle_steps": total,
            "share_after_lag_pct": 100 * float(past.sum()) / total}


def summarise_laid(laid: pd.DataFrame) -> pd.DataFrame:
    """Per group of omega and overall: runs, the median number of particles laid before the region, and
    the share [%] of the group's particle-steps (summed over its runs) they take after the lag."""
    laid = laid.assign(group=np.sign(laid["omega_rad_s"]).astype(int).map(GROUPS),
                       saved=laid["share_after_lag_pct"] * laid["particle_steps"])
    rows = [{"runs": group, "n": len(frame), "laid_before_region": frame["laid_before_region"].median(),
             "share_after_lag_pct": frame["saved"].sum() / frame["particle_steps"].sum()}
            for group, frame in [*laid.groupby("group", sort=False), ("all runs", laid)]]
    return pd.DataFrame(rows)


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """Per group of omega and overall: each phase's share of the time and of the travel [%], and its
    seconds per mm of travel [s/mm], summed over the group's runs."""
    runs = runs.assign(group=np.sign(runs["omega_rad_s"]).astype(int).map(GROUPS))
    rows = []
    for group, frame in [*runs.groupby("group", sort=False), ("all runs", runs)]:
        total = frame.groupby("phase")[["time_s", "travel_mm"]].sum().reindex(PHASES)
        row = {"runs": group, "n": frame["run"].nunique(), "time_s": total["time_s"].sum()}
        for name in PHASES:
            row[f"{name}_time_pct"] = 100 * total.loc[name, "time_s"] / total["time_s"].sum()
        for name in PHASES:
            row[f"{name}_travel_pct"] = 100 * total.loc[name, "travel_mm"] / total["travel_mm"].sum()
        for name in PHASES:
            mm = total.loc[name, "travel_mm"]
            row[f"{name}_s_per_mm"] = total.loc[name, "time_s"] / mm if mm > 0 else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="a map's runs folder (results/<level>/runs)")
    parser.add_argument("--level", default="default", help="the level whose region and run-out the runs had")
    parser.add_argument("--laid-lag-mm", type=float, default=8.0,
                        help="how far past a particle of the layer laid before the region the roller's axis is "
                             "when deleting it is counted as saving its particle-steps (mm)")
    parser.add_argument("--name", default="travel_time")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    config = load_config(ROOT / "config.yaml")
    if args.level not in config["fidelity"]:
        parser.error(f"--level: {args.level!r} is not one of {sorted(config['fidelity'])}")
    s = scene(config, args.level)
    edges = phase_edges(s.sampling_region, s.travel_end)
    folders = sorted(p.parent for p in args.runs.rglob("spread.in") if (p.parent / "spread.log").exists())
    if not folders:
        parser.error(f"--runs {args.runs}: no folder with spread.in and spread.log under it")
    read = [read_run(folder) for folder in folders]
    runs = pd.DataFrame([row for run in read for row in run_phases(run, edges)])
    table = summarise(runs)
    args.out.mkdir(parents=True, exist_ok=True)
    runs.to_csv(args.out / f"{args.name}.csv", index=False)
    command = " ".join(argv if argv is not None else sys.argv[1:])
    x0, x1 = s.sampling_region[:2]
    text = (f"# Where along the travel a spread's time goes ({args.level} level)\n\n"
            f"Read {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()} (no DEM: finished runs' "
            f"logs), by\n`.venv/bin/python benchmarks/travel_time.py {command}`.\n\n"
            f"Phases of the roller's axis: `run_in` from its start to the region ({x0 * 1e3:g} mm), `region` "
            f"over it (to {x1 * 1e3:g} mm), `run_out` to {s.travel_end * 1e3:g} mm (where the layer-laid checks "
            "begin), `laid_checks` until it stops. Time: LIGGGHTS' thermo `cpu`, its elapsed seconds (its CPU "
            "seconds where it has a core to itself), summed over the runs of each group; `_time_pct` and "
            "`_travel_pct`: each phase's share, `_s_per_mm`: its seconds per mm of travel.\n\n"
            + table.to_markdown(index=False, floatfmt=".1f") + "\n")
    if all((f / "final.dump").exists() for f in folders):
        laid = pd.DataFrame([laid_before_region(run, x0, args.laid_lag_mm * 1e-3) for run in read])
        laid.to_csv(args.out / f"{args.name}_laid.csv", index=False)
        summary = summarise_laid(laid)
        text += (f"\n## The layer laid before the region\n\nParticles whose final x is more than 1 mm short of "
                 f"the region ({x0 * 1e3:g} mm), median per run, and the share of the runs' particle-steps they "
                 f"take after the roller's axis is {args.laid_lag_mm:g} mm past each (what deleting them there "
                 f"would save; `{args.name}_laid.csv` per run):\n\n"
                 + summary.to_markdown(index=False, floatfmt=".1f") + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
