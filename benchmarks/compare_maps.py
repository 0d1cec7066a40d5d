"""Two maps of the same Design of Simulations side by side: how far one moved from the other.

Run from the repository root (no simulation; it reads two finished maps' datasets)::

    .venv/bin/python benchmarks/compare_maps.py OLD/dataset.csv NEW/dataset.csv \
        [--labels "5 MPa,20 MPa"] [--old-variant NAME | --old-means LABEL]
        [--noise benchmarks/measured/noise_default.csv | --noise RUNS.csv --noise-variant NAME] [--name maps_compared]

For each of the four metrics and each group of points (all, omega < 0, omega = 0, omega > 0): the
mean of each map over the points both ran, the mean relative change ``100 (new - old) / old`` per
point, and the mean absolute change in the pooled seed sd of ``--noise`` (optional: a noise-floor
CSV with ``<metric>_sd`` columns per point, or a ``bench_fidelity`` run table and the variant whose
seeds give it; its sampling region should be the maps'), and the paired t of the change (its mean over
its standard error across the points: whether the points share it). With ``--old-variant``, OLD is such a run table
and that variant's seed means per point stand for the old map (only the points it ran are compared);
with ``--old-means``, OLD is an earlier comparison's table and its group means stand for the old map.
Writes ``benchmarks/measured/<name>.csv`` and ``.md``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from benchmarks.bench_fidelity import METRICS  # noqa: E402
from benchmarks.machine import commit  # noqa: E402

KEYS = ["U_mm_s", "omega_rad_s"]
GROUPS = {"all": lambda w: w == w, "omega < 0": lambda w: w < 0, "omega = 0": lambda w: w == 0,
          "omega > 0": lambda w: w > 0}


def point_means(dataset: pd.DataFrame) -> pd.DataFrame:
    """The metrics' mean per (U, omega) point over its replicates."""
    return dataset.groupby(KEYS)[list(METRICS)].mean()


def variant_runs(runs: pd.DataFrame, variant: str) -> pd.DataFrame:
    """The finished runs of one variant of a ``bench_fidelity`` run table."""
    if "variant" not in runs:
        raise ValueError("not a bench_fidelity run table (no 'variant' column)")
    picked = runs[(runs["variant"] == variant) & (runs["error"].isna() if "error" in runs else True)]
    if picked.empty:
        raise ValueError(f"no runs of variant {variant!r} in the run table")
    return picked


def pooled_sd(noise: pd.DataFrame, variant: str | None = None) -> dict:
    """Root mean seed variance of each metric over a noise floor's points: a noise-floor CSV
    (``<metric>_sd`` per point) or, with ``variant``, that variant's runs in a ``bench_fidelity``
    run table (the sd over its seeds at each point)."""
    if variant is not None:
        sd = variant_runs(noise, variant).groupby(KEYS)[list(METRICS)].std()
        return {k: float(np.sqrt((sd[k] ** 2).mean())) for k in METRICS}
    return {k: float(np.sqrt((noise[f"{k}_sd"] ** 2).mean())) for k in METRICS if f"{k}_sd" in noise}


def compare_with_means(old_means: pd.DataFrame, label: str, new: pd.DataFrame, sds: dict | None = None) -> pd.DataFrame:
    """As :func:`compare`, against an older map kept only as a comparison's group means (the
    ``<label> mean`` column of an earlier ``compare_maps`` table): the change of the group's mean [%]
    and, with ``sds``, of the mean in those sds."""
    column = f"{label} mean"
    if column not in old_means:
        raise ValueError(f"no column {column!r} in the old comparison (its columns: {', '.join(old_means.columns)})")
    b = point_means(new)
    omega = b.index.get_level_values("omega_rad_s").to_numpy()
    old_by = old_means.set_index(["points", "metric"])[column]
    rows = []
    for group, pick in GROUPS.items():
        mask = pick(omega)
        for k, name in METRICS.items():
            if not mask.any() or (group, name) not in old_by.index:
                continue
            x, y = float(old_by[(group, name)]), float(b[k].to_numpy()[mask].mean())
            row = {"points": group, "n": int(mask.sum()), "metric": name, "old_mean": x, "new_mean": y,
                   "change_pct": 100 * (y - x) / x}
            if sds and k in sds:
                row["abs_change_in_sds"] = abs(y - x) / sds[k]
            rows.append(row)
    return pd.DataFrame(rows)


