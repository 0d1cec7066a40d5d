"""Run time against error: one knob at a time, against a reference, through real LIGGGHTS.

Usage::

    .venv/bin/python benchmarks/bench_fidelity.py [--level default] [--points 100:-10,100:0,100:10]
        [--seeds 2] [--variants reference,default,E1e6,...] [--jobs 2] [--name fidelity]
        [--ladder default,E2e7,E5e7,E1e8[;E2e7,E2e7+pile40]] [--out benchmarks/measured] [--keep DIR]
        [--movie-every-mm 0.5]

Every variant is the config's fidelity level with a few keys overridden
(``VARIANTS`` below). For each variant and seed (replicate: another heap
packing, same physics) it makes the geometry, settles the heap and spreads it
at each (U [mm/s], omega [rad/s]) point, measures the layer, and records wall
time, CPU time (LIGGGHTS' own), steps and particles. The error of a variant
on a metric is the mean over the points of |mean over its seeds - mean over
the reference's seeds| / mean |reference|; the reference's own seed-to-seed
spread (its sample standard deviation at each point over the same mean
reference) is the noise floor no variant can beat.

Writes ``benchmarks/measured/<name>.csv`` (one row per run), ``<name>.md``
(one row per variant, with machine and date) and ``<name>.png`` (CPU time
per run against error: the Pareto front). Runs ``--jobs`` scenes at once, so
compare ratios measured in one invocation.
"""
from __future__ import annotations

import argparse
import copy
import platform
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd
import yaml

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.dem.liggghts import LiggghtsError, children_cpu
from analysis.dem.simulate import make_geometry, settle, spread
from analysis.metrics.dump import read_dump
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units

ROOT = Path(__file__).resolve().parent.parent

METRICS = {"mass_g": "M_s", "throughput_mm2_s": "Q_s", "roughness_um": "R_q", "porosity_pct": "Phi"}

#: The big scene of the stiffness ladder: a 2.5 mm strip (14 mean diameters) with a 40 mg/mm pile,
#: topped up every 0.5 mm as every run of it was (the default level's own interval may change), nothing
#: frozen whatever the level sets (freeze_lag_mm).
#: Particles in a mg of the default powder's dose (the default level's 1,820 for 20 mg/mm over 1.2 mm).
PARTICLES_PER_MG = 1820 / (20 * 1.2)


def pile(mg_per_mm, strip_width_mm=1.2):
    """Overrides for a pile of ``mg_per_mm`` (mg per mm of width) on a strip of ``strip_width_mm`` (mm).

    The heap is dosed at the pile's mass (``heap_particles``, rounded to tens) and the feed then holds it.
    """
    return {"LEVEL.feed_pile_mg_per_mm": mg_per_mm,
            "LEVEL.heap_particles": int(round(mg_per_mm * strip_width_mm * PARTICLES_PER_MG, -1))}


BIG_SCENE = {"LEVEL.strip_width_mm": 2.5, **pile(40, 2.5), "LEVEL.feed_every_mm": 0.5, "LEVEL.freeze_lag_mm": None}
#: The default's 1.2 mm strip with the reference's 40 mg/mm pile (its particles settled from the start).
PILE40 = pile(40)

