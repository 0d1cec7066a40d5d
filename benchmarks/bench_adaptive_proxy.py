"""How many runs does a design need on a surface like the DEM data's? A noise-known proxy.

Usage (after ``make map``: it reads the default dataset, runs no DEM)::

    .venv/bin/python benchmarks/bench_adaptive_proxy.py [--dataset results/default/dataset.csv] [--reps 8]

``bench_adaptive.py`` measures designs on real DEM runs, but with one noise
draw and 16 held-out runs its ranking of designs is itself noisy.  Here the
truth is known: a Gaussian process (:class:`~analysis.surrogate.candidates.GPSurrogate`)
fitted to the 45 grid runs gives a smooth surface with the DEM data's own
length scales, and its white-noise term the run-to-run noise.  A design's
"run" is the truth plus a fresh noise draw; its error is the GP it fits
against the noise-free truth on a 25 x 25 grid over the sweep box
(nRMSE = RMSE / std of the truth, mean over the four metrics).  Repeated
``--reps`` times (noise draws and Sobol seeds), for: the nested grids (9, 15,
25, 27, 45 runs), Sobol designs and the adaptive loop
(:func:`analysis.surrogate.adaptive.run_adaptive`, 10 Sobol points and batches of 3, up
to ``--max-runs``) with each acquisition (``mepe``, ``imse``), scored after
every round.

Writes benchmarks/measured/adaptive_proxy.csv (every design, run count and
rep) and .md (mean and spread over the reps; the fewest runs with which each
design family reaches the 45-run grid's mean error).
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.columns import METRICS  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.surrogate.acquisition import ACQUISITIONS  # noqa: E402
from analysis.surrogate.adaptive import run_adaptive  # noqa: E402
from analysis.surrogate.candidates import GPSurrogate  # noqa: E402
from analysis.surrogate.data import inputs_of, targets_of  # noqa: E402
from analysis.surrogate.design_space import initial_design, sweep_bounds  # noqa: E402
from benchmarks.bench_adaptive import subgrids  # noqa: E402
from benchmarks.machine import cpu_model  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", type=Path, default=ROOT / "results/default/dataset.csv")
    parser.add_argument("--reps", type=int, default=8, help="noise draws and Sobol seeds")
    parser.add_argument("--max-runs", type=int, default=45, help="adaptive budget")
    parser.add_argument("--sobol-sizes", default="10,15,25,45")
    parser.add_argument("--name", default="adaptive_proxy")
    args = parser.parse_args(argv)
    if not args.dataset.exists():
        parser.error(f"--dataset {args.dataset} does not exist: run `make map` first")
    config = load_config(ROOT / "config.yaml")
    data = pd.read_csv(args.dataset)
    grid = {(float(u), float(w)) for u in config["sweep"]["U_mm_s"] for w in config["sweep"]["omega_rad_s"]}
    if set(map(tuple, inputs_of(data).tolist())) != grid:
        parser.error(f"--dataset {args.dataset} is not the config's {len(grid)}-point sweep grid (another "
                     "run of the workflow, e.g. a noise-floor config, may have overwritten it): run `make map`")
    truth = GPSurrogate().fit(inputs_of(data), targets_of(data))
    noise = truth.noise_std_
    bounds = sweep_bounds(config)
    settings = {**config["adaptive"], "max_runs": args.max_runs, "target_loo_r2": None}
    res = (settings["resolution_U_mm_s"], settings["resolution_omega_rad_s"])
    ref = np.array([(u, w) for u in np.linspace(*bounds[0], 25) for w in np.linspace(*bounds[1], 25)])
    F = truth.predict(ref)
    scale = F.std(axis=0)
    sizes = sorted({int(x) for x in args.sobol_sizes.split(",") if x.strip()})
    started = time.perf_counter()
    say = lambda line: print(line, flush=True)  # noqa: E731
    say(f"truth: GP on {len(data)} runs of {args.dataset}; length scales (U mm/s, omega rad/s) "
        + "; ".join(f"{m} {ls[0]:.1f}, {ls[1]:.2f}" for m, ls in zip(METRICS, truth.length_scales_))
        + "; noise sd " + ", ".join(f"{m} {s:.3g}" for m, s in zip(METRICS, noise)))

    def error(model):
        e = np.sqrt(((model.predict(ref) - F) ** 2).mean(axis=0)) / scale
        return {**{f"nrmse_{m}": float(v) for m, v in zip(METRICS, e)}, "nrmse_mean": float(e.mean())}

    rows = []
    for rep in range(args.reps):
        rng = np.random.default_rng(rep)

        def run(points, rng=rng):
            P = np.atleast_2d(np.asarray(points, float))
            Y = truth.predict(P) + rng.normal(size=(len(P), len(METRICS))) * noise
            return pd.DataFrame(np.c_[P, Y], columns=["U_mm_s", "omega_rad_s", *METRICS])

        def fitted(frame):
            return GPSurrogate().fit(inputs_of(frame), targets_of(frame))
        for label, pts in subgrids(config["sweep"]["U_mm_s"], config["sweep"]["omega_rad_s"]):
            rows.append({"design": "grid", "label": label, "rep": rep, "n_runs": len(pts),
                         **error(fitted(run(pts)))})
        sobol = run(initial_design(max(sizes), bounds, res, "sobol", seed=rep))
        for n in sizes:
            rows.append({"design": "sobol", "label": f"sobol {n}", "rep": rep, "n_runs": n,
                         **error(fitted(sobol.iloc[:n]))})
        for acq in ACQUISITIONS:
            def score(k, frame, gp, acq=acq, rep=rep):
                rows.append({"design": f"adaptive {acq}", "label": f"adaptive {acq}", "rep": rep,
                             "n_runs": len(frame), **error(gp)})
            run_adaptive(run, bounds, {**settings, "acquisition": acq, "seed": rep},
                         on_round=score, log=lambda line: None)
        say(f"rep {rep}: done, {time.perf_counter() - started:.0f} s")
    table = pd.DataFrame(rows)
    out = ROOT / "benchmarks" / "measured"
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / f"{args.name}.csv", index=False)
    write_md(table, args, settings, truth, noise, time.perf_counter() - started, out / f"{args.name}.md")
    return 0


def write_md(table, args, settings, truth, noise, elapsed, path):
    cols = [f"nrmse_{m}" for m in METRICS] + ["nrmse_mean"]
    summary = table.groupby(["design", "n_runs"])[cols].mean()
    spread = table.groupby(["design", "n_runs"])["nrmse_mean"].std()
    grid_full = summary.loc[("grid", summary.loc["grid"].index.max()), "nrmse_mean"]
    n_full = int(summary.loc["grid"].index.max())
    symbols = [s for s, _ in METRICS.values()]
    lines = ["# Map error against runs on a noise-known proxy of the default dataset", "",
             f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {cpu_model()}, in "
             f"{elapsed:.0f} s, by `.venv/bin/python benchmarks/bench_adaptive_proxy.py "
             f"{' '.join(sys.argv[1:])}` (no DEM run: the truth is a GP fitted to `{args.dataset.name}`).", "",
             "Truth: length scales (U mm/s, omega rad/s) "
             + "; ".join(f"{s} {ls[0]:.1f}, {ls[1]:.2f}" for s, ls in zip(symbols, truth.length_scales_))
             + "; run-to-run noise sd " + ", ".join(f"{s} {v:.3g}" for s, v in zip(symbols, noise))
             + " (the dataset's units). The sweep box is 60 mm/s x 40 rad/s.", "",
             f"Error: nRMSE of each design's GP against the noise-free truth on a 25 x 25 grid, mean "
             f"over {args.reps} reps (noise draws and Sobol seeds), +- the reps' sd. Adaptive: "
             f"{settings['initial_points']} Sobol points, batches of {settings['batch_size']}, error "
             f"weight {settings['error_weight']}.", ""]
    for design in summary.index.get_level_values(0).unique():
        part = summary.loc[design]["nrmse_mean"]
        reach = part[part <= grid_full]
        lines.append(f"- {design}: " + (f"reaches the {n_full}-run grid's error ({grid_full:.3f}) "
                                        f"with {int(reach.index.min())} runs" if len(reach) else
                                        f"does not reach the {n_full}-run grid's error ({grid_full:.3f}) "
                                        f"within {int(part.index.max())} runs (best {part.min():.3f})"))
    lines += ["", f"| design | runs | nRMSE {' / '.join(symbols)} | mean nRMSE (+- sd over reps) |",
              "|---|---:|---|---:|"]
    for (design, n), row in summary.iterrows():
        per = " / ".join(f"{row[c]:.3f}" for c in cols[:-1])
        lines.append(f"| {design} | {n} | {per} | {row['nrmse_mean']:.3f} +- {spread[(design, n)]:.3f} |")
    path.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {path.with_suffix('.csv')}, {path}")


if __name__ == "__main__":
    sys.exit(main())
