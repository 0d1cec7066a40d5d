"""The engine's own rate with the spread's contact model: a settled heap left at rest, no roller.

Usage::

    .venv/bin/python benchmarks/resting_rate.py [--level default] [--steps 20000] [--repeats 3]
        [--spread-points 70:-15,70:0] [--name resting_rate] [--out benchmarks/measured]

A spreading step's cost is judged against what the same LIGGGHTS build does with the same particles
and contact model when nothing moves: the ceiling a cheaper spreading step could approach. One heap
of the level is made and settled (replicate 0), then, from its settled restart, the particles over the
flat bed (ahead of the rough patch) are left at rest for ``--steps`` time steps in each variant,
``--repeats`` times, the variants interleaved (one run at a time, so their ratios are measured in one
run):

* ``as_spread``: the spread's contact model (Hertz, tangential history, and rolling friction epsd2 where
  the level's powder has it) against the substrate's mesh;
* ``flat_wall``: the same against a flat primitive wall at the bed's mean plane instead of the mesh.

(Without rolling friction the settled restart's contact histories do not fit: LIGGGHTS refuses it.)

Then the same heap is spread at each of ``--spread-points`` (U [mm/s]:omega [rad/s]; empty: none),
the variant ``spread U:omega``, its particle-steps counted over every particle integrated.

The rate is particle-steps (particles x steps) per CPU second of LIGGGHTS (its user + system time).
Writes ``<name>.csv`` (one row per run) and ``<name>.md`` (per variant: median rate and its ratio to
``as_spread``).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: this checkout's `analysis` importable

from analysis.config.fidelity import scene  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.dem.inputs import binsize, contact_model, processors_grid, skin  # noqa: E402
from analysis.dem.liggghts import input_path, render, run  # noqa: E402
from analysis.dem.simulate import THERMO_EVERY, make_geometry, settle, spread  # noqa: E402
from benchmarks.machine import commit, machine  # noqa: E402

#: variant -> the bed as a flat primitive wall (else the substrate's mesh)
VARIANTS = {"as_spread": False, "flat_wall": True}


def rest_run(config: dict, level: str, variant: str, settled: Path, meshes: Path, outdir: Path,
             steps: int) -> dict:
    """Run the settled heap of ``settled`` at rest for ``steps`` steps in ``variant``; its log's
    ``cpu_s`` [s], particles and steps, ``particle_steps_per_cpu_s`` and the fastest particle's speed
    ``max_speed_m_s`` [m/s] (at rest: the rate is not that of a moving heap)."""
    s, flat = scene(config, level), VARIANTS[variant]
    outdir.mkdir(parents=True, exist_ok=True)
    text = render("rest.in.j2", s=s, variant=variant, steps=steps, contact=contact_model(s),
                  processors=processors_grid(s), restart=input_path(settled / "settled.restart", outdir),
                  skin=skin(s), binsize=binsize(s), thermo_every=THERMO_EVERY, flat_wall=flat,
                  substrate_stl=input_path(meshes / "substrate.stl", outdir), box=[f"{v:.6g}" for v in s.box],
                  keep_below_x=s.rough_x[0] - 1e-3)
    (outdir / "rest.in").write_text(text)
    log = run(outdir / "rest.in", outdir / "rest.log", ranks=s.mpi_ranks)
    particles = int(log["thermo"]["Atoms"].iloc[-1])
    return {"variant": variant, "particles": particles, "steps": steps, "cpu_s": log["cpu_s"],
            "particle_steps_per_cpu_s": particles * steps / log["cpu_s"],
            "max_speed_m_s": float(log["thermo"]["vmax"].max())}


def summarise(runs: pd.DataFrame) -> pd.DataFrame:
    """Per variant: runs, particles, the median rate [M particle-steps per CPU s], its ratio to ``as_spread``
    and the fastest particle over its runs [m/s]."""
    table = runs.groupby("variant", sort=False).agg(runs=("cpu_s", "size"), particles=("particles", "first"),
                                                    rate=("particle_steps_per_cpu_s", "median"),
                                                    max_speed_m_s=("max_speed_m_s", "max"))
    table["rate_M_per_cpu_s"] = table.pop("rate") / 1e6
    table["vs_as_spread"] = table["rate_M_per_cpu_s"] / table.loc["as_spread", "rate_M_per_cpu_s"]
    return table.reset_index()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", default="default")
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--spread-points", default="70:-15,70:0",
                        help="U:omega pairs (mm/s:rad/s) the same heap is then spread at; empty: none")
    parser.add_argument("--name", default="resting_rate")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.repeats < 1:
        parser.error(f"--steps {args.steps} and --repeats {args.repeats}: each at least 1")
    try:
        points = [tuple(float(v) for v in p.split(":")) for p in args.spread_points.split(",") if p]
        assert all(len(p) == 2 for p in points)
    except (ValueError, AssertionError):
        parser.error(f"--spread-points {args.spread_points!r}: U:omega pairs (mm/s:rad/s), comma-separated")
    config = load_config(ROOT / "config.yaml")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        make_geometry(config, args.level, work / "meshes")
        settled = settle(config, args.level, work / "meshes", work / "settle")
        print(f"settled {settled['inserted']} particles", file=sys.stderr)
        for repeat in range(args.repeats):
            for variant in VARIANTS:
                row = rest_run(config, args.level, variant, work / "settle", work / "meshes",
                               work / f"{variant}_{repeat}", args.steps)
                rows.append({"repeat": repeat, **row})
                print(f"{variant} #{repeat}: {row['particle_steps_per_cpu_s'] / 1e6:.2f} M particle-steps per CPU s",
                      file=sys.stderr)
        for U, omega in points:
            run_dir = work / f"spread_{U:g}_{omega:g}"
            health = spread(config, args.level, U, omega, work / "meshes", work / "settle", run_dir)
            steps = int(health["steps"])
            rows.append({"repeat": 0, "variant": f"spread {U:g}:{omega:g}",
                         "particles": round(health["particle_steps"] / steps), "steps": steps,
                         "cpu_s": health["cpu_s"],
                         "particle_steps_per_cpu_s": health["particle_steps"] / health["cpu_s"],
                         "max_speed_m_s": health["peak_speed_m_s"]})
            print(f"spread {U:g}:{omega:g}: {rows[-1]['particle_steps_per_cpu_s'] / 1e6:.2f} M particle-steps per "
                  "CPU s", file=sys.stderr)
    runs = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    runs.to_csv(args.out / f"{args.name}.csv", index=False)
    table = summarise(runs)
    lines = [f"# The engine's resting rate with the spread's contact model ({args.level} level)", "",
             f"Measured on {machine()}, commit {commit()}, LIGGGHTS from apt, one run at a time, by",
             "", f"    .venv/bin/python benchmarks/resting_rate.py --level {args.level} --steps {args.steps} "
             f"--repeats {args.repeats} --spread-points '{args.spread_points}' --name {args.name}", "",
             "The level's settled heap (replicate 0) over the flat bed, left at rest; particle-steps per CPU "
             "second of LIGGGHTS (median over the repeats). Variants: `as_spread` the spread's contact model "
             "against the substrate's mesh; `flat_wall` the same against a flat primitive wall; `spread U:omega` "
             "the same heap spread at that point (particles: the mean integrated over its steps).", "",
             "| variant | runs | particles | M particle-steps per CPU s | vs as_spread | fastest particle (m/s) |",
             "|---|---:|---:|---:|---:|---:|"]
    lines += [f"| `{r.variant}` | {r.runs} | {r.particles} | {r.rate_M_per_cpu_s:.2f} | {r.vs_as_spread:.2f} | "
              f"{r.max_speed_m_s:.2g} |" for r in table.itertuples()]
    (args.out / f"{args.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
