"""The Design of Simulations' dataset: one row per run (speeds, the four layer
metrics, extras, cost and health), refusing any run whose health is unsound."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.columns import METRICS, STRUCTURE_METRICS, input_columns
from analysis.io import atomic_path
from analysis.physics import MAX_OVERLAP

#: The keys of a run's ``health.json`` its dataset row carries.
HEALTH = ["heap_exhausted", "supply_margin", "particles_ahead_of_roller", "fed_particles", "removed_ahead_of_roller",
          "atoms", "lost", "through_substrate", "through_roller", "max_overlap_fraction", "peak_speed_m_s",
          "kinetic_energy_J", "steps", "wall_s", "frozen_particles", "freeze_intruders_removed", "particle_steps",
          "particle_steps_per_s", "rayleigh_fraction", "hertz_fraction", "roller_travel_m", "run_out_m",
          "layer_laid_at_stop", "cpu_s", "resumed_from_step", "timestep_s", "unstable_retries", "unstable_error",
          "effective_gap_um", "gap_min_um", "gap_max_um", "substrate_mean_region_m",
          "inrun_max_overlap_um", "inrun_max_overlap_fraction", "inrun_max_wall_overlap_um",
          "inrun_max_wall_overlap_fraction", "squeeze_outs_max", "squeeze_out_samples",
          "feed_topups", "feed_pile_min_fraction", "fed_max_ahead_of_front_mm", "fed_share_of_region_layer",
          "fed_in_region_landed_ahead_of_roller_mm_median",
          "time_pair_s", "time_neigh_s", "time_comm_s", "time_other_s", "time_loop_s"]


class UnsoundRunError(ValueError):
    """A run's health or metrics rule it out of the dataset."""


class SupplyLimitedError(UnsoundRunError):
    """A run's heap ran dry before the end of the sampling region."""


def check_run(row: dict, level: str = "default", keep_supply_limited: bool = False) -> None:
    """Raise :class:`UnsoundRunError` naming the run and what is wrong with it.

    A run whose heap ran out before the roller passed the end of the sampling
    region (``heap_exhausted``: its M_s and Q_s are lower bounds) raises
    :class:`SupplyLimitedError` naming ``fidelity.<level>.heap_particles``,
    unless ``keep_supply_limited`` (then the row is kept, marked by
    ``heap_exhausted`` = True, and an empty region is a measurement of no powder)."""
    extra = "".join(f", {k}={v:g}" for k, v in row.items() if "." in k)
    name = f"run U={row['U_mm_s']:g} mm/s, omega={row['omega_rad_s']:g} rad/s{extra}, replicate {row['replicate']}"
    if row["heap_exhausted"] and not keep_supply_limited:
        raise SupplyLimitedError(
            f"{name}: the heap ran dry before the end of the sampling region (supply-limited: M_s and Q_s "
            f"would be lower bounds); raise fidelity.{level}.heap_particles or feed the pile "
            f"(fidelity.{level}.feed_pile_mg_per_mm), or set keep_supply_limited_runs: true to keep such runs "
            "(the maps mark them)")
    problems = [f"{key} = {row[key]}" for key in ("lost", "through_substrate", "through_roller") if row.get(key)]
    if row.get("peak_speed_m_s") is not None and not np.isfinite(row["peak_speed_m_s"]):
        problems.append("peak_speed_m_s is not finite (kinetic energy blew up)")
    if row["max_overlap_fraction"] > MAX_OVERLAP:
        problems.append(f"max_overlap_fraction = {row['max_overlap_fraction']:.3f} > {MAX_OVERLAP}")
    problems += [f"{key} is not finite" for key in METRICS if row[key] is None or not np.isfinite(row[key])]
    if row["n_particles"] == 0 and not row["heap_exhausted"]:
        problems.append("no particle in the sampling region (empty layer) with powder still ahead of the roller")
    if problems:
        raise UnsoundRunError(f"{name}: " + "; ".join(problems))


