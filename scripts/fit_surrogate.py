"""Snakemake entry: the paper's network (Table 2) scores, then the model chosen by
cross-validation fitted on the same training points, its intervals calibrated on its
held-out predictions, and the same candidate fitted to the layer-structure metrics (void
fraction, coverage) stacked beside it; write model, scores, split, grid."""

import sys

import pandas as pd

from analysis.io import atomic_path, write_json
from analysis.rule import rule_context
from analysis.surrogate.data import split_table
from analysis.surrogate.intervals import unbounded_warning
from analysis.surrogate.network import fit_surrogate, format_spread, test_r_spread
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.predict import predict_grid
from analysis.surrogate.scores import format_scores
from analysis.surrogate.selection import chosen_summary, fit_calibrated, read_choice
from analysis.surrogate.structure import format_structure, stack_structure

with rule_context(snakemake):
    out, params = snakemake.output, snakemake.params.surrogate
    df = pd.read_csv(snakemake.input.dataset)
    _, scores = fit_surrogate(df, params, n_jobs=snakemake.threads)   # the paper's network: the reference scores
    print(format_scores(scores))
    scores["test_spread"] = test_r_spread(df, params, params.get("test_splits", 20), n_jobs=snakemake.threads,
                                          known={int(params["split_seed"]): scores["test"]})   # split 0: that fit
    print(format_spread(scores["test_spread"]))
    name, table = read_choice(snakemake.input.choice)
    model, info, source = fit_calibrated(df, params, name, scores["split"]["train"],
                                         pd.read_csv(snakemake.input.predictions), n_jobs=snakemake.threads)
    scores["model"] = {**chosen_summary(model, info, df, scores["split"], table), "intervals": model.summary()}
    print(f"intervals: {model.method}; {100 * model.confidence:g} % multiplier "
          + " / ".join(f"{q:.2f}" for q in model.multiplier()[:4]) + f"; noise: {source}")
    print(f"chosen by cross-validation: {name} ({info['description']}); test R "
          + " / ".join(f"{s['R']:.3f}" if s["R"] is not None else "n/a"
                       for s in scores["model"]["test"].values()))
    model, scores["structure"] = stack_structure(model, df, params, name, scores["split"], n_jobs=snakemake.threads)
    print(format_structure(scores["structure"]))
    save_surrogate(model, out.model, scores)
    write_json(scores, out.scores)
    with atomic_path(out.split) as tmp:
        split_table(df, scores["split"]["train"], scores["split"]["test"]).to_csv(tmp, index=False)
    span = scores["input_range"]
    extra = {c: scores["swept"][c] for c in list(scores["inputs"])[2:]}  # at each swept value of the other axes
    grid = predict_grid(model, span["U_mm_s"], span["omega_rad_s"], snakemake.params.grid_points, extra=extra)
    warning = unbounded_warning(grid, model.n_runs, model.confidence)
    if warning:  # in the log and on the workflow's screen
        print(warning)
        print(f"rule surrogate: {warning}", file=sys.__stderr__, flush=True)
    with atomic_path(out.grid) as tmp:
        grid.to_csv(tmp, index=False)
