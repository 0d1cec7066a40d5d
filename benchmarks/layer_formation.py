"""How far behind the moving roller the layer is laid: the layer's mass along x, frame by frame.

Usage::

    .venv/bin/python benchmarks/layer_formation.py --runs DIR [--bin-mm 1] [--name layer_formation]
        [--out benchmarks/measured]

A forward-rolling roller drags powder backward under it: the layer at x keeps
gaining mass after the roller's axis has passed x, until the roller is far
enough ahead that its surface no longer reaches the layer. A sampling region
closer than that to where the roller stops (``run_out_mm``) measures a layer
still being laid. This benchmark measures that reach from runs kept by
``bench_fidelity.py --keep DIR --movie-every-mm X`` (folders
``<variant>_s<seed>_U<U>_w<omega>/`` holding ``movie.dump``, ``final.dump``
and ``health.json``), with no new DEM.

For each ``--bin-mm`` bin of x behind where the roller stopped, the bin's
layer is *complete* from the first frame after which its mass stays within
:data:`COMPLETE_TOLERANCE` of its mass at rest (``final.dump``); the
*formation length* is the roller axis' x at that frame less the bin's far
end: how far past a bin the roller travels before the layer there is laid. A
bin completed only after the roller stopped (while the layer came to rest)
was still being laid when the roller stopped: its formation length is the
distance to the stop, a lower bound (``complete_before_stop`` false).

``--past-mm 2,4,6``: the four metrics over the level's sampling region
measured on the frames where the roller's axis was that far past the
region's end, against the same run's at rest (``<name>_past.csv``, and a
table in ``<name>.md``): within one run, so free of the seed spread, what
stopping the roller that far past the region would have missed of the layer
the roller lays if it travels on (a roller stopped there also stops
dragging, so this is the layer's state, not a stopped run's).

Writes ``<name>.csv`` (one row per run and bin), ``<name>.md`` (per variant
and bin: the layer's mass per area at rest and the formation length over the
runs) and ``<name>.png`` (mass per area at rest along x, every run, each
variant's sampling region shaded and stop marked).
"""
from __future__ import annotations

import argparse
import json
import platform
import re
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.fidelity import scene  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.metrics.deposit import deposit_profile  # noqa: E402
from analysis.metrics.dump import read_dump, read_frames  # noqa: E402
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units  # noqa: E402
from benchmarks.bench_fidelity import METRICS, VARIANTS, variant_config  # noqa: E402

KEPT = re.compile(r"(?P<variant>.+)_s(?P<seed>\d+)_U(?P<U>[-\d.]+)_w(?P<omega>[-\d.]+)$")

#: A bin's layer is complete once its mass stays within this share of its mass at rest (above it
#: while the pile ahead of the roller covers the bin, below it while the layer is still being laid).
COMPLETE_TOLERANCE = 0.05


def completion_frame(masses: np.ndarray, at_rest: np.ndarray, tolerance: float = COMPLETE_TOLERANCE) -> np.ndarray:
    """Index of the first frame after which each bin's mass stays within ``tolerance`` of ``at_rest``.

    ``masses`` is (frames, bins); a bin never complete gets the number of frames."""
    ok = np.abs(masses - at_rest[None, :]) <= tolerance * at_rest[None, :]
    stays = np.flip(np.logical_and.accumulate(np.flip(ok, axis=0), axis=0), axis=0)
    return np.where(stays.any(axis=0), stays.argmax(axis=0), len(masses))


def read_movie(run: Path):
    """A kept run's frames, the roller axis' x [m] at each (where it stopped, once it has), the x [m]
    where it stopped, and its final state at rest."""
    health = json.loads((run / "health.json").read_text())
    x0, travel = health["roller_start_m"], health["roller_travel_m"]
    frames = list(read_frames(run / "movie.dump"))
    steps = np.array([f.timestep for f in frames])
    roller_x = x0 + np.minimum(steps * health["timestep_s"] * health["U_mm_s"] * 1e-3, travel)
    return frames, roller_x, x0 + travel, read_dump(run / "final.dump")