#: Config overrides (dotted keys; ``LEVEL`` stands for the benchmarked level's
#: fidelity block, whose ``youngs_modulus_dem_Pa`` wins over the material's). "default" is the
#: level as configured.
VARIANTS = {
    "default": {},
    # the tests' free-flowing powder (.test/config.yaml): the smoke level's noise floor the tests judge by
    "test_powder": {f"material.{k}": v for k, v in
                    yaml.safe_load((ROOT / ".test/config.yaml").read_text())["material"].items()},
    "reference": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, "timestep.rayleigh_fraction": 0.1,
                  "LEVEL.size_classes": 9, "LEVEL.profilometer_lines": 2000},
    "E2e7": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7},
    "E2e6": {"LEVEL.youngs_modulus_dem_Pa": 2.0e6},
    "E1e6": {"LEVEL.youngs_modulus_dem_Pa": 1.0e6},
    "dt0.1": {"timestep.rayleigh_fraction": 0.1},
    "dt0.3": {"timestep.rayleigh_fraction": 0.3},
    "classes3": {"LEVEL.size_classes": 3},
    "classes9": {"LEVEL.size_classes": 9},
    "lines200": {"LEVEL.profilometer_lines": 200},
    "ranks2": {"LEVEL.mpi_ranks": 2},
    "E1e6+dt0.3": {"LEVEL.youngs_modulus_dem_Pa": 1.0e6, "timestep.rayleigh_fraction": 0.3},
    # pass 2: cheaper steps and fewer roller facets, and the scene's size
    "dt0.4": {"timestep.rayleigh_fraction": 0.4},
    "facets90": {"roller.facets_around": 90},
    "dt0.4+facets90": {"timestep.rayleigh_fraction": 0.4, "roller.facets_around": 90},
    "dt0.3+facets180": {"timestep.rayleigh_fraction": 0.3, "roller.facets_around": 180},  # default before pass 2
    "facets60": {"roller.facets_around": 60},
    "strip1.8": {"LEVEL.strip_width_mm": 1.8, "LEVEL.heap_particles": 1350},
    "heap1.5x": {"LEVEL.heap_particles": 1350},
    "lines2000": {"LEVEL.profilometer_lines": 2000},
    # the stiffness ladder of the fed scene (docs/scene_size.md: Stiffness)
    "E5e6": {"LEVEL.youngs_modulus_dem_Pa": 5.0e6},
    "E5e7": {"LEVEL.youngs_modulus_dem_Pa": 5.0e7},
    "E1e8": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8},
    "E2e8": {"LEVEL.youngs_modulus_dem_Pa": 2.0e8},
    "E4e8": {"LEVEL.youngs_modulus_dem_Pa": 4.0e8},
    # the fed scene's size and supply at 20 MPa (docs/scene_size.md: At the converged stiffness)
    "E2e7+strip2.5": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, "LEVEL.strip_width_mm": 2.5,
                      "LEVEL.heap_particles": 3800},
    "E2e7+pile40": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, **PILE40},
    "E2e7+region6": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, "LEVEL.sampling_length_mm": 6.0},
    # both unconverged knobs turned together: the reference the default is judged against
    "E2e7+strip2.5+pile40": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, **BIG_SCENE},
    # the reference one step stiffer: does the stiffness shift of the default's scene hold on the bigger one?
    "E5e7+strip2.5+pile40": {"LEVEL.youngs_modulus_dem_Pa": 5.0e7, **BIG_SCENE},
    # the big scene one step stiffer again: converged in stiffness (50 against 100 MPa)? The omega -15 reference
    "E1e8+strip2.5+pile40": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE},
    # the width one step past the 2.5 mm strip (28 mean diameters), the pile's 20 mg/mm over 5 mm
    "E2e7+strip5": {"LEVEL.youngs_modulus_dem_Pa": 2.0e7, "LEVEL.strip_width_mm": 5.0,
                    "LEVEL.heap_particles": 7580},
    # the gap as built: a 180-facet roller (sagitta 2.3 um) against the default 90 (sagitta 9.1 um)
    # (its runs before the default's 0.25 mm top-ups, with 0.5 mm ones), and with the default's top-ups
    "facets180": {"roller.facets_around": 180, "LEVEL.feed_every_mm": 0.5},
    "facets180+feed0.25": {"roller.facets_around": 180, "LEVEL.feed_every_mm": 0.25},
    # the feed: top-ups every 0.25 mm (the default level's interval, so in new runs the same scene as
    # `default`) and every 0.5 mm (the other levels'), and no feed from a heap that lasts (40 mg/mm: the
    # pile's 20 plus the 18 mg/mm forward rolling laid over the 13 mm travel at omega -15 before calibration)
    "feed0.25": {"LEVEL.feed_every_mm": 0.25},
    "feed0.5": {"LEVEL.feed_every_mm": 0.5},
    "unfed40": {"LEVEL.feed_pile_mg_per_mm": None, "LEVEL.heap_particles": 3640},
    # the layer laid before the region frozen, and dropped, once the roller is 8 mm past it (freeze_lag_mm;
    # the default level set it from fffa867 to 592349f), and never
    "freeze8": {"LEVEL.freeze_lag_mm": 8.0},
    "nofreeze": {"LEVEL.freeze_lag_mm": None},
    # both stopped 12 mm past the region: the freeze judged free of where the stop rule stops the roller
    "freeze8+runout12": {"LEVEL.freeze_lag_mm": 8.0, "LEVEL.run_out_mm": 12.0, "LEVEL.run_out_max_mm": 12.0},
    # a cheaper step, now that a blown-up spread is re-run at timestep.unstable_retry_fraction
    "dt0.5": {"timestep.rayleigh_fraction": 0.5},
    # the smoke level's pile for the calibrated powder (benchmarks/measured/smoke_pile15.md)
    "pile15": pile(15, 1.0),
    # the 40 mg/mm pile (within the reference at U 100, too much at U 70) stiffened: rough again at U 100
    # (docs/scene_size.md: At the calibrated powder: U = 100 mm/s)
    "E5e7+pile40": {"LEVEL.youngs_modulus_dem_Pa": 5.0e7, **PILE40},
    # between the default's 20 mg/mm pile (rough at U 100) and 40 (too much at U 70)
    "pile30": pile(30),
    # one step past the 40 mg/mm pile (the feed's wedge ahead of the roller holds twice at most 53 mg/mm):
    # is the layer converged in the pile at 40?
    "pile50": pile(50),
    # the reference one step wider (28 mean diameters) at the calibrated powder: is its 2.5 mm strip converged?
    "E1e8+strip5+pile40": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE, "LEVEL.strip_width_mm": 5.0,
                           **pile(40, 5.0)},
    # the reference with its heap dosed 4 mm further back (its slumped toe near x = 1.5 mm, not 5.5): is the
    # layer over the region the pile's steady layer or the end of the cut heap's thicker one?
    "E1e8+strip2.5+pile40+heap-8": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE, "LEVEL.heap_start_mm": -8.0},
    # the wider reference with the same longer run-in: is its layer's step at 6-7 mm the end of the cut heap's
    # thicker layer (it moves 4 mm back, out of the region) or the width's own (it stays)?
    "E1e8+strip5+pile40+heap-8": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE, "LEVEL.strip_width_mm": 5.0,
                                  **pile(40, 5.0), "LEVEL.heap_start_mm": -8.0},
    # the roller stopped 8 and 12 mm past the region's end, not 4: the layer at x grows behind a forward-rolling
    # roller until it is about 4 mm past (benchmarks/layer_formation.py): is the region's layer complete?
    "runout8": {"LEVEL.run_out_mm": 8.0, "LEVEL.run_out_max_mm": 8.0},
    "runout12": {"LEVEL.run_out_mm": 12.0, "LEVEL.run_out_max_mm": 12.0},
    # the roller stops once the region's layer is laid (layer_laid), 2 to 12 mm past the region, over a
    # substrate rough 0.5 mm past it, peaks clipped at 0.9 of the gap (as measured, 2026-12-06/07)
    "laid": {"LEVEL.run_out_mm": 2.0, "LEVEL.run_out_max_mm": 12.0, "LEVEL.rough_past_mm": 0.5,
             "substrate.peak_cap_fraction_of_gap": 0.9},
    # `laid` with the peaks clipped at 0.6 of the gap (180 um), as the 8 mm margin below
    "laid+cap0.6": {"LEVEL.run_out_mm": 2.0, "LEVEL.run_out_max_mm": 12.0, "LEVEL.rough_past_mm": 0.5,
                    "substrate.peak_cap_fraction_of_gap": 0.6},
    # the substrate rough 8 mm past the region, not 0.5: the region's layer is laid while the roller's nip is
    # 4-7.5 mm past it, over flat bed unless the patch reaches there (the roller stops as `laid`'s)
    "laid+rough8": {"LEVEL.run_out_mm": 2.0, "LEVEL.run_out_max_mm": 12.0, "LEVEL.rough_past_mm": 8.0},
    # rough 8 mm past, its peaks clipped at 0.6 of the gap (180 um, 2.3 Sq) above the region's mean plane: the
    # smallest particle (121 um at `default`) clears every peak under the roller; 0.9 (270 um) blew runs up
    "laid+rough8+cap0.6": {"LEVEL.run_out_mm": 2.0, "LEVEL.run_out_max_mm": 12.0, "LEVEL.rough_past_mm": 8.0,
                           "substrate.peak_cap_fraction_of_gap": 0.6},
    # rough wherever the powder goes, as the paper's plate: from behind the heap to past the latest stop
    "laid+roughall": {"LEVEL.run_out_mm": 2.0, "LEVEL.run_out_max_mm": 12.0, "LEVEL.rough_before_mm": 30.0,
                      "LEVEL.rough_past_mm": 30.0},
    # the default's sampling region twice as long (6-12 mm): the roller stops once that region is laid, so the
    # longer region costs its own travel only (benchmarks/bench_region.py re-measures the kept layers over 6-9 mm)
    "region6": {"LEVEL.sampling_length_mm": 6.0},
    "E1e8+strip2.5+pile40+region6": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE,
                                     "LEVEL.sampling_length_mm": 6.0},
    # the 6-12 mm region with one of the reference's knobs at a time: past 9 mm the reference's layer thins and
    # the default's does not (docs/scene_size.md: At the map's scene); which knob makes the difference?
    "region6+E1e8": {"LEVEL.sampling_length_mm": 6.0, "LEVEL.youngs_modulus_dem_Pa": 1.0e8},
    "region6+pile40": {"LEVEL.sampling_length_mm": 6.0, **PILE40},
    "region6+strip2.5": {"LEVEL.sampling_length_mm": 6.0, "LEVEL.strip_width_mm": 2.5, **pile(20, 2.5)},
    "region6+feed0.5": {"LEVEL.sampling_length_mm": 6.0, "LEVEL.feed_every_mm": 0.5},
    "E1e8+strip2.5+pile40+runout8": {"LEVEL.youngs_modulus_dem_Pa": 1.0e8, **BIG_SCENE, "LEVEL.run_out_mm": 8.0,
                                     "LEVEL.run_out_max_mm": 8.0},
    # the substrate of the next (previous) replicate under this replicate's heap and feed: run at seed 0
    # (1), a layer shaped along x like its own seed's follows the powder, like the other seed's the substrate
    "substrate+1": {"substrate.seed": 8},
    "substrate-1": {"substrate.seed": 6},
}

