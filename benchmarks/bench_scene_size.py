"""Scene size against the reference: is a level's scene converged, and what does it cost?

Usage (after the runs; benchmarks/README.md gives the whole sequence)::

    .venv/bin/snakemake --cores 2 --configfile benchmarks/reference_study.yaml -- results/reference/dataset.csv
    .venv/bin/snakemake --cores 2 --configfile benchmarks/reference_study.yaml --config level=default \
        -- results/default/dataset.csv
    .venv/bin/python benchmarks/bench_scene_size.py --levels default [--name scene_size]

Reads each level's finished runs (every run folder's ``metrics.json``, ``health.json``,
``final.dump`` and its replicate's substrate) and writes to
``benchmarks/measured/``:

- ``<name>_deposit.csv``, ``.png``: the reference's deposit profiles (layer mass per
  area along the travel) and, per point, where the layer reaches steady state
  (:func:`analysis.metrics.deposit.steady_state_start`, plateau: the region's far half);
- ``<name>_pile.csv``, ``.png`` (unfed levels only): per bin past the heap's toe, the layer's
  areal mass against the powder still ahead of the roller (mass balance): does the deposit
  depend on the pile?
- ``<name>.csv``, ``.md``, ``.png``: one row per scene, each level measured over its own
  sampling region (as its map is made) and over the reference's steady region, and the
  reference re-measured over an earlier start or a shorter region (the layer behind the
  roller does not depend on where the roller goes next, so these are measured on the
  reference's own dumps; their cost is scaled by their share of the travel): CPU time
  per run, and per metric the largest difference of point means from the reference's,
  in units of the reference's pooled seed-to-seed sd (converged: below 2 at every point).

M_s is compared per unit area of the sampling region (a wider strip has a wider region).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.metrics.deposit import deposit_profile, pile_ahead, profile_figure, run_profiles, steady_state_start
from analysis.metrics.dump import read_dump
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units

ROOT = Path(__file__).resolve().parent.parent

METRICS = {"mass_mg_mm2": "M_s/area", "throughput_mm2_s": "Q_s", "roughness_um": "R_q", "porosity_pct": "Phi"}
#: Converged: every point mean within this many pooled reference sds.
TOLERANCE_SD = 2.0


def level_runs(config: dict, level: str) -> pd.DataFrame:
    """Every finished run of the level (``metrics.json`` and ``health.json`` of each run
    folder), with M_s per area [mg/mm^2] and the run folder."""
    x0, x1, y0, y1 = scene(config, level).sampling_region
    rows = []
    for folder in sorted((ROOT / "results" / level / "runs").glob("U*_w*_r*")):
        if not (folder / "metrics.json").is_file():
            continue
        health = json.loads((folder / "health.json").read_text())
        rows.append({**json.loads((folder / "metrics.json").read_text()), "run_dir": folder,
                     **{k: health[k] for k in ("cpu_s", "supply_margin", "roller_travel_m", "steps")}})
    data = pd.DataFrame(rows)
    data["mass_mg_mm2"] = data["mass_g"] * 1e3 / ((x1 - x0) * (y1 - y0) * 1e6)
    return data


def remeasure(config: dict, level: str, runs: pd.DataFrame, region_mm: tuple) -> pd.DataFrame:
    """The runs' metrics over another sampling region (x from, to [mm]; the full strip width)."""
    s = scene(config, level)
    region = (region_mm[0] * 1e-3, region_mm[1] * 1e-3, *s.sampling_region[2:])
    rows = []
    for run in runs.itertuples(index=False):
        frame = read_dump(run.run_dir / "final.dump")
        substrate = ROOT / "results" / level / "meshes" / f"r{run.replicate}" / "substrate.stl"
        m = to_report_units(spread_layer_metrics(frame, region, run.U_mm_s * 1e-3, s.density, substrate=substrate,
                                                 n_lines=s.profilometer_lines, seed=config["profilometer"]["seed"]))
        rows.append({"U_mm_s": run.U_mm_s, "omega_rad_s": run.omega_rad_s, "replicate": run.replicate,
                     "cpu_s": run.cpu_s, "supply_margin": run.supply_margin, **m,
                     "mass_mg_mm2": m["mass_g"] * 1e3 / ((region[1] - region[0]) * (region[3] - region[2]) * 1e6)})
    return pd.DataFrame(rows)