def formation(frames, roller_x: np.ndarray, stop: float, rest, density: float, bin_width: float) -> pd.DataFrame:
    """One row per bin [SI inside, mm and mg/mm^2 out] of a run's movie (:func:`read_movie`)."""
    width = float(np.diff(rest.box[1])[0])
    first, last = int(np.floor(roller_x[0] / bin_width)), int(np.floor(stop / bin_width))  # whole bins behind the stop
    x_range = (first * bin_width, last * bin_width)  # on multiples of the bin: every run's bins line up
    edges = np.arange(first, last + 1) * bin_width
    areal = np.array([deposit_profile(f.atoms, density, width, x_range, bin_width)["areal_mass_mg_mm2"]
                      for f in frames])
    at_rest = deposit_profile(rest.atoms, density, width, x_range, bin_width)["areal_mass_mg_mm2"].to_numpy()
    done = completion_frame(areal, at_rest)
    moving = roller_x < stop - 1e-9
    before_stop = np.append(moving, False)[done]  # completed while the roller still moved
    x_complete = np.where(at_rest > 0, np.append(roller_x, stop)[done], np.nan)  # an empty bin: no layer
    return pd.DataFrame({
        "bin_start_mm": np.round(edges[:-1] * 1e3, 6), "bin_end_mm": np.round(edges[1:] * 1e3, 6),
        "layer_mg_per_mm2": at_rest,
        "x_roller_complete_mm": x_complete * 1e3,
        "formation_length_mm": (x_complete - edges[1:]) * 1e3,
        "complete_before_stop": before_stop & (at_rest > 0),
        "stop_mm": stop * 1e3, "frames": len(frames)})


def region_metrics(run: Path, U_mm_s: float, s, profilometer_seed: int):
    """``measure(frame)``: the four metrics [report units] over ``s``'s sampling region of a frame of
    kept run ``run`` (on its own substrate), as the fidelity benchmark measures them."""
    def measure(frame) -> dict:
        return to_report_units(spread_layer_metrics(frame, s.sampling_region, U_mm_s * 1e-3, s.density,
                                                    substrate=run / "substrate.stl", n_lines=s.profilometer_lines,
                                                    seed=profilometer_seed))
    return measure


def region_past(frames, roller_x: np.ndarray, stop: float, s, past_mm: list[float], measure,
                at_rest: dict) -> pd.DataFrame:
    """The four metrics (``measure(frame)``, :func:`region_metrics`) over ``s``'s sampling region on the frame
    nearest each ``past_mm`` [mm] of the roller's axis past the region's end (none past where it stopped),
    and ``at_rest`` (``past_mm`` NaN)."""
    end = s.sampling_region[1]
    measured = [(d, roller_x[k], measure(frames[k])) for d in sorted(past_mm) if end + d * 1e-3 < stop
                for k in [int(np.argmin(np.abs(roller_x - (end + d * 1e-3))))]]
    measured.append((np.nan, np.nan, at_rest))
    return pd.DataFrame([{"past_mm": d, "x_roller_mm": x * 1e3, **{k: report[k] for k in METRICS}}
                         for d, x, report in measured])


def region_speed(atoms: pd.DataFrame, region: tuple, density: float, mean_mass: float) -> float:
    """The sampling region's particles' speed [m/s] as the stop rule (``layer_laid``) sees it: the RMS
    speed of a mean-mass particle with their mean kinetic energy (over every particle whose centre's x
    is in the region, at any height)."""
    inside = atoms[(atoms["x"] >= region[0]) & (atoms["x"] < region[1])]
    if inside.empty:
        return 0.0
    mass = density * 4.0 / 3.0 * np.pi * inside["radius"].to_numpy() ** 3
    v2 = (inside[["vx", "vy", "vz"]].to_numpy() ** 2).sum(axis=1)
    return float(np.sqrt(np.mean(mass * v2) / mean_mass))


def rule_stop(speeds: np.ndarray, threshold: float, checks: int) -> int | None:
    """Index of the first check ending ``checks`` in a row with ``speeds`` below ``threshold`` (None: never)."""
    run = 0
    for k, slow in enumerate(speeds < threshold):
        run = run + 1 if slow else 0
        if run >= checks:
            return k
    return None


def stop_rules(frames, roller_x: np.ndarray, stop: float, s, rules: list, min_mm: float, measure,
               at_rest: dict) -> pd.DataFrame:
    """Where each ``(speed [mm/s], checks)`` rule, checked on the movie's frames from ``min_mm`` past the
    region's end on, would have stopped the roller, and the four metrics there (``measure(frame)``,
    :func:`region_metrics`) against ``at_rest``. A rule never met stops where the run stopped."""
    end = s.sampling_region[1]
    first = end + min_mm * 1e-3 - 1e-9
    k_checks = [k for k in range(len(frames)) if first <= roller_x[k] < stop - 1e-9]
    speeds = np.array([region_speed(frames[k].atoms, s.sampling_region, s.density, s.mean_particle_mass)
                       for k in k_checks]) * 1e3
    measured, rows = {None: at_rest}, []  # by check index (None: at rest), each frame measured once
    for speed, checks in rules:
        i = rule_stop(speeds, speed, checks)
        x = roller_x[k_checks[i]] if i is not None else stop
        if i not in measured:
            measured[i] = measure(frames[k_checks[i]])
        rows.append({"rule_mm_s": speed, "rule_checks": checks, "laid_before_end": i is not None,
                     "stop_past_mm": (x - end) * 1e3,
                     **{f"{name}_change_pct": 100 * (measured[i][k] - at_rest[k]) / at_rest[k]
                        for k, name in METRICS.items()}})
    return pd.DataFrame(rows)


