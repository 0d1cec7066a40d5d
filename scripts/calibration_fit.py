"""Snakemake entry: the tests' results as a table, a surrogate per measured property, the
coefficients that reproduce the measurements (refused, with the reachable range, if none do),
written as a config file for --configfile; the response surfaces."""
from pathlib import Path

from analysis.calibration.calibrate import (
    calibrated_config,
    coefficient_bounds,
    collect_results,
    fit_responses,
    response_summary,
    solve,
    targets,
)
from analysis.calibration.report import plot_responses
from analysis.io import write_json
from analysis.rule import rule_context

with rule_context(snakemake):
    cal, out = snakemake.params.calibration, snakemake.output
    bounds, measured = coefficient_bounds(cal), targets(cal)
    results = collect_results(cal, [Path(p) for p in snakemake.input])
    responses = fit_responses(results, list(bounds), list(measured), snakemake.params.confidence,
                              n_restarts=snakemake.params.gp_restarts)
    results.to_csv(out.results, index=False)
    solution = solve(responses, measured, bounds, snakemake.params.confidence, cal["grid_points"])
    solution["responses"] = response_summary(responses)
    print({k: solution[k] for k in ("chosen", "range", "predicted")})
    Path(out.config).write_text(calibrated_config(solution, cal["measured"].get("source") or ""))
    write_json(solution, out.solution)
    plot_responses(responses, results, bounds, solution, Path(out.surfaces))