def build_dataset(metrics_files, health_files, benchmark_files, out, level: str = "default",
                  keep_supply_limited: bool = False, points=None) -> pd.DataFrame:
    """Join per-run ``metrics.json``, ``health.json`` and Snakemake benchmark
    TSVs (same order) into ``out`` (CSV, written atomically), each run checked
    by :func:`check_run`.

    ``points`` (one ``{input: value}`` per run, :attr:`analysis.config.sweep.Run.point`) gives each run's
    inputs, first in its row: the run table, not the run's own file, says where a run sits in the
    sweep (a run at the config's own value of an axis was written before the axis was swept).

    ``cpu_s`` is LIGGGHTS' own CPU time (user + system of the launched
    process and its ranks, ``health.json``); Snakemake's benchmark sampling
    misses part of it and gives only ``max_rss_MB`` and ``benchmark_cpu_s``."""
    rows = []
    points = [{}] * len(metrics_files) if points is None else points
    for metrics, health, bench, point in zip(metrics_files, health_files, benchmark_files, points, strict=True):
        row = {**point, **{k: v for k, v in json.loads(Path(metrics).read_text()).items() if k not in point}}
        h = json.loads(Path(health).read_text())
        row.update({key: h.get(key) for key in HEALTH})
        b = pd.read_csv(bench, sep="\t").iloc[-1]
        row.update({"benchmark_cpu_s": float(b["cpu_time"]), "max_rss_MB": float(b["max_rss"])})
        check_run(row, level, keep_supply_limited)
        rows.append(row)
    table = pd.DataFrame(rows)
    table = table.sort_values([*input_columns(table), "replicate"], ignore_index=True)
    with atomic_path(out) as tmp:
        table.to_csv(tmp, index=False)
    return table


def void_fraction_pct(packing_fraction):
    """Void fraction of a layer, %: ``100 (1 - packing fraction)``.

    Parameters
    ----------
    packing_fraction : array_like
        Solid volume of the particles over the volume under the measured layer top,
        ``L_x L_y thk_avg`` (dimensionless; dataset.csv's ``packing_fraction``).

    Returns
    -------
    numpy.ndarray
        The void share of that volume [%]; NaN where the packing fraction is (an empty layer).
    """
    return 100.0 * (1.0 - np.asarray(packing_fraction, float))


def coverage_pct(coverage):
    """Coverage of the substrate, %: ``100 x`` the share of profilometer probes that hit powder
    (``coverage`` of dataset.csv, dimensionless)."""
    return 100.0 * np.asarray(coverage, float)


#: Each layer-structure metric's source column in dataset.csv and its derivation.
_STRUCTURE_SOURCES = {"void_fraction_pct": ("packing_fraction", void_fraction_pct),
                      "coverage_pct": ("coverage", coverage_pct)}


def with_structure_metrics(df):
    """The runs with the layer-structure metrics (:data:`analysis.columns.STRUCTURE_METRICS`) as columns.

    ``void_fraction_pct`` [%] from ``packing_fraction`` and ``coverage_pct`` [%] from ``coverage``
    (:func:`void_fraction_pct`, :func:`coverage_pct`), for the source columns ``df`` has; the
    others are left as they are. Returns a new frame; ``df`` is not changed.
    """
    return df.assign(**{m: derive(df[source]) for m, (source, derive) in _STRUCTURE_SOURCES.items()
                        if source in df})


def structure_problem(df):
    """Why the layer-structure metrics of ``df`` (after :func:`with_structure_metrics`) cannot be
    fitted, as text, or None when every run has them finite."""
    missing = [m for m in STRUCTURE_METRICS if m not in df]
    if missing:
        return "the dataset lacks " + ", ".join(_STRUCTURE_SOURCES[m][0] for m in missing)
    bad = ~np.isfinite(df[list(STRUCTURE_METRICS)].to_numpy(float)).all(axis=1)
    if bad.any():
        return (f"runs {np.flatnonzero(bad).tolist()} have no finite packing fraction or coverage "
                "(an empty layer)")
    return None


def point_groups(df):
    """Label of each run's point (U, omega and any extra axes), numbered in order of first appearance.

    Replicates (runs at the same inputs from different heap packings) share a
    label; with one run per point the labels are ``0 .. n-1`` in row order.

    Parameters
    ----------
    df : pandas.DataFrame
        Has ``U_mm_s`` (mm/s), ``omega_rad_s`` (rad/s) and the extra axes' columns
        (:func:`input_columns`).

    Returns
    -------
    numpy.ndarray of int, shape (n_runs,)
    """
    keys = df[input_columns(df)].to_numpy(float)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first))
    return rank[inverse.ravel()]