def rules_table(rules: pd.DataFrame) -> pd.DataFrame:
    """Per rule: where it stops (median and largest distance past the region), how many runs it stopped
    before they ended, and each metric's mean and largest absolute change from the run at rest."""
    out = []
    for (speed, checks), g in rules.groupby(["rule_mm_s", "rule_checks"]):
        row = {"at rest below (mm/s)": speed, "checks in a row": checks, "runs": len(g),
               "stopped before the run's end": int(g["laid_before_end"].sum()),
               "stop past the region (mm), median / max": f"{g['stop_past_mm'].median():.1f} / "
                                                           f"{g['stop_past_mm'].max():.1f}"}
        for name in METRICS.values():
            change = g[f"{name}_change_pct"].abs()
            row[f"|{name} change| (%), mean / max"] = f"{change.mean():.1f} / {change.max():.1f}"
        out.append(row)
    return pd.DataFrame(out)


def past_table(past: pd.DataFrame) -> pd.DataFrame:
    """Per variant, point and distance past the region: each metric's mean change from the same run at
    rest (% of that run's) and its range over the runs."""
    rest = past[past["past_mm"].isna()].set_index(["variant", "seed", "U_mm_s", "omega_rad_s"])[list(METRICS)]
    moving = past[past["past_mm"].notna()].set_index(["variant", "seed", "U_mm_s", "omega_rad_s"])
    change = 100 * (moving[list(METRICS)] - rest.reindex(moving.index)) / rest.reindex(moving.index)
    change["past_mm"] = moving["past_mm"]
    out = []
    for (variant, U, omega, d), g in change.reset_index().groupby(["variant", "U_mm_s", "omega_rad_s", "past_mm"]):
        row = {"variant": variant, "U (mm/s)": U, "omega (rad/s)": omega, "roller past the region's end (mm)": d,
               "runs": len(g)}
        for k, name in METRICS.items():
            row[f"{name} change (%)"] = f"{g[k].mean():+.1f} ({g[k].min():+.1f} to {g[k].max():+.1f})"
        out.append(row)
    return pd.DataFrame(out)


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """Per variant and bin: mean mass per area at rest and the formation length over the runs."""
    grouped = rows.groupby(["variant", "bin_start_mm"], sort=True)
    return grouped.agg(runs=("seed", "size"), layer_mg_per_mm2=("layer_mg_per_mm2", "mean"),
                       layer_sd=("layer_mg_per_mm2", "std"),
                       formation_median_mm=("formation_length_mm", "median"),
                       formation_max_mm=("formation_length_mm", "max"),
                       complete_before_stop=("complete_before_stop", "sum")).reset_index()


