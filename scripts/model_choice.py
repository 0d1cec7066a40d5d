"""Snakemake entry: score the candidate surrogates and their intervals by cross-validation;
name the chosen one; keep the held-out predictions (the intervals' calibration set)."""

import pandas as pd

from analysis.metrics.noise_floor import accuracy_ceiling
from analysis.rule import rule_context
from analysis.surrogate.selection import (
    choose_model,
    cross_validate_models,
    min_coverage_pct,
    model_choice_markdown,
    write_model_choice,
)

with rule_context(snakemake):
    params = snakemake.params.surrogate
    df = pd.read_csv(snakemake.input.dataset)
    table, predictions = cross_validate_models(df, params, log=lambda line: print(line, flush=True),
                                               n_jobs=snakemake.threads, return_predictions=True)
    least = min_coverage_pct(params)
    chosen, ranking = choose_model(table, params["models"], least)
    ceiling = accuracy_ceiling(df)
    write_model_choice(table, chosen, snakemake.output.csv, snakemake.output.md, ceiling,
                       snakemake.params.level, params["confidence"], least, predictions,
                       snakemake.output.predictions, cv_loo=params["cv_loo"])
    print(model_choice_markdown(table, chosen, ceiling, snakemake.params.level, params["confidence"], least,
                                params["cv_loo"]))