#: Health figures of a spread recorded beside its metrics (analysis.dem.health).
HEALTH = ("heap_exhausted", "supply_margin", "max_overlap_fraction", "max_overlap_anywhere", "peak_speed_m_s",
          "inrun_max_overlap_fraction", "inrun_max_wall_overlap_fraction", "squeeze_outs_max",
          "fed_max_ahead_of_front_mm", "fed_share_of_region_layer", "feed_pile_min_fraction", "unstable_retries")


def variant_config(base: dict, level: str, overrides: dict) -> dict:
    """A copy of ``base`` with ``overrides`` applied (``LEVEL.`` = ``fidelity.<level>.``)."""
    config = copy.deepcopy(base)
    for key, value in overrides.items():
        node, *path = key.replace("LEVEL.", f"fidelity.{level}.").split(".")
        target = config[node]
        for part in path[:-1]:
            target = target[part]
        target[path[-1]] = value
    return config


def short_error(err: Exception) -> str:
    """The line of an error that says what broke: LIGGGHTS' ERROR line, or the first line."""
    lines = str(err).splitlines()
    return next((ln.strip() for ln in lines if "ERROR" in ln), lines[0] if lines else type(err).__name__)


def measure_layer(config: dict, level: str, run_dir: Path, meshes: Path, U_mm_s: float) -> dict:
    """The four metrics of a run's ``final.dump``, in the dataset's units (METRICS keys)."""
    s = scene(config, level)
    metrics = spread_layer_metrics(read_dump(run_dir / "final.dump"), s.sampling_region, U_mm_s * 1e-3, s.density,
                                   substrate=meshes / "substrate.stl", n_lines=s.profilometer_lines,
                                   seed=config["profilometer"]["seed"])
    return {k: to_report_units(metrics)[k] for k in METRICS}