def plot(rows: pd.DataFrame, regions: dict, path: Path) -> None:
    """Mass per area at rest along x, every run; each variant's region shaded and stop marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    variants = sorted(rows["variant"].unique())
    fig, axes = plt.subplots(len(variants), 1, figsize=(7, 2.6 * len(variants)), sharex=True, squeeze=False)
    for ax, variant in zip(axes[:, 0], variants):
        for (seed, U, omega), run in rows[rows["variant"] == variant].groupby(["seed", "U_mm_s", "omega_rad_s"]):
            centre = (run["bin_start_mm"] + run["bin_end_mm"]) / 2
            ax.plot(centre, run["layer_mg_per_mm2"], marker=".", label=f"s{seed} U{U:g} w{omega:g}")
            ax.axvline(run["stop_mm"].iloc[0], color="k", lw=0.8)
        ax.axvspan(*regions[variant], color="grey", alpha=0.2)
        ax.set_title(f"{variant} (region shaded, roller stops at the line)", fontsize=9)
        ax.set_ylabel("layer at rest [mg/mm$^2$]")
        ax.legend(fontsize=6)
    axes[-1, 0].set_xlabel("x [mm]")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="bench_fidelity.py --keep folder (with movies)")
    parser.add_argument("--level", default="default")
    parser.add_argument("--bin-mm", type=float, default=1.0)
    parser.add_argument("--past-mm", default="",
                        help="comma-separated distances [mm] of the roller past the region's end at which to measure "
                             "the region, against the same run at rest")
    parser.add_argument("--stop-rules", default="",
                        help="comma-separated SPEED:CHECKS stop rules (layer_laid: the region's RMS speed in mm/s "
                             "below SPEED at CHECKS frames in a row) to try on the movies' frames")
    parser.add_argument("--rules-from-mm", type=float, default=2.0,
                        help="the rules' first check this far past the region's end [mm] (run_out_mm)")
    parser.add_argument("--name", default="layer_formation")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    if not args.bin_mm > 0:
        parser.error(f"--bin-mm {args.bin_mm}: a positive bin width [mm]")
    runs = sorted(p for p in args.runs.glob("*") if KEPT.match(p.name) and (p / "movie.dump").exists())
    if not runs:
        parser.error(f"--runs {args.runs}: no kept run with a movie.dump (bench_fidelity.py --keep DIR "
                     "--movie-every-mm X)")
    try:
        past_mm = [float(v) for v in args.past_mm.split(",") if v.strip()]
    except ValueError:
        parser.error(f"--past-mm {args.past_mm!r}: comma-separated distances in mm")
    try:
        rules = [(float(a), int(b)) for a, b in (r.split(":") for r in args.stop_rules.split(",") if r.strip())]
    except ValueError:
        parser.error(f"--stop-rules {args.stop_rules!r}: comma-separated SPEED:CHECKS, e.g. 1:3,0.5:2")
    if any(speed <= 0 or checks < 1 for speed, checks in rules):
        parser.error(f"--stop-rules {args.stop_rules!r}: a positive speed and at least 1 check")
    base = load_config(ROOT / "config.yaml")
    rows, regions, past, tried = [], {}, [], []
    for run in runs:
        key = KEPT.match(run.name).groupdict()
        if key["variant"] not in VARIANTS:
            parser.error(f"{run}: unknown variant {key['variant']!r}")
        s = scene(variant_config(base, args.level, VARIANTS[key["variant"]]), args.level)
        regions[key["variant"]] = (s.sampling_region[0] * 1e3, s.sampling_region[1] * 1e3)
        print(f"{run.name}: reading the movie", flush=True)
        labels = dict(variant=key["variant"], seed=int(key["seed"]), U_mm_s=float(key["U"]),
                      omega_rad_s=float(key["omega"]))
        frames, roller_x, stop, rest = read_movie(run)
        rows.append(formation(frames, roller_x, stop, rest, s.density, args.bin_mm * 1e-3).assign(**labels))
        if past_mm or rules:
            measure = region_metrics(run, labels["U_mm_s"], s, base["profilometer"]["seed"])
            at_rest = measure(rest)  # once, for both tables
        if past_mm:
            past.append(region_past(frames, roller_x, stop, s, past_mm, measure, at_rest).assign(**labels))
        if rules:
            tried.append(stop_rules(frames, roller_x, stop, s, rules, args.rules_from_mm, measure,
                                    at_rest).assign(**labels))
    rows = pd.concat(rows, ignore_index=True)
    args.out.mkdir(parents=True, exist_ok=True)
    rows.to_csv(args.out / f"{args.name}.csv", index=False)
    plot(rows, regions, args.out / f"{args.name}.png")
    table = summarise(rows)
    command = f"`.venv/bin/python benchmarks/layer_formation.py {' '.join(argv if argv is not None else sys.argv[1:])}`"
    text = (f"# How far behind the roller the layer is laid ({args.level} level)\n\n"
            f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, from {len(runs)} "
            f"kept runs ({rows['frames'].min()}-{rows['frames'].max()} frames each), by\n{command}.\n\n"
            f"Per {args.bin_mm:g} mm bin of x: the layer's mass per area at rest (mean and sd over the runs) and "
            f"its formation length (the roller axis' x when the bin's mass stays within "
            f"{COMPLETE_TOLERANCE:.0%} of that, less the bin's far end; median and largest over the runs); "
            f"`complete_before_stop`: runs whose bin was laid before the roller stopped (else its formation "
            f"length is a lower bound). Regions (mm): "
            + ", ".join(f"`{v}` {a:g}-{b:g}" for v, (a, b) in sorted(regions.items())) + ".\n\n"
            + table.to_markdown(index=False, floatfmt=".2f") + "\n")
    if past:
        past = pd.concat(past, ignore_index=True)
        past.to_csv(args.out / f"{args.name}_past.csv", index=False)
        text += ("\n## The region measured while the roller travels on\n\nEach metric over the region on the frame "
                 "nearest each distance of the roller's axis past the region's end, against the same run at rest: "
                 "mean change over the runs (% of the run at rest; smallest to largest).\n\n"
                 + past_table(past).to_markdown(index=False, floatfmt=".1f") + "\n")
    if tried:
        tried = pd.concat(tried, ignore_index=True)
        tried.to_csv(args.out / f"{args.name}_rules.csv", index=False)
        text += (f"\n## Stop rules tried on the frames\n\nEach rule checked on the movie's frames from "
                 f"{args.rules_from_mm:g} mm past the region's end on: the roller would stop at the first frame "
                 "ending that many frames in a row at which the region's particles move slower than that (RMS "
                 "speed of a mean-mass particle with their mean kinetic energy); the four metrics over the region "
                 "on that frame against the same run at rest (a rule never met: where the run stopped).\n\n"
                 + rules_table(tried).to_markdown(index=False) + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
