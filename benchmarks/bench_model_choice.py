"""Benchmark of the stage after the spreads: the model choice with cold and warm-started leave-one-out fits,
and how far one 35/10 split moves the paper's network's test R.

Run from the repository root::

    .venv/bin/python benchmarks/bench_model_choice.py [--jobs 1] [--seed 0]

On a synthetic 45-point dataset over the default design (the smooth metrics of
tests/conftest.py, each run scattered by the default scene's seed-to-seed noise,
9.8 / 12.3 / 9.1 / 7.7 % for M_s / Q_s / R_q / Phi, docs/uncertainty.md), with
config.yaml's ``surrogate:`` settings: ``cross_validate_models`` once with the
network's leave-one-point-out fits fresh (``warm_loo=False``) and once
warm-started, side by side in one process; the chosen model of each (they
must agree) and their leave-one-out R^2; then ``test_r_spread`` over
``surrogate.test_splits`` seeded splits. Writes
``benchmarks/measured/model_choice.md`` with the machine and its load.
"""

import argparse
import datetime
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from conftest import synthetic_dataset  # noqa: E402

from analysis.columns import METRICS  # noqa: E402
from analysis.surrogate.network import format_spread, test_r_spread  # noqa: E402
from analysis.surrogate.selection import choose_model, cross_validate_models, min_coverage_pct  # noqa: E402

#: The default scene's pooled relative seed-to-seed sd per metric (docs/uncertainty.md).
SEED_NOISE = dict(zip(METRICS, (0.098, 0.123, 0.091, 0.077)))


def noisy_dataset(seed):
    """The synthetic 45-point design, each metric scattered by the default scene's seed noise."""
    df = synthetic_dataset(0)
    rng = np.random.default_rng(seed)
    for m, rel in SEED_NOISE.items():
        df[m] = df[m] * (1 + rel * rng.standard_normal(len(df)))
    return df


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=1, help="folds fitted at once (the rule's threads)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic runs' noise")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks/measured/model_choice.md")
    args = parser.parse_args(argv)
    params = yaml.safe_load((ROOT / "config.yaml").read_text())["surrogate"]
    params["cv_loo"] = True       # every candidate's leave-one-point-out (config.yaml: the tied ones only): their cost
    df = noisy_dataset(args.seed)
    load = os.getloadavg()[0]
    rows, chosen = [], {}
    for label, warm in (("fresh (n_init restarts each)", False), ("warm-started from the k-fold models", True)):
        t0 = time.perf_counter()
        table = cross_validate_models(df, params, log=print, n_jobs=args.jobs, warm_loo=warm)
        wall = time.perf_counter() - t0
        chosen[label] = choose_model(table, params["models"], min_coverage_pct(params))[0]
        loo = table[table.scheme == "loo"].groupby("model", sort=False)
        mlp = table[(table.model == "mlp") & (table.scheme == "loo")]
        rows.append(f"| {label} | {wall:.0f} | {mlp['fit_s'].iloc[0]:.0f} | {chosen[label]} | "
                    + " / ".join(f"{m} {v:.3f}" for m, v in loo["R2"].mean().items()) + " |")
        print(rows[-1], flush=True)
    t0 = time.perf_counter()
    spread = test_r_spread(df, params, params.get("test_splits", 20), n_jobs=args.jobs)
    spread_s = time.perf_counter() - t0
    print(format_spread(spread))
    text = "\n".join([
        "# The stage after the spreads: model choice, and the spread of one split's test R",
        "",
        f"`.venv/bin/python benchmarks/bench_model_choice.py --jobs {args.jobs} --seed {args.seed}`, "
        f"{datetime.date.today()}, {platform.node() or 'this machine'} ({os.cpu_count()} cores, load average "
        f"{load:.1f} at the start: shared), config.yaml's `surrogate:` settings; a synthetic 45-point dataset over "
        "the default design with the default scene's seed noise (9.8 / 12.3 / 9.1 / 7.7 % for M_s / Q_s / R_q / Phi).",
        "",
        "| network's leave-one-point-out fits | model choice, s | network LOO fits, s (summed) | chosen | "
        "mean LOO R^2 per candidate |",
        "|---|---:|---:|---|---|",
        *rows,
        "",
        f"Same choice both ways: {'yes' if len(set(chosen.values())) == 1 else '**no**'}.",
        "",
        f"The paper's network's test R over {spread['n_splits']} seeded 35/10 splits of the same runs "
        f"({spread_s:.0f} s): mean +- sd (min-max) per metric:",
        "",
        "| metric | mean | sd | min | max |",
        "|---|---:|---:|---:|---:|",
        *(f"| {METRICS[m][0]} | {spread[m]['R_mean']:.3f} | {spread[m]['R_sd']:.3f} | {spread[m]['R_min']:.3f} | "
          f"{spread[m]['R_max']:.3f} |" for m in METRICS),
        "",
    ])
    args.out.write_text(text)
    print(text)
    return 0 if len(set(chosen.values())) == 1 else 1


if __name__ == "__main__":
    sys.exit(main())
