"""Noise against the sampling region's length: the same layers re-measured over longer regions.

Usage::

    .venv/bin/python benchmarks/bench_region.py --replicates DIR [--map results/default/runs]
        [--regions 4-9,5-9,6-10.5,6-12] [--variant default] [--against REFERENCE] [--name region_noise]
        [--out benchmarks/measured]

The run-in and run-out of a spread are a fixed cost per run, so a longer
sampling region buys area, and lower noise, without more DEM. Whether that
area is usable is a question of physics: the layer must be in steady state
over it. This benchmark answers both from layers already simulated, with no
new DEM:

* ``--replicates``: runs kept by ``bench_fidelity.py --keep DIR`` (folders
  ``<variant>_s<seed>_U<U>_w<omega>/`` holding ``final.dump`` and
  ``substrate.stl``). Their seed-to-seed sd at each region gives the noise.
* ``--map``: a map's run folders (``results/<level>/runs``); their spread
  over the map's points at each region gives the signal, and each run's
  shift from the level's own region is the region's bias.
* ``--against``: another kept variant in the same folder (a bigger, stiffer
  reference), re-measured over the same regions: at each region, how far the
  variant's point means lie from the reference's, in the reference's pooled
  seed sd (as ``bench_fidelity.py --ladder`` judges a step).

Each region spans ``start-end`` [mm] along the spreading direction
(``--regions``; the level's own region is always one of them); across it,
the replicates' region spans the kept variant's own (a wider variant's layer
is measured over its whole strip, as ``bench_fidelity.py`` measured it), the
map's the level's. M_s is scaled to the level's own region area (mass per
area), so that every region's and variant's numbers read in the same units;
Q_s, R_q and Phi do not depend on the area.

Writes ``<name>.csv`` (one row per layer and region) and ``<name>.md``: per
region, the pooled seed sd of each metric (% of its mean), the noise
ceiling R_max = sqrt(1 - sd^2 / var(map)) a surrogate of the map could reach,
and the bias against the level's region in pooled seed sds of that region.
"""
from __future__ import annotations

import argparse
import platform
import re
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.fidelity import scene  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.dem.geometry import load_stl, substrate_rms  # noqa: E402
from analysis.dem.health import fed_share  # noqa: E402
from analysis.metrics.dump import read_dump  # noqa: E402
from analysis.metrics.noise_floor import POOLED, noise_floor  # noqa: E402
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units  # noqa: E402
from benchmarks.bench_fidelity import METRICS, VARIANTS, variant_config  # noqa: E402

KEPT = re.compile(r"(?P<variant>.+)_s(?P<seed>\d+)_U(?P<U>[-\d.]+)_w(?P<omega>[-\d.]+)$")
MAP_RUN = re.compile(r"U(?P<U>[-\d.]+)_w(?P<omega>[-\d.]+)_r(?P<seed>\d+)$")


def layers(replicates: Path | None, map_runs: Path | None, variant: str, against: str | None = None) -> list[dict]:
    """The layers to measure: ``{source, seed, U_mm_s, omega_rad_s, dump, substrate}``; ``source`` is
    ``replicates`` (the kept ``variant``), ``against`` (the kept ``against`` variant) or ``map``."""
    found = []
    sources = {variant: "replicates", **({against: "against"} if against else {})}
    for folder in sorted(replicates.iterdir()) if replicates else []:
        m = KEPT.match(folder.name)
        if m and m["variant"] in sources and (folder / "final.dump").exists():
            found.append({"source": sources[m["variant"]], "seed": int(m["seed"]), "U_mm_s": float(m["U"]),
                          "omega_rad_s": float(m["omega"]), "dump": folder / "final.dump",
                          "substrate": folder / "substrate.stl"})
    for folder in sorted(map_runs.iterdir()) if map_runs else []:
        m = MAP_RUN.match(folder.name)
        if m and (folder / "final.dump").exists():
            meshes = map_runs.parent / "meshes" / f"r{m['seed']}"
            found.append({"source": "map", "seed": int(m["seed"]), "U_mm_s": float(m["U"]),
                          "omega_rad_s": float(m["omega"]), "dump": folder / "final.dump",
                          "substrate": meshes / "substrate.stl"})
    return found