def sampling_area_mm2(config: dict, level: str) -> float:
    """Area of the level's sampling region [mm^2]: M_s is the mass over it."""
    x0, x1, y0, y1 = scene(config, level).sampling_region
    return (x1 - x0) * (y1 - y0) * 1e6


def movie_steps(config: dict, level: str, U_mm_s: float, every_mm: float) -> int:
    """Steps between movie frames for one every ``every_mm`` [mm] of the roller's travel at ``U_mm_s``
    [mm/s]; 0 (no movie) for ``every_mm`` 0."""
    if not every_mm:
        return 0
    return max(1, round(every_mm / U_mm_s / scene(config, level).timestep))


def run_scene(task) -> list[dict]:
    """Geometry, settle (seed ``replicate``) and every point's spread of one variant."""
    name, config, level, replicate, points, keep, movie_every_mm = task
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_geometry(config, level, tmp / "meshes", replicate=replicate)  # a new substrate and heap
        try:
            settle(config, level, tmp / "meshes", tmp / "settle", replicate=replicate)
        except LiggghtsError as err:  # a broken setting is a result too
            print(f"{name} seed {replicate}: settle failed: {err}", flush=True)
            return [{"variant": name, "seed": replicate, "U_mm_s": U, "omega_rad_s": omega,
                     "error": short_error(err)} for U, omega in points]
        for U, omega in points:
            cpu0 = children_cpu()
            try:
                health = spread(config, level, U, omega, tmp / "meshes", tmp / "settle", tmp / "run",
                                movie_every=movie_steps(config, level, U, movie_every_mm), replicate=replicate)
            except (LiggghtsError, ValueError) as err:  # ValueError: e.g. an empty layer to measure
                print(f"{name} seed {replicate} U={U:g} omega={omega:g}: failed: {err}", flush=True)
                rows.append({"variant": name, "seed": replicate, "U_mm_s": U, "omega_rad_s": omega,
                             "cpu_s": children_cpu() - cpu0, "error": short_error(err)})
                continue
            cpu = children_cpu() - cpu0
            if keep is not None:  # the layer and its substrate, to re-measure over other regions, and
                # the run's input, log (the feed's weighings and fronts) and health, to read what it did
                kept = keep / f"{name}_s{replicate}_U{U:g}_w{omega:g}"
                kept.mkdir(parents=True, exist_ok=True)
                for file in ("final.dump", "spread.in", "spread.log", "health.json"):
                    shutil.copy2(tmp / "run" / file, kept / file)
                shutil.copy2(tmp / "meshes" / "substrate.stl", kept / "substrate.stl")
                if (tmp / "run" / "feed_landings.csv").exists():  # where each fed particle landed
                    shutil.copy2(tmp / "run" / "feed_landings.csv", kept / "feed_landings.csv")
                if movie_every_mm:  # the travel's frames
                    shutil.copy2(tmp / "run" / "movie.dump", kept / "movie.dump")
            rows.append({"variant": name, "seed": replicate, "U_mm_s": U, "omega_rad_s": omega,
                         "wall_s": health["wall_s"], "cpu_s": cpu, "steps": health["steps"],
                         "particles": health["atoms"], "timestep_s": health["timestep_s"],
                         **{k: health.get(k) for k in HEALTH},
                         "sampling_area_mm2": sampling_area_mm2(config, level),
                         **measure_layer(config, level, tmp / "run", tmp / "meshes", U)})
            print(f"{name} seed {replicate} U={U:g} omega={omega:g}: {health['wall_s']:.1f} s, "
                  + ", ".join(f"{METRICS[k]} {rows[-1][k]:.4g}" for k in METRICS), flush=True)
    return rows


