"""MPI scaling of a spreading run, the paper level's start-up, and the projected cluster cost.

Usage::

    .venv/bin/python benchmarks/bench_scaling.py [--levels smoke,default] [--ranks 1,2] [--paper-steps 200]

1. For each level: settle its heap once (one rank), then spread it at
   U = 100 mm/s, omega = -5 rad/s on each rank count, from the same heap, one
   run at a time; records wall time, particle-steps per second, speed-up and
   parallel efficiency, and the ``processors`` grid used.
2. The ``paper`` level: make its geometry, render its settle input and run
   ``--paper-steps`` steps of each settling phase at the full particle count
   on all cores; records particles, substrate triangles, peak memory (max RSS
   of LIGGGHTS) and the time per step.
3. A projection of one paper spread and of the 45-run sweep on N cores from
   those numbers, arithmetic written out.

Writes ``benchmarks/measured/scaling.md`` (machine and date included).
Run it on an otherwise idle machine: it measures wall time.
"""
from __future__ import annotations

import argparse
import copy
import os
import platform
import resource
import sys
import tempfile
import time
from math import ceil
from pathlib import Path

import numpy as np

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.dem.simulate import make_geometry, settle, spread

ROOT = Path(__file__).resolve().parent.parent

U_MM_S, OMEGA = 100.0, -5.0


def with_ranks(config: dict, level: str, ranks: int) -> dict:
    config = copy.deepcopy(config)
    config["fidelity"][level]["mpi_ranks"] = ranks
    return config


def scaling(config: dict, level: str, ranks: list[int]) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_geometry(config, level, tmp / "meshes")
        settle(with_ranks(config, level, 1), level, tmp / "meshes", tmp / "settle")
        for n in ranks:
            h = spread(with_ranks(config, level, n), level, U_MM_S, OMEGA, tmp / "meshes", tmp / "settle",
                       tmp / f"run{n}")
            rows.append({"level": level, "ranks": n, "grid": h["processors"], "particles": h["atoms"],
                         "steps": h["steps"], "wall_s": h["wall_s"], "rate": h["particle_steps_per_s"]})
            print(rows[-1], flush=True)
    return rows