def measure(task) -> list[dict]:
    """One layer's four metrics over every region (M_s scaled to ``area_ref`` [m^2]), the share of
    its particles there that the feed added (ids above the settled heap's count) and the substrate's mean
    height under the region above the gap's datum (its mean plane under the run's own sampling region)."""
    layer, regions, area_ref, density, n_lines, seed = task
    frame = read_dump(layer["dump"], required=("id", "x", "y", "z", "radius"))
    substrate = load_stl(layer["substrate"])
    datum = substrate_rms(substrate, layer["own_x"])[0]
    rows = []
    for label, region in regions[layer["source"]]:
        try:
            report = to_report_units(spread_layer_metrics(
                frame, region, layer["U_mm_s"] * 1e-3, density, substrate=layer["substrate"],
                n_lines=n_lines, seed=seed))
        except ValueError:  # the region reaches past this layer's box (a shorter travel): not measured
            report = dict.fromkeys(METRICS, np.nan)
        area = (region[1] - region[0]) * (region[3] - region[2])
        row = {k: v for k, v in layer.items() if k not in ("dump", "substrate", "heap_particles", "own_x")}
        row.update({"region_mm": label, "start_mm": region[0] * 1e3, "end_mm": region[1] * 1e3,
                    "length_mm": (region[1] - region[0]) * 1e3,
                    **{k: report[k] for k in METRICS}})
        row["mass_g"] *= area_ref / area
        row["fed_pct"] = 100 * fed_share(frame.atoms, layer["heap_particles"] + 1, region)
        row["substrate_above_datum_um"] = 1e6 * (substrate_rms(substrate, region[:2])[0] - datum)
        rows.append(row)
    return rows