def packings_per_variant(runs):
    """How many seeds (heap packings) each variant has, and at which points when that differs.

    Tables joined from several studies hold different packings per variant and per point: the
    summary says what each has, whatever ``--seeds`` was given.
    """
    said = []
    for variant, rows in runs.groupby("variant", sort=False):
        counts = rows.groupby(["U_mm_s", "omega_rad_s"], sort=False)["seed"].nunique()
        if counts.nunique() == 1:
            said.append(f"`{variant}` {counts.iloc[0]}")
            continue
        by_count = counts.groupby(counts, sort=False).groups
        said.append(f"`{variant}` {counts.min()}-{counts.max()} (" + "; ".join(
            f"{n} at " + ", ".join(f"{u:g}:{w:g}" for u, w in idx) for n, idx in by_count.items()) + ")")
    return ", ".join(said)


def summarise(runs: pd.DataFrame, reference: str) -> pd.DataFrame:
    """One row per variant: cost per run and relative error per metric against ``reference``.

    A variant run at fewer points than the reference is judged at the points it ran only: its
    error is the mean |variant - reference| there over the reference's mean |value| there, and
    ``points`` says how many (its cost per run is over those points too)."""
    failed = runs["error"].notna() if "error" in runs else pd.Series(False, index=runs.index)
    fails = failed.groupby(runs["variant"], sort=False).sum()
    runs = runs[~failed]
    if "sampling_area_mm2" in runs:  # M_s per unit area: a wider strip has a wider region
        ref_area = runs.loc[runs["variant"] == reference, "sampling_area_mm2"].iloc[0]
        runs = runs.assign(mass_g=runs["mass_g"] * ref_area / runs["sampling_area_mm2"])
    means = runs.groupby(["variant", "U_mm_s", "omega_rad_s"])[list(METRICS)].mean()
    ref = means.loc[reference]
    scale = ref.abs().mean()
    rows = []
    for variant, group in runs.groupby("variant", sort=False):
        shared = means.loc[variant].index.intersection(ref.index)
        err = (means.loc[variant].loc[shared] - ref.loc[shared]).abs().mean() / ref.loc[shared].abs().mean()
        rows.append({"variant": variant, "points": len(shared), "seeds": group["seed"].nunique(), "runs": len(group),
                     "failed": int(fails.get(variant, 0)),
                     "cpu_s_per_run": group["cpu_s"].mean(), "wall_s_per_run": group["wall_s"].mean(),
                     "steps_per_run": group["steps"].mean(), "particles": int(group["particles"].max()),
                     **{f"err_{METRICS[k]}": err[k] for k in METRICS}})
    for variant in fails.index.difference(means.index.get_level_values(0)):  # nothing ran through
        rows.append({"variant": variant, "failed": int(fails[variant])})
    table = pd.DataFrame(rows)
    ref_runs = runs[runs["variant"] == reference]
    if ref_runs["seed"].nunique() > 1:
        spread_ = ref_runs.groupby(["U_mm_s", "omega_rad_s"])[list(METRICS)].std().mean() / scale
        table.loc[len(table)] = {"variant": "noise floor (reference seed-to-seed std)",
                                 **{f"err_{METRICS[k]}": spread_[k] for k in METRICS}}
    return table