def pooled_sd(runs: pd.DataFrame, by=("U_mm_s", "omega_rad_s")) -> pd.Series:
    """Pooled seed-to-seed standard deviation of each metric over the groups ``by`` (the points)."""
    groups = runs.groupby(list(by))[list(METRICS)]
    dof = groups.count() - 1
    return np.sqrt((groups.var(ddof=1).fillna(0) * dof).sum() / dof.sum())


def compare(name: str, runs: pd.DataFrame, ref_runs: pd.DataFrame, sd: pd.Series, cpu_scale: float = 1.0) -> dict:
    """One row: cost, and the largest |point mean - reference mean| per metric, in units of
    the reference's pooled seed-to-seed sd (``max_diff_sd_*``: ``converged`` below
    TOLERANCE_SD) and of the two scenes' pooled sd (``max_diff_pooled_sd_*``: both
    scenes' replicates pooled over the points, the usual effect size; ``within_pooled``)."""
    cols = list(METRICS)
    means = runs.groupby(["U_mm_s", "omega_rad_s"])[cols].mean()
    ref_means = ref_runs.groupby(["U_mm_s", "omega_rad_s"])[cols].mean()
    common = means.index.intersection(ref_means.index)  # points both have run
    diff = (means.loc[common] - ref_means.loc[common]).abs()
    gap = (diff / sd).max()
    both = pd.concat([runs.assign(scene="level"), ref_runs.assign(scene="ref")])
    both = both[both.set_index(["U_mm_s", "omega_rad_s"]).index.isin(common)]
    gap2 = (diff / pooled_sd(both, by=("scene", "U_mm_s", "omega_rad_s"))).max()
    row = {"scene": name, "points": len(common), "runs": len(runs), "cpu_s_per_run": runs["cpu_s"].mean() * cpu_scale,
           "min_supply_margin": runs["supply_margin"].min() if "supply_margin" in runs else np.nan}
    row.update({f"max_diff_sd_{label}": gap[m] for m, label in METRICS.items()})
    row["converged"] = bool((gap < TOLERANCE_SD).all())
    row.update({f"max_diff_pooled_sd_{label}": gap2[m] for m, label in METRICS.items()})
    row["within_pooled"] = bool((gap2 < TOLERANCE_SD).all())
    own = pooled_sd(runs) / runs[cols].mean().abs()
    row.update({f"seed_sd_pct_{label}": 100 * own[m] for m, label in METRICS.items()})
    return row


def deposit_against_pile(config: dict, levels: list[str]) -> pd.DataFrame:
    """Every bin past the settled heap's toe of every run of ``levels``: the layer's areal mass
    [mg/mm^2] against the powder still ahead of the roller there [mg/mm of width]
    (:func:`analysis.metrics.deposit.pile_ahead`). A deposit that depends on the pile alone
    collapses onto one curve whatever the heap's size."""
    tables = []
    for level in levels:
        s = scene(config, level)
        for folder in sorted((ROOT / "results" / level / "runs").glob("U*_w*_r*")):
            if not (folder / "metrics.json").is_file():
                continue
            run = json.loads((folder / "metrics.json").read_text())
            settle_dir = ROOT / "results" / level / "settle" / f"r{run['replicate']}"
            heap = read_dump(settle_dir / "settled.dump").atoms
            toe = json.loads((settle_dir / "health.json").read_text())["heap_toe_m"] * 1e3
            heap_volume = 4 / 3 * np.pi * np.sum(heap["radius"].to_numpy() ** 3)
            heap_mass = 1e3 * s.density * heap_volume / s.strip_width  # mg/mm
            profile = deposit_profile(read_dump(folder / "final.dump").atoms, s.density, s.strip_width,
                                      (s.box[0], s.sampling_region[1]))
            profile["pile_mg_mm"] = pile_ahead(profile, heap_mass)
            tables.append(profile[profile["x_mm"] > toe].assign(level=level, U_mm_s=run["U_mm_s"],
                                                                 omega_rad_s=run["omega_rad_s"]))
    return pd.concat(tables, ignore_index=True)


