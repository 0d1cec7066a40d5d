"""Do the calibrated intervals cover what they claim? Held-out DEM runs and synthetic runs of known noise.

Usage (after ``make map``: it reads the default dataset, runs no DEM)::

    .venv/bin/python benchmarks/bench_intervals.py [--dataset results/default/dataset.csv] \\
        [--outer-repeats 2] [--synthetic-seeds 3] [--models mlp,gp,trees]

**DEM, held out** (nested grouped cross-validation): the runs are split into
``cv_folds`` folds by (U, omega) point (shuffle seed 100 + repeat, not the
workflow's); for each fold the workflow's procedure is repeated on the other
runs alone: the candidates' grouped k-fold cross-validation
(:func:`analysis.surrogate.selection.cross_validate_models`, config's ``cv_folds``
x ``cv_repeats``), the choice (:func:`~analysis.surrogate.selection.choose_model`),
each candidate fitted to those runs and calibrated on its held-out predictions
(:func:`analysis.surrogate.intervals.calibrated_from_predictions`), then the
interval of each run of the fold, which no step saw.  *chosen* is the candidate
the choice picked in each fold, as the workflow would have.

**Synthetic** (tests/conftest.py's paper-like metrics, 5 % relative Gaussian
noise, the 45-point grid): the same procedure on all 45 runs, checked against
2,000 new noisy runs and the noise-free truth at random off-grid speeds, per seed.

Writes benchmarks/measured/intervals.csv (one row per data, model, metric) and
intervals.md, with the single-run interval's width beside the noise floor
(``benchmarks/measured/noise_default.csv``: 1.645 x the seed-to-seed sd is the
narrowest honest 90 % run interval).
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import norm

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]     # `benchmarks` (run as a script); tests' synthetic data

from analysis.columns import METRICS  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.metrics.noise_floor import POOLED  # noqa: E402
from analysis.surrogate.data import inputs_of, point_folds, targets_of  # noqa: E402
from analysis.surrogate.intervals import calibrated_from_predictions, interval_score, relative_noise  # noqa: E402
from analysis.surrogate.selection import choose_model, cross_validate_models, fit_chosen, min_coverage_pct  # noqa: E402
from benchmarks.machine import cpu_model  # noqa: E402


def calibrated_candidates(df, params):
    """The workflow's procedure on ``df``: CV, choice, each candidate fitted and calibrated.

    Returns ({name: CalibratedSurrogate}, chosen name)."""
    table, held_out = cross_validate_models(df, params, return_predictions=True)
    chosen, _ = choose_model(table, params["models"], min_coverage_pct(params))
    rho, source = relative_noise(df, random_state=int(params["random_state"]))
    models = {}
    for name in params["models"]:
        model, _ = fit_chosen(df, params, name)
        mine = held_out[(held_out.model == name) & (held_out.scheme == "kfold")]
        models[name] = calibrated_from_predictions(model, mine, df, rho, params["confidence"], source)
    return models, chosen


def records(fitted, X, y, truth=None, **labels):
    """One row per (point, metric): the run, the prediction and both intervals."""
    mean, lo, hi = fitted.predict_interval(X, kind="run")
    _, mlo, mhi = fitted.predict_interval(X, kind="mean")
    k = len(METRICS)
    n = len(X)
    frame = pd.DataFrame({"metric": np.tile(list(METRICS), n), "y": y[:, :k].ravel(),
                          "pred": mean[:, :k].ravel(), "lo": lo[:, :k].ravel(), "hi": hi[:, :k].ravel(),
                          "mean_lo": mlo[:, :k].ravel(), "mean_hi": mhi[:, :k].ravel()})
    if truth is not None:
        frame["truth"] = truth[:, :k].ravel()
    for key, value in labels.items():
        frame[key] = value
    return frame


def held_out_dem(df, params, repeats, log):
    rows = []
    for o in range(repeats):
        for f, (train, test) in enumerate(point_folds(df, params["cv_folds"], 100 + o)):
            t0 = time.perf_counter()
            models, chosen = calibrated_candidates(df.iloc[train].reset_index(drop=True), params)
            X, Y = inputs_of(df)[test], targets_of(df)[test]
            for name, model in models.items():
                rows.append(records(model, X, Y, data="dem", model=name, repeat=o, fold=f))
                if name == chosen:
                    rows.append(records(model, X, Y, data="dem", model="chosen", repeat=o, fold=f, picked=name))
            log(f"outer repeat {o} fold {f}: chosen {chosen}, {time.perf_counter() - t0:.0f} s")
    return pd.concat(rows, ignore_index=True)


def synthetic(params, seeds, log):
    from conftest import synthetic_dataset, synthetic_metrics
    noise, rows = 0.05, []
    for seed in range(seeds):
        t0 = time.perf_counter()
        df = synthetic_dataset(seed, noise=noise)
        models, chosen = calibrated_candidates(df, params)
        rng = np.random.default_rng(1000 + seed)
        X = np.c_[rng.uniform(40, 100, 2000), rng.uniform(-20, 20, 2000)]
        truth = np.column_stack(list(synthetic_metrics(X[:, 0], X[:, 1]).values()))
        runs = truth * (1 + noise * rng.standard_normal(truth.shape))
        for name, model in models.items():
            rows.append(records(model, X, runs, truth, data="synthetic", model=name, repeat=seed))
            if name == chosen:
                rows.append(records(model, X, runs, truth, data="synthetic", model="chosen", repeat=seed,
                                    picked=name))
        log(f"synthetic seed {seed}: chosen {chosen}, {time.perf_counter() - t0:.0f} s")
    return pd.concat(rows, ignore_index=True)


def summarise(runs, confidence):
    """Coverage (%), mean width (metric units and % of the mean |y|), interval score (%) per data, model, metric."""
    def one(g):
        inside = (g.y >= g.lo) & (g.y <= g.hi)
        scale = g.y.abs().mean() / 100
        out = {"n": len(g), "coverage_pct": 100 * inside.mean(), "width": (g.hi - g.lo).mean(),
               "width_pct": (g.hi - g.lo).mean() / scale,
               "interval_score_pct": interval_score(g.y, g.lo, g.hi, confidence).mean() / scale,
               "mean_width": (g.mean_hi - g.mean_lo).mean()}
        out["mean_coverage_pct"] = (100 * ((g.truth >= g.mean_lo) & (g.truth <= g.mean_hi)).mean()
                                    if "truth" in g and g.truth.notna().any() else np.nan)
        return out
    return pd.DataFrame([{"data": d, "model": m, "metric": x, **one(g)}
                         for (d, m, x), g in runs.groupby(["data", "model", "metric"], sort=False)])


def _shown(path):
    """``path`` relative to the repository when inside it."""
    path = Path(path).resolve()
    return path.relative_to(ROOT) if path.is_relative_to(ROOT) else path


def write_md(table, runs, args, params, noise_sd, elapsed, path):
    symbols = [s for s, _ in METRICS.values()]
    level = f"{100 * params['confidence']:g} %"
    z = norm.ppf(0.5 + params["confidence"] / 2)
    lines = [f"# Coverage of the calibrated {level} intervals: held-out DEM runs and synthetic runs", "",
             f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {cpu_model()} (2 cores shared with "
             f"a DEM study), in {elapsed:.0f} s, by `.venv/bin/python benchmarks/bench_intervals.py "
             f"{' '.join(sys.argv[1:])}` (no DEM run: `{_shown(args.dataset)}`, the 45-run `default` map, one run "
             "per point).", "",
             f"Intervals: {params['confidence']:g}-level grouped cross-conformal "
             "(analysis.surrogate.intervals, docs/uncertainty.md), calibrated on the config's grouped "
             f"{params['cv_folds']}-fold x {params['cv_repeats']} held-out predictions of the runs each model "
             "was fitted to. *chosen*: the candidate the workflow's choice rule picked from those runs alone.", ""]

    def block(data, title, note, extra=()):
        part = table[table.data == data]
        if part.empty:
            return []
        head = (["model", f"covers %: {' / '.join(symbols)}", "mean covers %", f"width %: {' / '.join(symbols)}",
                 f"interval score %: {' / '.join(symbols)}"] + [e[0] for e in extra])
        out = [f"## {title}", "", note, "", "| " + " | ".join(head) + " |",
               "|" + "|".join(["---"] * len(head)) + "|"]
        for model, g in part.groupby("model", sort=False):
            g = g.set_index("metric").loc[list(METRICS)]
            cells = [model, " / ".join(f"{v:.0f}" for v in g.coverage_pct), f"{g.coverage_pct.mean():.1f}",
                     " / ".join(f"{v:.1f}" for v in g.width_pct), " / ".join(f"{v:.1f}" for v in g.interval_score_pct)]
            cells += [fn(g) for _, fn in extra]
            out.append("| " + " | ".join(cells) + " |")
        return out + [""]

    picked = runs[(runs.data == "dem") & (runs.model == "chosen")].groupby(["repeat", "fold"])["picked"].first()
    n_dem = runs[(runs.data == "dem") & (runs.model == "chosen")].shape[0] // len(METRICS)
    lines += block("dem", f"Held-out DEM runs (nested grouped {params['cv_folds']}-fold x {args.outer_repeats})",
                   f"{n_dem} held-out runs x 4 metrics per model ({args.outer_repeats} outer repeat(s) of the 45); "
                   f"width and interval score in % of the mean metric. The choice picked: "
                   + ", ".join(f"{m} in {c} of {len(picked)} folds" for m, c in picked.value_counts().items()) + ".",
                   [(f"mean half-width: {' / '.join(symbols)}",
                     lambda g: " / ".join(f"{v / 2:.3g}" for v in g.width))])
    lines += block("synthetic", f"Synthetic runs, 5 % relative noise, {args.synthetic_seeds} seeds",
                   "The 45-point grid with noise, the same procedure on all 45 runs; checked against 2,000 new "
                   "noisy runs at random off-grid speeds per seed. *Mean covers*: the noise-free truth inside "
                   "the interval of the mean (not conformal: the calibrated std of the mean).",
                   [(f"mean interval covers truth %: {' / '.join(symbols)}",
                     lambda g: " / ".join(f"{v:.0f}" for v in g.mean_coverage_pct))])
    if noise_sd is not None:
        chosen = table[(table.data == "dem") & (table.model == "chosen")].set_index("metric")
        lines += ["## Against the run-to-run spread", "",
                  f"The narrowest honest {level} interval of a single run is +- {z:.3f} x the seed-to-seed sd "
                  "(benchmarks/measured/noise_default.csv, pooled); the chosen model's mean half-width on the "
                  "held-out DEM runs beside it (dataset units):", "",
                  "| metric | seed sd | +- z sd | chosen half-width | ratio |", "|---|---:|---:|---:|---:|"]
        for m, (s, _) in METRICS.items():
            half = chosen.loc[m, "width"] / 2
            lines.append(f"| {s} | {noise_sd[m]:.3g} | {z * noise_sd[m]:.3g} | {half:.3g} | "
                         f"{half / (z * noise_sd[m]):.1f} |")
        lines += ["", "A ratio above 1: the interval holds the run-to-run noise and the map's own error "
                  "(model error from 36 training points); the noise alone would under-cover."]
    path.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", type=Path, default=ROOT / "results/default/dataset.csv")
    parser.add_argument("--outer-repeats", type=int, default=2, help="repeats of the outer grouped k-fold")
    parser.add_argument("--synthetic-seeds", type=int, default=3, help="synthetic datasets (0: none)")
    parser.add_argument("--models", default=None, help="candidates (default: config's surrogate.models)")
    parser.add_argument("--noise-floor", type=Path, default=ROOT / "benchmarks/measured/noise_default.csv")
    parser.add_argument("--name", default="intervals")
    args = parser.parse_args(argv)
    if not args.dataset.exists():
        parser.error(f"--dataset {args.dataset} does not exist: run `make map` first")
    params = dict(load_config(ROOT / "config.yaml")["surrogate"])
    params["cv_loo"] = False
    if args.models:
        params["models"] = args.models.split(",")
    df = pd.read_csv(args.dataset)
    t0 = time.perf_counter()

    def log(line):
        print(f"[{time.perf_counter() - t0:6.0f} s] {line}", flush=True)

    parts = [held_out_dem(df, params, args.outer_repeats, log)]
    if args.synthetic_seeds:
        parts.append(synthetic(params, args.synthetic_seeds, log))
    runs = pd.concat(parts, ignore_index=True)
    table = summarise(runs, params["confidence"])
    out = ROOT / "benchmarks/measured" / f"{args.name}.md"
    table.to_csv(out.with_suffix(".csv"), index=False)
    noise_sd = None
    if args.noise_floor.exists():      # a noise_floor.csv (analysis.metrics.noise_floor): its pooled row
        pooled = pd.read_csv(args.noise_floor).set_index("point").loc[POOLED]
        noise_sd = {m: float(pooled[f"{m}_sd"]) for m in METRICS}
    write_md(table, runs, args, params, noise_sd, time.perf_counter() - t0, out)
    print(f"wrote {out.with_suffix('.csv')}, {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