def convergence(runs: pd.DataFrame, ladder: list[str]) -> pd.DataFrame:
    """Each step of a ladder of variants (cheapest first, each the next one made finer, stiffer or
    bigger) judged in the finer scene's own seed spread.

    For each step ``a -> b`` and metric: the largest over the points of |mean_a - mean_b| divided
    by the pooled seed sd of ``b`` (the root of the mean over the points of ``b``'s seed variance),
    and the signed mean relative change ``100 (a - b) / b`` [%]. The step is converged in a metric when
    that largest shift is at most 1 (one pooled sd of the finer scene: a noisy coarse scene does not
    pass more easily). M_s per unit sampling area, as ``summarise``. Failed runs are left out.

    Beside it, how much of that shift the seed noise of the two means could make: the largest over
    the points and metrics of Welch's ``|t| = |mean_a - mean_b| / sqrt(s_a^2 / n_a + s_b^2 / n_b)``
    (``largest Welch t``) and where it is (``at``). With 3 packings a side, scenes alike in every respect
    give ``|t|`` above 2 in about one comparison in eight.
    """
    if "error" in runs:
        runs = runs[runs["error"].isna()]
    if "sampling_area_mm2" in runs:
        runs = runs.assign(mass_g=runs["mass_g"] / runs["sampling_area_mm2"])
    groups = runs.groupby(["variant", "U_mm_s", "omega_rad_s"])[list(METRICS)]
    means, sds, counts = groups.mean(), groups.std(), groups.count()
    rows = []
    for a, b in zip(ladder, ladder[1:]):
        shift = (means.loc[a] - means.loc[b]).dropna()
        pooled = (sds.loc[b] ** 2).mean() ** 0.5
        in_sd = shift.abs().max() / pooled
        rel = (shift / means.loc[b].loc[shift.index]).mean()
        t = (shift.abs() / (sds.loc[a] ** 2 / counts.loc[a] + sds.loc[b] ** 2 / counts.loc[b])
             .loc[shift.index] ** 0.5).stack().dropna()
        U, omega, metric = t.idxmax() if len(t) else (None, None, None)
        at = f"{METRICS[metric]}, U {U:g}, omega {omega:g}" if len(t) else ""
        rows.append({"step": f"{a} -> {b}", "points": len(shift), "finer seeds": int(runs.loc[
                         runs["variant"] == b, "seed"].nunique()),
                     **{f"{METRICS[k]} shift (finer sds)": in_sd[k] for k in METRICS},
                     **{f"{METRICS[k]} change (%)": 100 * rel[k] for k in METRICS},
                     "converged": bool((in_sd <= 1).all()),
                     "largest Welch t": t.max() if len(t) else float("nan"), "at": at})
    return pd.DataFrame(rows)