def paper_start(config: dict, steps: int, ranks: int) -> dict:
    config = with_ranks(config, "paper", ranks)
    s = scene(config, "paper")
    (ROOT / "results").mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(dir=ROOT / "results") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        geometry = make_geometry(config, "paper", tmp / "meshes")
        t_geometry = time.perf_counter() - t0
        rss0 = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        try:
            h = settle(config, "paper", tmp / "meshes", tmp / "settle", max_steps=steps)
            error = None
        except Exception as err:  # noqa: BLE001 - a start-up failure is the result
            h, error = {}, str(err).splitlines()[0]
        rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        log = (tmp / "settle" / "settle.log").read_text(errors="replace")
    loop = [line for line in log.splitlines() if line.startswith("Loop time")]
    run_s = sum(float(line.split()[3]) for line in loop)
    run_steps = sum(int(line.split()[8]) for line in loop)
    return {"particles": s.heap_particles, "inserted": h.get("inserted"), "ranks": ranks,
            "substrate_triangles": geometry["substrate_triangles"], "geometry_s": t_geometry,
            "steps": run_steps, "run_s": run_s, "wall_s": h.get("wall_s"),
            "max_rss_MB_per_rank": max(rss, rss0) / 1024, "error": error,
            "timestep_s": s.timestep}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--levels", default="smoke,default")
    parser.add_argument("--ranks", default="1,2")
    parser.add_argument("--paper-steps", type=int, default=200, help="steps per settling phase (0: skip)")
    parser.add_argument("--cluster-cores", type=int, default=32, help="cores per paper run in the projection")
    args = parser.parse_args(argv)
    config = load_config(ROOT / "config.yaml")
    ranks = [int(r) for r in args.ranks.split(",")]
    rows = [row for level in args.levels.split(",") for row in scaling(config, level, ranks)]
    lines = ["| level | particles | ranks | processors grid | steps | wall s | particle-steps/s | speed-up | "
             "efficiency |", "|---|---:|---:|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        base = next(r for r in rows if r["level"] == row["level"] and r["ranks"] == ranks[0])
        speedup = base["wall_s"] / row["wall_s"] * row["steps"] / base["steps"]
        lines.append(f"| {row['level']} | {row['particles']} | {row['ranks']} | `{row['grid']}` | {row['steps']} | "
                     f"{row['wall_s']:.1f} | {row['rate']:.3g} | {speedup:.2f} | "
                     f"{speedup / row['ranks'] * ranks[0]:.0%} |")
    text = (f"# MPI scaling and the paper level's cost\n\nMeasured {time.strftime('%Y-%m-%d')} on "
            f"{platform.machine()}, {os.cpu_count()} cores, by `.venv/bin/python benchmarks/bench_scaling.py "
            f"{' '.join(argv if argv is not None else sys.argv[1:])}`.\n\n"
            f"## One spread (U = {U_MM_S:g} mm/s, omega = {OMEGA:g} rad/s), same settled heap\n\n"
            + "\n".join(lines) + "\n")
    # Projection of the paper level from the largest measured scene's single-rank rate
    big = max((r for r in rows if r["ranks"] == 1), key=lambda r: r["particles"])
    s = scene(config, "paper")
    n_cores = args.cluster_cores
    two = [r for r in rows if r["level"] == big["level"] and r["ranks"] == 2]
    efficiency = (big["wall_s"] / two[0]["wall_s"] * two[0]["steps"] / big["steps"] / 2) if two else 1.0
    sweep = config["sweep"]
    x0 = -np.sqrt(2 * s.roller_radius * (s.heap[3] - s.heap[2]))  # the roller starts just behind the heap
    steps_per_U = {U: ceil((s.travel_end - x0) / (U * 1e-3) / s.timestep + s.rest_time / s.timestep)
                   for U in sweep["U_mm_s"]}
    mean_steps = np.mean([steps_per_U[U] for U in sweep["U_mm_s"] for _ in sweep["omega_rad_s"]])
    particle_steps = s.heap_particles * mean_steps
    per_run_h = particle_steps / (big["rate"] * n_cores * efficiency) / 3600
    runs = len(sweep["U_mm_s"]) * len(sweep["omega_rad_s"]) * sweep["replicates"]
    text += (f"\n## Projection for the `paper` level\n\n"
             f"- time step {s.timestep:.3g} s ({len(s.diameters)} size classes, smallest "
             f"{min(s.diameters) * 1e6:.0f} um); roller travel {(s.travel_end - x0) * 1e3:.0f} mm plus up to "
             f"{s.rest_time:g} s of rest: {min(steps_per_U.values()):,} (U = {max(steps_per_U):g} mm/s) to "
             f"{max(steps_per_U.values()):,} (U = {min(steps_per_U):g} mm/s) steps, "
             f"mean {mean_steps:,.0f} over the sweep\n"
             f"- particle-steps per run: {s.heap_particles:,} x {mean_steps:,.0f} = {particle_steps:.3g}\n"
             f"- rate per core: {big['rate']:.3g} particle-steps/s (the `{big['level']}` spread on one rank, "
             f"above); parallel efficiency {efficiency:.0%} (its 2-rank run), assumed to hold on {n_cores} cores\n"
             f"- one run on {n_cores} cores: {particle_steps:.3g} / ({big['rate']:.3g} x {n_cores} x "
             f"{efficiency:.2f}) = **{per_run_h:.1f} h**; the {runs}-run sweep: {runs} x {per_run_h:.1f} = "
             f"**{runs * per_run_h:.0f} h** of wall time if run one after another, "
             f"{runs * per_run_h * n_cores:,.0f} core-hours; with all {runs} runs at once on "
             f"{runs * n_cores} cores, ~{per_run_h:.1f} h\n")
    if args.paper_steps:
        p = paper_start(config, args.paper_steps, os.cpu_count() or 1)
        print(p, flush=True)
        text += (f"\n## The `paper` level starts on this machine\n\n"
                 f"Geometry ({p['substrate_triangles']:,} substrate triangles) in {p['geometry_s']:.0f} s; "
                 f"settle input rendered and run on {p['ranks']} ranks for {args.paper_steps} steps per "
                 f"settling phase ({p['steps']} steps in all): {p['inserted'] or 0:,} of {p['particles']:,} "
                 f"particles inserted, LIGGGHTS' loop time {p['run_s']:.0f} s "
                 f"({p['run_s'] / max(p['steps'], 1):.2f} s per step), wall {p['wall_s'] or float('nan'):.0f} s "
                 f"including insertion, peak memory {p['max_rss_MB_per_rank']:.0f} MB per rank (max RSS)."
                 + (f" Failed: {p['error']}" if p["error"] else "") + "\n")
    out = ROOT / "benchmarks" / "measured" / "scaling.md"
    out.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