def point_means(df, split=None):
    """One row per point (U, omega, extra axes): the replicate mean, std and count of each metric.

    Parameters
    ----------
    df : pandas.DataFrame
        The runs (speeds and the four metrics; the layer-structure metrics too, where it has
        their columns: :func:`with_structure_metrics`).
    split : (array of int, array of int), optional
        Row positions of the training and test runs (by point, see
        :func:`split_runs`); mapped to point positions.

    Returns
    -------
    points : pandas.DataFrame
        In order of first appearance: ``U_mm_s``, ``omega_rad_s``, the extra axes,
        ``n_replicates``, the metric means (their column names) and
        ``<metric>_sd`` (seed-to-seed standard deviation, ddof 1; 0 for a
        single run), in the metrics' units.
    point_split : (array of int, array of int) or None
        Point positions of the training and test points.
    """
    groups, inputs = point_groups(df), input_columns(df)
    metrics = [*METRICS, *(m for m in STRUCTURE_METRICS if m in df)]
    frame = df[inputs + metrics].assign(_point=groups)
    grouped = frame.groupby("_point", sort=True)
    points = grouped[inputs + metrics].mean().reset_index(drop=True)
    points.insert(len(inputs), "n_replicates", grouped.size().to_numpy())
    sd = grouped[metrics].std(ddof=1).fillna(0.0).reset_index(drop=True)
    for m in metrics:
        points[f"{m}_sd"] = sd[m].to_numpy()
    if split is None:
        return points, None
    test_points = np.unique(groups[np.asarray(split[1], int)])
    is_test = np.isin(np.arange(len(points)), test_points)
    return points, (np.flatnonzero(~is_test), np.flatnonzero(is_test))


def workflow_summary(dataset, wall_s: float) -> str:
    """One line on what a workflow's spreads cost: runs, LIGGGHTS' CPU time, the particle-steps
    per CPU second over every particle integrated (``particle_steps``), and the workflow's wall
    time ``wall_s`` [s]. ``dataset`` is a ``dataset.csv`` path or its table.

    The rate is taken over the runs that have both ``particle_steps`` and ``cpu_s``; without
    them it reads n/a.
    """
    df = pd.read_csv(dataset) if isinstance(dataset, (str, Path)) else dataset
    cpu_s = pd.to_numeric(df["cpu_s"], errors="coerce")
    cpu = float(cpu_s.sum())
    steps = pd.to_numeric(df["particle_steps"], errors="coerce") if "particle_steps" in df else None
    both = (steps.notna() & cpu_s.notna() & (cpu_s > 0)) if steps is not None else None
    rate = (float(steps[both].sum()) / float(cpu_s[both].sum()) if both is not None and both.any()
            else float("nan"))
    return (f"spreadmap: {len(df)} runs, LIGGGHTS CPU {cpu / 60:.1f} min ({cpu / max(len(df), 1):.0f} s a run), "
            + (f"{rate / 1e6:.2f} M" if np.isfinite(rate) else "n/a")
            + f" particle-steps per CPU second, workflow wall time {wall_s / 60:.1f} min")


def workflow_summary_line(dataset, started: float, now: float | None = None) -> str:
    """The workflow's last line (the Snakefile's ``onsuccess``), never an exception.

    ``dataset``: the level's ``dataset.csv``; ``started``, ``now``: epoch seconds of the
    workflow's start and end (``now`` defaults to the clock). :func:`workflow_summary` when the
    dataset reads; when this invocation did not write it (older than ``started``: a target short
    of it, or everything up to date), the line says so; without a readable dataset, a short line
    with the wall time and why.
    """
    now = time.time() if now is None else now
    wall = f"workflow wall time {(now - started) / 60:.1f} min"
    path = Path(dataset)
    try:
        if not path.is_file():
            return f"spreadmap: {wall} (no {path}: these targets do not make the dataset)"
        line = workflow_summary(path, now - started)
        if path.stat().st_mtime < started:
            line += f" ({path.name} not remade by this invocation)"
        return line
    except Exception as err:   # noqa: BLE001 (a summary line must never fail the finished workflow)
        return f"spreadmap: {wall} ({path} unreadable for the summary: {type(err).__name__}: {err})"
