"""Map error against the number of DEM runs: the paper's grid, a quasi-random design, the adaptive design.

Usage (an idle machine; every run goes through the Snakemake workflow, so runs
already made -- e.g. the 45 grid runs of `make map` -- are reused)::

    .venv/bin/python benchmarks/bench_adaptive.py --level default --cores 2

All designs are simulated at the same fidelity level.  The error of each is
measured against a held-out set of off-grid runs (``--held-out`` points of a
scrambled Sobol sequence with another seed, none on the grid or in a design,
and excluded from the adaptive design's candidates): a surrogate (``--model``,
default the GP of the adaptive loop) is fitted on the design's runs, and per
metric ``nRMSE = RMSE(held-out) / std(held-out values)`` (0: perfect, 1: no
better than the held-out mean; R^2 = 1 - nRMSE^2) is recorded.

Designs: nested sub-grids of the sweep grid (the paper's 5 x 9 = 45 and
coarser ones: 3 x 3, 3 x 5, 5 x 5, 3 x 9), the first n points of a scrambled Sobol
sequence (``--sobol-sizes``; its seed is ``adaptive.seed``, so the adaptive
design starts from the same runs), and the adaptive design (``adaptive:`` in
config.yaml; ``--initial``, ``--batch``, ``--max-runs`` override), scored
after each round.

Writes benchmarks/measured/<name>.csv, .md and .png (``--name``; default
``adaptive`` for the default level, ``adaptive_<level>`` otherwise) with the
machine and the date.  Cost at the default level: held-out + Sobol + adaptive
runs not yet simulated, each a `default` spread (its cost: benchmarks/measured/make_map.md).
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.adaptive_workflow import WorkflowEvaluator  # noqa: E402
from analysis.columns import METRICS  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.surrogate.acquisition import ACQUISITIONS  # noqa: E402
from analysis.surrogate.adaptive import run_adaptive  # noqa: E402
from analysis.surrogate.candidates import CANDIDATES, make_candidate  # noqa: E402
from analysis.surrogate.data import inputs_of, targets_of  # noqa: E402
from analysis.surrogate.design_space import initial_design, sweep_bounds  # noqa: E402
from benchmarks.machine import cpu_model  # noqa: E402


def subgrids(U, omega):
    """Nested sub-grids of the U x omega grid: (label, list of (U, omega)), coarse to full.

    3 x 3, 3 x 5, 5 x 5, 3 x 9 and 5 x 9 for the paper's grid (3 x 9 keeps every omega:
    the metrics vary on ~5 rad/s in omega, on 20-60 mm/s in U).
    """
    U, omega = sorted(U), sorted(omega)

    def coarse(v):
        return [v[0], v[len(v) // 2], v[-1]] if len(v) > 3 else v

    def half(v):
        return v[::2] if len(v) > 3 else v
    out = {}
    for us, ws in ((coarse(U), coarse(omega)), (coarse(U), half(omega)), (U, half(omega)),
                   (coarse(U), omega), (U, omega)):
        out.setdefault(len(us) * len(ws), (f"grid {len(us)}x{len(ws)}",
                                           [(u, w) for u in us for w in ws]))
    return [out[k] for k in sorted(out)]


def off_design(n, bounds, resolution, seed, taken):
    """n Sobol points (seed) on the lattice, none of them in ``taken``."""
    pool = initial_design(max(4 * n, n + len(taken)), bounds, resolution, "sobol", seed)
    taken = {tuple(p) for p in np.round(np.asarray(taken, float), 6)}
    keep = [p for p in pool if tuple(np.round(p, 6)) not in taken]
    if len(keep) < n:
        raise ValueError(f"cannot place {n} held-out points off the designs")
    return np.array(keep[:n])


ACQ = {"mepe": "expected prediction error at the point (mepe)",
       "imse": "integrated variance reduction over the box (imse)"}


def errors(model, held):
    """Per metric nRMSE and R^2 of ``model`` on the held-out runs ``held``."""
    Y, P = targets_of(held), model.predict(inputs_of(held))
    scale = Y.std(axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    nrmse = np.sqrt(((P - Y) ** 2).mean(axis=0)) / scale
    r2 = 1.0 - ((P - Y) ** 2).sum(axis=0) / ((Y - Y.mean(axis=0)) ** 2).sum(axis=0)
    return {**{f"nrmse_{m}": float(v) for m, v in zip(METRICS, nrmse)},
            **{f"r2_{m}": float(v) for m, v in zip(METRICS, r2)},
            "nrmse_mean": float(nrmse.mean())}


def noise_floor_nrmse(path, held):
    """Per metric nRMSE of a perfect map of the mean on single held-out runs: pooled sd / std(held)."""
    pooled = pd.read_csv(path).set_index("point").loc["pooled"]
    scale = targets_of(held).std(axis=0)
    return {m: float(pooled[f"{m}_sd"] / s) for m, s in zip(METRICS, scale)}


def fit(name, params, data):
    model = make_candidate(name, params)
    return model.fit(inputs_of(data), targets_of(data))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", default="default")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--workdir", type=Path, default=ROOT, help="Snakemake working directory")
    parser.add_argument("--held-out", type=int, default=16, help="held-out off-grid points")
    parser.add_argument("--held-out-seed", type=int, default=101)
    parser.add_argument("--sobol-sizes", default="10,15,25", help="comma-separated design sizes")
    parser.add_argument("--grid", help="U1,U2,...:w1,w2,... instead of the config's sweep grid")
    parser.add_argument("--initial", type=int, help="overrides adaptive.initial_points")
    parser.add_argument("--batch", type=int, help="overrides adaptive.batch_size")
    parser.add_argument("--max-runs", type=int, help="overrides adaptive.max_runs")
    parser.add_argument("--acquisition", choices=ACQUISITIONS, help="overrides adaptive.acquisition")
    parser.add_argument("--error-weight", type=float, help="overrides adaptive.error_weight")
    parser.add_argument("--model", default="gp", choices=list(CANDIDATES),
                        help="surrogate whose map error is measured (default gp)")
    parser.add_argument("--name", help="output stem in benchmarks/measured/")
    parser.add_argument("--noise", type=Path, help="noise-floor CSV of the level (default "
                        "benchmarks/measured/noise_<level>.csv if it exists): its pooled sd over "
                        "the held-out values' std is the nRMSE a perfect map of the mean scores")
    args = parser.parse_args(argv)
    config = load_config(ROOT / "config.yaml")
    if args.level not in config["fidelity"]:
        parser.error(f"--level {args.level}: no such fidelity level")
    if args.grid:
        try:
            us, ws = ([float(x) for x in part.split(",")] for part in args.grid.split(":"))
        except ValueError:
            parser.error(f"--grid {args.grid!r}: expected U1,U2,...:w1,w2,...")
        config["sweep"].update({"U_mm_s": us, "omega_rad_s": ws})
    sizes = sorted({int(x) for x in args.sobol_sizes.split(",") if x.strip()})
    settings = {**config["adaptive"], **{k: v for k, v in (("initial_points", args.initial),
                                                          ("batch_size", args.batch),
                                                          ("max_runs", args.max_runs),
                                                          ("acquisition", args.acquisition),
                                                          ("error_weight", args.error_weight))
                                           if v is not None}}
    if config["sweep"]["replicates"] != 1:
        parser.error("the benchmark compares single-run designs: set sweep.replicates to 1")
    name = args.name or ("adaptive" if args.level == "default" else f"adaptive_{args.level}")
    params = config["surrogate"]
    bounds = sweep_bounds(config)
    res = (settings["resolution_U_mm_s"], settings["resolution_omega_rad_s"])
    t_start = time.time()
    say = lambda line: print(line, flush=True)  # noqa: E731
    outdir = args.workdir / f"results/{args.level}/adaptive/bench_{name}"
    evaluate = WorkflowEvaluator(args.level, outdir, args.workdir, args.cores, 1, log=say)

    grid_points = np.array([(u, w) for u in config["sweep"]["U_mm_s"]
                            for w in config["sweep"]["omega_rad_s"]], float)
    sobol = initial_design(max(sizes + [settings["initial_points"]]), bounds, res, "sobol",
                           settings["seed"])
    held_points = off_design(args.held_out, bounds, res, args.held_out_seed,
                             np.r_[grid_points, sobol])
    say(f"bench_adaptive at level {args.level}: grid {len(grid_points)} points, Sobol sizes "
        f"{sizes}, adaptive {settings['initial_points']} + batches of {settings['batch_size']} "
        f"to {settings['max_runs']} runs, {len(held_points)} held-out points; model {args.model}")
    rows = []

    say("grid design:")
    grid_data = evaluate(grid_points)
    say("Sobol design:")
    sobol_data = evaluate(sobol)
    say("held-out runs:")
    held = evaluate(held_points)

    def runs_at(data, pts):
        keys = {(round(float(u), 6), round(float(w), 6)) for u, w in pts}
        return data[[(round(u, 6), round(w, 6)) in keys for u, w in inputs_of(data)]]

    for label, pts in subgrids(config["sweep"]["U_mm_s"], config["sweep"]["omega_rad_s"]):
        data = runs_at(grid_data, pts)
        rows.append({"design": "grid", "label": label, "n_runs": len(data),
                     **errors(fit(args.model, params, data), held)})
        say(f"  {label}: {len(data)} runs, mean nRMSE {rows[-1]['nrmse_mean']:.3f}")
    for n in sizes:
        data = runs_at(sobol_data, sobol[:n])          # the first n points of the sequence
        rows.append({"design": "sobol", "label": f"sobol {n}", "n_runs": n,
                     **errors(fit(args.model, params, data), held)})
        say(f"  sobol {n}: mean nRMSE {rows[-1]['nrmse_mean']:.3f}")

    def score_round(k, data, gp):
        model = gp if args.model == "gp" else fit(args.model, params, data)
        rows.append({"design": "adaptive", "label": f"adaptive round {k}", "n_runs": len(data),
                     **errors(model, held)})
        say(f"  adaptive round {k}: {len(data)} runs, mean nRMSE {rows[-1]['nrmse_mean']:.3f}")

    say("adaptive design:")
    result = run_adaptive(evaluate, bounds, settings, exclude=held_points, on_round=score_round,
                          log=say)
    table = pd.DataFrame(rows)
    noise = args.noise or ROOT / f"benchmarks/measured/noise_{args.level}.csv"
    floor = noise_floor_nrmse(noise, held) if noise.exists() else None
    write(table, result, args, name, settings, time.time() - t_start, held_points, floor, noise)
    return 0


def write(table, result, args, name, settings, elapsed, held_points, floor=None, noise=None):
    out = ROOT / "benchmarks" / "measured"
    out.mkdir(parents=True, exist_ok=True)
    table.to_csv(out / f"{name}.csv", index=False)
    full = table[table.design == "grid"].sort_values("n_runs").iloc[-1]
    lines = [f"# Map error against the number of DEM runs ({args.level} level)", "",
             f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {cpu_model()}, "
             f"in {elapsed:.0f} s (runs already simulated were reused), by",
             f"`.venv/bin/python benchmarks/bench_adaptive.py {' '.join(sys.argv[1:])}`.", "",
             f"Error: a {args.model} surrogate ({CANDIDATES[args.model]}) fitted on each design's "
             f"runs, against {len(held_points)} held-out off-grid runs (Sobol, seed "
             f"{args.held_out_seed}; never in a design). nRMSE = RMSE / std of the held-out "
             "values per metric (R^2 = 1 - nRMSE^2); mean over M_s, Q_s, R_q, Phi.", "",
             f"Adaptive design: {settings['initial_points']} Sobol points, then batches of "
             f"{settings['batch_size']} by {ACQ[settings.get('acquisition', 'mepe')]} (error weight "
             f"{settings['error_weight']}), budget {settings['max_runs']} runs; stopped by "
             f"{result.stop}.", ""]
    if floor:
        lines += [f"Noise floor: the seed-to-seed spread (pooled, `{Path(noise).name}`) over the held-out "
                  "values' std, the nRMSE a perfect map of the mean would score on single runs: "
                  + " / ".join(f"{v:.3f}" for v in floor.values())
                  + f" (mean {np.mean(list(floor.values())):.3f}).", ""]
    for design in ("adaptive", "sobol"):
        part = table[table.design == design].sort_values("n_runs")
        reach = part[part.nrmse_mean <= full.nrmse_mean]
        lines.append(f"- {design}: " + (
            f"reaches the {int(full.n_runs)}-run grid's error ({full.nrmse_mean:.3f}) with "
            f"{int(reach.n_runs.iloc[0])} runs" if len(reach) else
            f"does not reach the {int(full.n_runs)}-run grid's error ({full.nrmse_mean:.3f}) "
            f"within {int(part.n_runs.max())} runs (best {part.nrmse_mean.min():.3f})"))
    symbols = [s for s, _ in METRICS.values()]
    lines += ["", f"| design | runs | nRMSE {' / '.join(symbols)} | mean nRMSE | "
              f"R^2 {' / '.join(symbols)} |", "|---|---:|---|---:|---|"]
    for row in table.sort_values(["design", "n_runs"]).itertuples():
        nr = " / ".join(f"{getattr(row, f'nrmse_{m}'):.3f}" for m in METRICS)
        r2 = " / ".join(f"{getattr(row, f'r2_{m}'):.3f}" for m in METRICS)
        lines.append(f"| {row.label} | {row.n_runs} | {nr} | {row.nrmse_mean:.3f} | {r2} |")
    lines += ["", "Adaptive design points (round 0: the initial Sobol design):", "",
              "| round | U (mm/s) | omega (rad/s) |", "|---:|---:|---:|"]
    lines += [f"| {int(r['round'])} | {r.U_mm_s:g} | {r.omega_rad_s:g} |"
              for _, r in result.design.iterrows()]
    (out / f"{name}.md").write_text("\n".join(lines) + "\n")

    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for design, style in (("grid", "s-"), ("sobol", "o-"), ("adaptive", "^-")):
        part = table[table.design == design].sort_values("n_runs")
        ax.plot(part.n_runs, part.nrmse_mean, style, label=design)
    ax.axhline(full.nrmse_mean, color="0.6", lw=0.8, ls="--",
               label=f"{int(full.n_runs)}-run grid")
    if floor:
        ax.axhline(np.mean(list(floor.values())), color="0.3", lw=0.8, ls=":",
                   label="noise floor (perfect map of the mean)")
    ax.set(xlabel="DEM runs", ylabel="mean nRMSE on held-out runs",
           title=f"Map error against runs ({args.level} level, {args.model} surrogate)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.savefig(out / f"{name}.png", dpi=130)
    print(f"wrote {out / name}.csv, .md, .png")


if __name__ == "__main__":
    sys.exit(main())