def plot_pile(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    omegas = sorted(table["omega_rad_s"].unique())
    fig, axes = plt.subplots(1, len(omegas), figsize=(5 * len(omegas), 4), squeeze=False)
    for ax, omega in zip(axes[0], omegas):
        for (level, U), group in table[table["omega_rad_s"] == omega].groupby(["level", "U_mm_s"]):
            ax.scatter(group["pile_mg_mm"], group["areal_mass_mg_mm2"], s=6, alpha=0.6, label=f"{level}, U = {U:g}")
        ax.set_title(f"ω = {omega:g} rad/s (bins past the heap's toe)")
        ax.set_xlabel("powder ahead of the roller (mg per mm of width)")
        ax.set_ylabel("layer mass per area (mg/mm$^2$)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--levels", default="default", help="levels run at the reference points, comma-separated")
    parser.add_argument("--reference", default="reference")
    parser.add_argument("--name", default="scene_size")
    parser.add_argument("--ref-region", help="the reference's steady region FROM-TO (mm) instead of the one the "
                        "deposit profiles give, e.g. to leave out the layer under the stopped roller")
    parser.add_argument("--level-regions", default="",
                        help="extra rows: LEVEL:FROM-TO (mm), comma-separated, a level re-measured over that region")
    parser.add_argument("--level-files", default="benchmarks/scene_size.yaml",
                        help="YAML files (comma-separated) whose `fidelity` levels are added to config.yaml's")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    config = load_config(ROOT / "config.yaml")
    for path in filter(None, args.level_files.split(",")):
        config["fidelity"].update(yaml.safe_load((ROOT / path).read_text())["fidelity"])
    out = ROOT / "benchmarks" / "measured"
    ref_scene = scene(config, args.reference)
    ref = level_runs(config, args.reference)
    region_mm = tuple(v * 1e3 for v in ref_scene.sampling_region[:2])

    # Deposit profiles of the reference and where each point's layer is steady
    profiles = run_profiles([d / "final.dump" for d in ref["run_dir"]],
                            ref[["U_mm_s", "omega_rad_s", "replicate"]].to_dict("records"),
                            ref_scene.density, ref_scene.strip_width, (ref_scene.box[0], ref_scene.travel_end))
    plateau = ((region_mm[0] + region_mm[1]) / 2, region_mm[1])
    in_region = profiles[(profiles["x_mm"] > region_mm[0]) & (profiles["x_mm"] < region_mm[1])]  # rough substrate
    starts = {point: round(steady_state_start(group, plateau), 2)
              for point, group in in_region.groupby(["U_mm_s", "omega_rad_s"])}
    profiles.to_csv(out / f"{args.name}_deposit.csv", index=False)
    replicates = ref.groupby(["U_mm_s", "omega_rad_s"]).size().max()
    profile_figure(profiles, region_mm, f"Deposit profiles, level {args.reference} (band: {replicates} replicates)"
                   ).savefig(out / f"{args.name}_deposit.png", dpi=130)

    # The reference's own steady region: from the latest steady start to the region's end
    steady_from = max(starts.values())
    if args.ref_region:
        steady_from, ref_end = (float(v) for v in args.ref_region.split("-"))
        region_mm = (region_mm[0], ref_end)
    ref_steady = remeasure(config, args.reference, ref, (max(steady_from, region_mm[0]), region_mm[1]))
    sd = pooled_sd(ref_steady)
    ref_means = ref_steady.groupby(["U_mm_s", "omega_rad_s"])[list(METRICS)].mean()
    travel = ref["roller_travel_m"].mean() * 1e3
    rows = [compare(f"{args.reference} (region {steady_from:g}-{region_mm[1]:g} mm)", ref_steady, ref_steady, sd)]
    seen = {(steady_from, region_mm[1])}
    for start, length in ((steady_from, 4.0), (region_mm[0], 4.0), (steady_from, 2.0)):
        if start + length > region_mm[1] + 1e-9 or (start, start + length) in seen:
            continue
        seen.add((start, start + length))
        runs = remeasure(config, args.reference, ref, (start, start + length))
        shorter = (travel - (region_mm[1] - start - length)) / travel
        rows.append(compare(f"{args.reference}, region {start:g}-{start + length:g} mm", runs, ref_steady, sd, shorter))
    for level in [lv for lv in args.levels.split(",") if lv]:
        runs = level_runs(config, level)
        own = tuple(round(v * 1e3, 6) for v in scene(config, level).sampling_region[:2])
        # as it ships (its own region: what its map is made of), and over the reference's steady region
        rows.append(compare(f"{level} (own region {own[0]:g}-{own[1]:g} mm)", runs, ref_steady, sd))
        end = min(region_mm[1], own[1])
        if (max(steady_from, region_mm[0]), end) != own:
            rows.append(compare(f"{level} (region {steady_from:g}-{end:g} mm)",
                                remeasure(config, level, runs, (max(steady_from, region_mm[0]), end)), ref_steady, sd))
    for item in filter(None, args.level_regions.split(",")):
        level, span = item.split(":")
        a, b = (float(v) for v in span.split("-"))
        rows.append(compare(f"{level} (region {a:g}-{b:g} mm)", remeasure(config, level, level_runs(config, level),
                                                                            (a, b)), ref_steady, sd))
    table = pd.DataFrame(rows)
    table.to_csv(out / f"{args.name}.csv", index=False)
    ref_mean = ref_means.abs().mean()
    floor = ", ".join(f"{label} {sd[m]:.3g} ({100 * sd[m] / ref_mean[m]:.1f} %)" for m, label in METRICS.items())

    lines = [f"# Scene size against the reference ({args.reference} level)", "",
             f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, in "
             f"{time.perf_counter() - started:.0f} s (analysis of the runs), by",
             f"`.venv/bin/python benchmarks/bench_scene_size.py {' '.join(argv if argv is not None else sys.argv[1:])}`"
             " after the runs of `benchmarks/README.md` (scene size).", "",
             "Steady state starts (first 1-mm window within 2 standard errors of the plateau "
             f"{plateau[0]:g}-{plateau[1]:g} mm, and staying so for 2 mm), per point (U mm/s, omega rad/s): "
             + ", ".join(f"({U:g}, {w:g}): {x:g} mm" for (U, w), x in starts.items()), "",
             f"Differences: max over the points of |mean - reference mean| / the reference's pooled seed-to-seed sd; "
             f"converged below {TOLERANCE_SD:g} for every metric. The reference's pooled seed-to-seed sd "
             f"(noise floor; M_s/area in mg/mm^2, Q_s mm^2/s, R_q um, Phi %): {floor}. "
             "Cost: LIGGGHTS' CPU seconds per spreading run "
             "(re-measured regions: the reference's cost scaled by their share of the travel).", "",
             table[[c for c in table if not c.startswith(("max_diff_pooled", "within", "seed_sd"))]].to_markdown(
                 index=False, floatfmt=".3g"), "",
             "The same differences in units of the two scenes' pooled seed-to-seed sd (both scenes' replicates, "
             f"pooled over the points: the usual effect size; within below {TOLERANCE_SD:g}), and each scene's own "
             "pooled seed-to-seed sd in % of its mean:", "",
             table[["scene"] + [c for c in table
                                if c.startswith(("max_diff_pooled", "within", "seed_sd"))]].to_markdown(
                 index=False, floatfmt=".3g"), ""]
    (out / f"{args.name}.md").write_text("\n".join(lines))
    print("\n".join(lines))
    plot(table, out / f"{args.name}.png")
    unfed = [lv for lv in [args.reference, *args.levels.split(",")] if lv and scene(config, lv).feed_pile_mass is None]
    if unfed:  # a fed pile is topped up: the mass balance says nothing about it
        pile = deposit_against_pile(config, unfed)
        pile.to_csv(out / f"{args.name}_pile.csv", index=False)
        plot_pile(pile, out / f"{args.name}_pile.png")
    return 0


def plot(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = table[table["cpu_s_per_run"].notna()]
    fig, axes = plt.subplots(1, 4, figsize=(16, 4), sharey=True)
    for ax, label in zip(axes, METRICS.values()):
        col = f"max_diff_sd_{label}"
        ax.scatter(rows[col], rows["cpu_s_per_run"])
        for _, r in rows.iterrows():
            ax.annotate(r["scene"], (r[col], r["cpu_s_per_run"]), fontsize=6)
        ax.axvline(TOLERANCE_SD, color="grey", ls="--", label=f"{TOLERANCE_SD:g} pooled sd")
        ax.set_xlabel(f"max |difference| of {label} (reference sds)")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("CPU s per spreading run")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    sys.exit(main())