def summarise(runs: pd.DataFrame, own: str) -> pd.DataFrame:
    """Per region (``region_mm`` label): pooled seed sd (replicates), the map's spread, R_max, and the
    shift from the level's own region ``own``, on the map's runs and on the replicates (paired); with
    ``against`` rows (a reference variant), the largest distance of a point's replicate mean from the
    reference's (``<m>_vs_ref_sd``, in the reference's pooled seed sd over that region) and the mean
    change over the points (``<m>_vs_ref_pct``, % of the reference's means)."""
    point = ["U_mm_s", "omega_rad_s"]
    rep = runs[runs["source"] == "replicates"]
    mapped = runs[runs["source"] == "map"]
    ref = runs[runs["source"] == "against"]
    labels = list(dict.fromkeys(runs.sort_values(["length_mm", "start_mm"])["region_mm"]))
    floor = {}  # the replicates' pooled seed sd per region: the workflow's noise floor (its pooled row)
    for label in labels:
        table = noise_floor(rep[rep["region_mm"] == label]).set_index("point")
        floor[label] = table.loc[POOLED] if POOLED in table.index else pd.Series(dtype=float)
    sd = {(label, k): float(floor[label].get(f"{k}_sd", np.nan)) for label in labels for k in METRICS}
    rows = []
    for label in labels:
        one = runs[runs["region_mm"] == label].iloc[0]
        row = {"region_mm": label, "length_mm": one["length_mm"]}
        m = mapped[mapped["region_mm"] == label]
        for k, name in METRICS.items():
            s = sd[label, k]
            row[f"{name}_sd_pct"] = float(floor[label].get(f"{k}_rel_pct", np.nan))
            var_map = float(m[k].var(ddof=1)) if len(m) > 1 else np.nan
            row[f"{name}_R_max"] = (float(np.sqrt(max(0.0, 1 - s**2 / var_map)))
                                    if var_map > 0 and np.isfinite(s) else np.nan)
        for source, frame, by in (("map", mapped, "omega_rad_s"), ("rep", rep, point)):
            base = frame[frame["region_mm"] == own].set_index(point + ["seed"])
            other = frame[frame["region_mm"] == label].set_index(point + ["seed"])
            for k, name in METRICS.items():
                # each run's shift from its own value over the level's region, in that region's seed sd;
                # the largest mean shift of one omega's runs (map: over its U's) or of one point (replicates)
                shift = (other[k] - base[k]).dropna() / sd.get((own, k), np.nan)
                worst = shift.groupby(level=by).mean().abs().max() if len(shift) else np.nan
                row[f"{name}_{source}_shift_sd"] = worst
        if len(ref):
            here, there = rep[rep["region_mm"] == label], ref[ref["region_mm"] == label]
            ref_floor = noise_floor(there).set_index("point")
            means = here.groupby(point)[list(METRICS)].mean()
            ref_means = there.groupby(point)[list(METRICS)].mean()
            shared = means.index.intersection(ref_means.index)
            for k, name in METRICS.items():
                ref_sd = float(ref_floor.loc[POOLED, f"{k}_sd"]) if POOLED in ref_floor.index else np.nan
                diff = (means.loc[shared, k] - ref_means.loc[shared, k]).dropna()
                row[f"{name}_vs_ref_sd"] = float(diff.abs().max() / ref_sd) if len(diff) and ref_sd > 0 else np.nan
                row[f"{name}_vs_ref_pct"] = (float((100 * diff / ref_means.loc[diff.index, k]).mean())
                                             if len(diff) else np.nan)
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--replicates", type=Path, default=None, help="bench_fidelity.py --keep's folder")
    parser.add_argument("--map", type=Path, default=None, help="a map's runs folder (results/<level>/runs)")
    parser.add_argument("--level", default="default")
    parser.add_argument("--variant", default="default",
                        help="the kept variant (bench_fidelity.py's) whose replicates give the noise")
    parser.add_argument("--against", default=None,
                        help="a kept reference variant in the same folder: the variant's distance from it per region")
    parser.add_argument("--regions", default="4-9,5-9,6-10,6-12", help="regions start-end [mm], comma-separated")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default="region_noise")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    for option, name in (("--variant", args.variant), ("--against", args.against)):
        if name is not None and name not in VARIANTS:
            parser.error(f"{option}: {name!r} is not one of bench_fidelity.py's variants")
    if args.against == args.variant:
        parser.error(f"--against: {args.against!r} is the variant itself; name a bigger, stiffer one")
    config = load_config(ROOT / "config.yaml")
    s = scene(config, args.level)
    x0, x1, y0, y1 = s.sampling_region
    kept = {source: scene(variant_config(config, args.level, VARIANTS[name]), args.level)
            for source, name in (("replicates", args.variant), ("against", args.against)) if name is not None}
    own = f"{x0 * 1e3:g}-{x1 * 1e3:g}"
    regions = {own: (x0, x1)}
    for label in args.regions.split(","):
        try:
            a, b = (float(v) for v in label.split("-"))
        except ValueError:
            parser.error(f"--regions: {label!r} is not start-end in mm (e.g. 6-12)")
        if not b > a:
            parser.error(f"--regions: {label!r} ends before it starts")
        regions[f"{a:g}-{b:g}"] = (a * 1e-3, b * 1e-3)
    spans = {**{source: k.sampling_region[2:] for source, k in kept.items()}, "map": (y0, y1)}
    regions = {source: [(label, (*x, *y)) for label, x in regions.items()] for source, y in spans.items()}
    heap = {**{source: k.heap_particles for source, k in kept.items()}, "map": s.heap_particles}
    own_x = {**{source: k.sampling_region[:2] for source, k in kept.items()}, "map": (x0, x1)}
    found = [{**layer, "heap_particles": heap[layer["source"]], "own_x": own_x[layer["source"]]}
             for layer in layers(args.replicates, args.map, args.variant, args.against)]
    if not found:
        parser.error(f"no layers found under --replicates {args.replicates} (variant {args.variant!r}) "
                     f"or --map {args.map}")
    started = time.perf_counter()
    area_ref = (x1 - x0) * (y1 - y0)
    tasks = [(layer, regions, area_ref, s.density, s.profilometer_lines, config["profilometer"]["seed"])
             for layer in found]
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for i, done in enumerate(pool.map(measure, tasks), 1):
            rows += done
            print(f"{i}/{len(tasks)} layers measured", end="\r", flush=True)
    runs = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    runs.to_csv(args.out / f"{args.name}.csv", index=False)
    table = summarise(runs, own)
    command = " ".join(argv if argv is not None else sys.argv[1:])
    counts = runs[runs["region_mm"] == own].groupby("source").size().to_dict()
    text = (f"# Noise against the sampling region's length ({args.level} level)\n\n"
            f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, in "
            f"{time.perf_counter() - started:.0f} s (no DEM: layers re-measured), by\n"
            f"`.venv/bin/python benchmarks/bench_region.py {command}`.\n\n"
            f"Layers: {counts.get('replicates', 0)} replicated runs (variant `{args.variant}`), "
            + (f"{counts.get('against', 0)} of the reference `{args.against}`, " if args.against else "")
            + f"{counts.get('map', 0)} map runs. The level's own region: {own} mm. M_s per its area.\n\n"
            "- `<m>_sd_pct`: pooled seed sd over the replicated points, % of the mean;\n"
            "- `<m>_R_max`: sqrt(1 - sd^2 / var over the map's runs), the best R a surrogate can reach;\n"
            "- `<m>_map_shift_sd`: the largest mean shift of one omega's map runs (over its U's) from their "
            "values over the level's region, in that region's pooled seed sd; `<m>_rep_shift_sd`: the same "
            "for one point's replicates (the same layers, paired);\n"
            + ("- `<m>_vs_ref_sd`: the largest distance of a point's mean from the reference's, in the reference's "
               "pooled seed sd over that region; `<m>_vs_ref_pct`: the mean change over the points, % of the "
               "reference's;\n" if args.against else "")
            +
            "- the CSV's `fed_pct`: per layer and region, the share of the particles over the region that the "
            "feed added (ids above the settled heap's count); `substrate_above_datum_um`: the substrate's mean "
            "height under the region above the gap's datum, its mean plane under the run's own region "
            "(benchmarks/substrate_height.py reads it).\n\n"
            + table.to_markdown(index=False, floatfmt=".2f") + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
