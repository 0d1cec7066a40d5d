"""The noise floor: how much a spread layer's metrics change with the heap packing alone.

The paper calls its DEM data noise-free.  It is not: the same spreader speeds
on a differently packed heap (another random seed, same physics) give another
layer.  With ``sweep.replicates`` >= 2 every (U, omega) point is simulated from
several heap packings; the seed-to-seed standard deviation of each metric is
the noise floor, and no surrogate can predict a single run better than it.

:func:`noise_floor` tabulates it per point; :func:`accuracy_ceiling` turns it
into the best cross-validated scores a perfect model of the mean could reach
on these runs (compare :mod:`analysis.surrogate.selection`'s table against them).

Columns, units: as the dataset (``U_mm_s`` mm/s, ``omega_rad_s`` rad/s,
``mass_g`` g, ``throughput_mm2_s`` mm^2/s, ``roughness_um`` um,
``porosity_pct`` %); relative spreads in % of the point's mean.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.columns import METRICS, input_columns, point_label
from analysis.io import atomic_path

#: Row label of the pooled summary in the noise-floor table.
from analysis.metrics.dataset import point_groups, point_means

#: Row label of the pooled summary in the noise-floor table.
POOLED = "pooled"


def noise_floor(df):
    """Seed-to-seed spread of each metric, per (U, omega) point with >= 2 replicates.

    Parameters
    ----------
    df : pandas.DataFrame
        The runs: ``U_mm_s``, ``omega_rad_s`` and the four metric columns,
        several rows (replicates) per point.

    Returns
    -------
    pandas.DataFrame
        One row per replicated point, then a row ``point = "pooled"``:
        ``point`` (``U<U>_w<omega>``), ``U_mm_s``, ``omega_rad_s``,
        ``n_replicates``, and per metric ``<metric>_mean``, ``<metric>_sd``
        (standard deviation over the replicates, ddof 1, metric units) and
        ``<metric>_rel_pct`` (sd / |mean| x 100; NaN where the mean is 0).
        The pooled row has the pooled standard deviation
        ``sqrt(sum (y - mean_point)^2 / sum (n_point - 1))``, the mean of the
        point means, and their ratio.  Empty (no rows) when no point has two
        replicates.
    """
    points, _ = point_means(df)
    rep = points[points["n_replicates"] >= 2].reset_index(drop=True)
    table = pd.DataFrame({
        "point": [point_label(p) for p in rep[input_columns(df)].to_dict("records")],
        **{c: rep[c] for c in input_columns(df)},
        "n_replicates": rep["n_replicates"]})
    dof = (rep["n_replicates"] - 1).to_numpy(float)
    pooled = {"point": POOLED, **{c: np.nan for c in input_columns(df)},
              "n_replicates": int(rep["n_replicates"].sum())}
    for m in METRICS:
        mean, sd = rep[m].to_numpy(float), rep[f"{m}_sd"].to_numpy(float)
        table[f"{m}_mean"], table[f"{m}_sd"] = mean, sd
        table[f"{m}_rel_pct"] = _relative(sd, mean)
        if len(rep):
            pooled_sd = float(np.sqrt(np.sum(dof * sd**2) / dof.sum()))
            pooled_mean = float(np.mean(np.abs(mean)))
            pooled.update({f"{m}_mean": pooled_mean, f"{m}_sd": pooled_sd,
                           f"{m}_rel_pct": float(_relative(pooled_sd, pooled_mean))})
    if len(rep):
        table = pd.concat([table, pd.DataFrame([pooled])], ignore_index=True)
    return table


def pooled_seed_sd(df) -> dict:
    """The pooled seed-to-seed sd of each metric (dataset units): the ``pooled`` row of
    :func:`noise_floor`, as ``{metric: sd}``."""
    pooled = noise_floor(df).set_index("point").loc[POOLED]
    return {m: float(pooled[f"{m}_sd"]) for m in METRICS}


def two_run_tolerance(seed_sd: dict, k: float = 4.0) -> dict:
    """Largest ``|difference|`` of each metric between two runs of one point that are not
    bit-identical (a run resumed from a checkpoint and its straight twin; 2 MPI ranks and 1):
    ``k`` sds of the difference of two runs, ``k x sqrt(2) x`` the seed-to-seed sd ``seed_sd``
    (``{metric: sd}``, dataset units).

    A resumed run is no closer to its straight twin than another heap is: stopped and
    resumed at 10 moments of one smoke spread, its R_q differed by 1.23 pooled seed sds
    (root mean square, largest 2.7; benchmarks/measured/resume.md), so the difference of
    the two has about sqrt(2) seed sds, and ``k`` of a single run's sd would fail a sound
    resume about once in 300 comparisons of one metric.
    """
    return {m: k * float(np.sqrt(2.0)) * sd for m, sd in seed_sd.items()}


def _relative(sd, mean):
    sd, mean = np.asarray(sd, float), np.asarray(mean, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mean != 0, 100.0 * sd / np.abs(mean), np.nan)


def accuracy_ceiling(df):
    """Best cross-validated R, R^2 and MAPE a model of the mean metric can reach on ``df``.

    A perfect model predicts each point's true mean; its error on a single
    run is that run's deviation from the mean, whose variance is the noise
    floor.  Estimated from the points with >= 2 replicates (the noise assumed
    the same at every point):

    * ``R2_max = 1 - s_pooled^2 / var(y)`` over all runs (clipped at 0),
    * ``R_max = sqrt(R2_max)``,
    * ``MAPE_floor_pct``: mean of ``|y - mean_point| / |y| x sqrt(n/(n-1))``
      over the replicated runs with y != 0 (the factor undoes the shrinkage
      of deviations from a sample mean).

    Returns
    -------
    dict or None
        ``{metric: {"sd", "rel_pct", "R_max", "R2_max", "MAPE_floor_pct"}}``
        (``sd`` in the metric's unit, ``rel_pct`` in % of the mean), or None
        when no point has two replicates.
    """
    groups = point_groups(df)
    counts = np.bincount(groups)
    n_run = counts[groups]
    replicated = n_run >= 2
    if not replicated.any():
        return None
    floor = noise_floor(df).set_index("point").loc[POOLED]
    out = {}
    for m in METRICS:
        y = df[m].to_numpy(float)
        group_mean = np.bincount(groups, weights=y) / counts
        dev = (y - group_mean[groups])[replicated]
        scale = np.sqrt(n_run[replicated] / (n_run[replicated] - 1.0))
        y_rep = y[replicated]
        nonzero = y_rep != 0
        sd = float(floor[f"{m}_sd"])
        var_all = float(np.var(y, ddof=1)) if len(y) > 1 else np.nan
        r2 = max(0.0, 1.0 - sd**2 / var_all) if var_all > 0 else np.nan
        mape = (100.0 * np.mean(np.abs(dev[nonzero]) * scale[nonzero] / np.abs(y_rep[nonzero]))
                if nonzero.any() else np.nan)
        out[m] = {"sd": sd, "rel_pct": float(floor[f"{m}_rel_pct"]),
                  "R_max": float(np.sqrt(r2)), "R2_max": float(r2), "MAPE_floor_pct": float(mape)}
    return out


def noise_floor_markdown(table, level=None):
    """The noise-floor table as Markdown: per point, sd and sd/mean of each metric."""
    title = "# Noise floor: seed-to-seed spread of the layer metrics" + (f" ({level})" if level else "")
    if table.empty:
        return (f"{title}\n\nOne run per (U, omega) point: no noise floor measured. Set "
                "`sweep.replicates` to 2 or more (different heap packings, same physics) to "
                "measure it.\n")
    head = ["point", "replicates"] + [f"{s} sd ({u})" for s, u in METRICS.values()]
    lines = [title, "",
             "Standard deviation over the replicates (different random heap packings, same "
             "physics) of each metric, and in brackets relative to its mean. The `pooled` row "
             "pools the variances of all points. No surrogate predicts a single run better "
             "than this.", ""]
    cells = pd.DataFrame({
        head[0]: [f"**{p}**" if p == POOLED else p for p in table["point"]],
        head[1]: table["n_replicates"].astype(int).astype(str),
        **{h: [f"{sd:.3g} ({_pct(rel)})" for sd, rel in zip(table[f"{m}_sd"], table[f"{m}_rel_pct"])]
           for h, m in zip(head[2:], METRICS)}})
    lines.append(cells.to_markdown(index=False, colalign=["left"] * 2 + ["right"] * len(METRICS)))
    return "\n".join(lines) + "\n"


def _pct(x):
    return "n/a" if not np.isfinite(x) else f"{x:.1f} %"


def write_noise_floor(df, csv_path, md_path, level=None):
    """Write :func:`noise_floor` of ``df`` as CSV and Markdown (each atomically); return the table."""
    table = noise_floor(df)
    with atomic_path(csv_path) as tmp:
        table.to_csv(tmp, index=False)
    with atomic_path(md_path) as tmp:
        tmp.write_text(noise_floor_markdown(table, level))
    return table