def compare(old: pd.DataFrame, new: pd.DataFrame, sds: dict | None = None) -> pd.DataFrame:
    """One row per (group of points, metric): both maps' means, the mean relative change [%],
    with ``sds`` (metric -> pooled seed sd) the mean absolute change in those sds, and the paired t
    of the change (:func:`paired_t`)."""
    a, b = point_means(old), point_means(new)
    shared = a.index.intersection(b.index)
    if shared.empty:
        raise ValueError("the two datasets share no (U, omega) point")
    a, b = a.loc[shared], b.loc[shared]
    omega = shared.get_level_values("omega_rad_s").to_numpy()
    rows = []
    for group, pick in GROUPS.items():
        mask = pick(omega)
        if not mask.any():
            continue
        for k, name in METRICS.items():
            x, y = a[k].to_numpy()[mask], b[k].to_numpy()[mask]
            row = {"points": group, "n": int(mask.sum()), "metric": name, "old_mean": x.mean(), "new_mean": y.mean(),
                   "change_pct": 100 * np.mean((y - x) / x)}
            if sds and k in sds:
                row["abs_change_in_sds"] = np.mean(np.abs(y - x)) / sds[k]
            row["paired_t"] = paired_t(y - x, scale=np.abs(x).mean())
            rows.append(row)
    return pd.DataFrame(rows)


def paired_t(diff: np.ndarray, scale: float = 1.0) -> float:
    """The mean of the points' differences over its standard error (a paired t statistic, n - 1 degrees
    of freedom): a change the points share stands out of the scatter a chaotic run adds to each point.
    NaN with fewer than 2 points or no scatter beyond 1e-4 of ``scale`` (the values' size): runs identical
    but for the precision their dumps were printed with."""
    scatter = np.std(diff, ddof=1) if len(diff) > 1 else 0.0
    return float(np.mean(diff) / (scatter / np.sqrt(len(diff)))) if scatter > 1e-4 * scale else float("nan")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old", type=Path)
    parser.add_argument("new", type=Path)
    parser.add_argument("--labels", default="old,new", help="the two maps' names, comma-separated")
    parser.add_argument("--noise", type=Path, help="a noise-floor CSV (<metric>_sd per point), or a bench_fidelity "
                        "run table with --noise-variant")
    parser.add_argument("--noise-variant", help="the variant of --noise's runs whose seed sd judges the change")
    parser.add_argument("--old-variant", help="OLD is a bench_fidelity run table: this variant's runs are the old map")
    parser.add_argument("--old-means", metavar="LABEL", help="OLD is an earlier comparison's table: its "
                        "'<LABEL> mean' column holds the old map's group means (the change is of the means)")
    parser.add_argument("--name", default="maps_compared")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    for path in (args.old, args.new, args.noise):
        if path is not None and not path.is_file():
            parser.error(f"no such file: {path}")
    labels = args.labels.split(",")
    if len(labels) != 2:
        parser.error(f"--labels {args.labels!r}: give two names, comma-separated")
    datasets = [pd.read_csv(path) for path in (args.old, args.new)]
    try:
        if args.old_variant is not None:
            datasets[0] = variant_runs(datasets[0], args.old_variant)
        sds = pooled_sd(pd.read_csv(args.noise), args.noise_variant) if args.noise else None
        table = (compare_with_means(datasets[0], args.old_means, datasets[1], sds) if args.old_means
                 else compare(*datasets, sds))
    except ValueError as err:
        parser.error(str(err))
    table = table.rename(columns={"old_mean": f"{labels[0]} mean", "new_mean": f"{labels[1]} mean"})
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / f"{args.name}.csv", index=False)
    text = (f"# {labels[1]} against {labels[0]}: the same Design of Simulations\n\n"
            f"Compared {time.strftime('%Y-%m-%d')} at commit {commit()} by\n`.venv/bin/python "
            f"benchmarks/compare_maps.py {args.old} {args.new} --labels \"{args.labels}\""
            + (f" --old-variant {args.old_variant}" if args.old_variant else "")
            + (f" --old-means \"{args.old_means}\"" if args.old_means else "")
            + (f" --noise {args.noise}" if args.noise else "")
            + (f" --noise-variant {args.noise_variant}" if args.noise_variant else "") + "`.\n\n"
            + ("change_pct: 100 (new - old) / old of the group's means; abs_change_in_sds: the means' absolute "
               if args.old_means else
               "change_pct: the mean over the points of 100 (new - old) / old; abs_change_in_sds: the mean absolute ")
            + "change over the pooled seed sd of the noise floor given.\n\n"
            + table.to_markdown(index=False, floatfmt=".3g") + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