def plot(table: pd.DataFrame, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 4, figsize=(16, 4), sharey=True)
    rows = table[table["cpu_s_per_run"].notna()]
    floor = table[table["cpu_s_per_run"].isna()]
    for ax, metric in zip(axes, METRICS.values()):
        col = f"err_{metric}"
        ax.scatter(100 * rows[col], rows["cpu_s_per_run"])
        for _, r in rows.iterrows():
            ax.annotate(r["variant"], (100 * r[col], r["cpu_s_per_run"]), fontsize=7)
        if len(floor):
            ax.axvline(100 * floor[col].iloc[0], color="grey", ls="--", label="noise floor")
            ax.legend(fontsize=7)
        ax.set_xlabel(f"error of {metric} against the reference [%]")
    axes[0].set_ylabel("CPU time per spreading run [s]")
    axes[0].set_yscale("log")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", default="default")
    parser.add_argument("--points", default="100:-10,100:0,100:10", help="U:omega pairs, mm/s:rad/s")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="seeds first-seed .. first-seed + seeds - 1 (to add replicates to a study)")
    parser.add_argument("--variants", default="reference,default,E1e6,dt0.3,E1e6+dt0.3")
    parser.add_argument("--reference", default="reference")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--name", default="fidelity")
    parser.add_argument("--ladder", default="",
                        help="variants from cheapest to finest (e.g. default,E2e7,E5e7,E1e8): each step judged in "
                             "the finer one's pooled seed sd (convergence); several ladders separated by ';'")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured", help="folder of the results")
    parser.add_argument("--keep", type=Path, default=None,
                        help="copy each run's final.dump, substrate.stl, spread.in, spread.log, health.json and "
                             "feed_landings.csv to "
                             "DIR/<variant>_s<seed>_U<U>_w<omega>/ (benchmarks/bench_region.py re-measures the "
                             "layers over other sampling regions)")
    parser.add_argument("--movie-every-mm", type=float, default=0.0,
                        help="with --keep: also keep a frame of every particle every this many mm of the roller's "
                             "travel (movie.dump)")
    parser.add_argument("--summarise", action="store_true",
                        help="no runs: rewrite <name>.md and .png from <name>.csv (same --variants, --reference)")
    args = parser.parse_args(argv)
    base = load_config(ROOT / "config.yaml")
    points = [tuple(float(v) for v in p.split(":")) for p in args.points.split(",")]
    names = args.variants.split(",")
    unknown = [n for n in names if n not in VARIANTS]
    if unknown or args.reference not in names:
        parser.error(f"unknown variant(s) {unknown} or reference {args.reference!r} not among --variants; "
                     f"known: {sorted(VARIANTS)}")
    if args.movie_every_mm < 0 or (args.movie_every_mm and args.keep is None):
        parser.error(f"--movie-every-mm {args.movie_every_mm:g}: a positive travel [mm] between frames, with --keep")
    tasks = [(n, variant_config(base, args.level, VARIANTS[n]), args.level, seed, points, args.keep,
              args.movie_every_mm)
             for n in names for seed in range(args.first_seed, args.first_seed + args.seeds)]
    started = time.perf_counter()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    ladders = [[n for n in one.split(",") if n] for one in args.ladder.split(";")]
    if set().union(*ladders) - set(names):
        parser.error(f"--ladder {args.ladder!r} names variants not among --variants {args.variants!r}")
    if args.summarise:
        runs = pd.read_csv(out / f"{args.name}.csv")
        if "sampling_area_mm2" not in runs:  # recorded before the column existed: from the variants' configs
            runs["sampling_area_mm2"] = runs["variant"].map(
                {n: sampling_area_mm2(config, level) for n, config, level, *_ in tasks})
            runs.to_csv(out / f"{args.name}.csv", index=False)
    else:
        done = []
        with ProcessPoolExecutor(args.jobs) as pool:
            for rows in pool.map(run_scene, tasks):  # saved as each scene ends: a long study is not lost
                done += rows
                pd.DataFrame(done).to_csv(out / f"{args.name}.csv", index=False)
        runs = pd.DataFrame(done)
    table = summarise(runs, args.reference)
    plot(table, out / f"{args.name}.png")
    overrides = "\n".join(f"- `{n}`: {VARIANTS[n] or 'the level as configured'}" for n in names)
    fmt = {c: "{:.1%}".format for c in table if c.startswith("err_")}
    shown = table.copy()
    for col, f in fmt.items():
        shown[col] = shown[col].map(lambda v, f=f: "" if pd.isna(v) else f(v))
    for col in ("cpu_s_per_run", "wall_s_per_run", "steps_per_run"):
        shown[col] = shown[col].map(lambda v: "" if pd.isna(v) else f"{v:.0f}")
    command = f"`.venv/bin/python benchmarks/bench_fidelity.py {' '.join(argv if argv is not None else sys.argv[1:])}`"
    when = (f"Runs from `{args.name}.csv` (measured by the same command without `--summarise`), summarised "
            f"{time.strftime('%Y-%m-%d')} by\n{command}.\n\n" if args.summarise else
            f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, "
            f"{args.jobs} scenes at once, in {time.perf_counter() - started:.0f} s, by\n{command}.\n\n")
    packings = packings_per_variant(runs)
    text = (f"# Run time against error ({args.level} level)\n\n" + when +
            f"Points (U mm/s, omega rad/s): {points}; seeds (heap packings) per variant: {packings}.\n"
            f"Error: mean over the points of |variant - reference| / mean |reference|, each the mean "
            f"over its seeds; M_s per unit sampling area (a wider strip has a wider region).\n\n"
            f"Variants:\n{overrides}\n\n" + shown.to_markdown(index=False) + "\n")
    if any(len(ladder) > 1 for ladder in ladders):
        steps = pd.concat([convergence(runs, ladder) for ladder in ladders if len(ladder) > 1], ignore_index=True)
        text += ("\n## Convergence, one step at a time\n\nEach step's largest shift over the points, in "
                 "pooled seed sds of the finer scene, and its mean relative change; converged: every "
                 "metric within 1 sd. Largest Welch t: the largest over the points and metrics of the shift over the "
                 "standard error of the two means (absolute; seed noise alone puts about one comparison in eight "
                 "above 2 with 3 packings a side), and where.\n\n"
                 + steps.to_markdown(index=False, floatfmt=".2f") + "\n")
    (out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
