"""Snakemake entry: score the candidate surrogates by cross-validation; name the chosen one."""

import pandas as pd

from analysis.metrics.noise_floor import accuracy_ceiling
from analysis.rule import rule_context
from analysis.surrogate.selection import choose_model, cross_validate_models, model_choice_markdown, write_model_choice

with rule_context(snakemake):
    params = snakemake.params.surrogate
    df = pd.read_csv(snakemake.input.dataset)
    table = cross_validate_models(df, params, log=lambda line: print(line, flush=True),
                                  n_jobs=snakemake.threads)
    chosen, ranking = choose_model(table, params["models"])
    ceiling = accuracy_ceiling(df)
    write_model_choice(table, chosen, snakemake.output.csv, snakemake.output.md, ceiling,
                       snakemake.params.level)
    print(model_choice_markdown(table, chosen, ceiling, snakemake.params.level))
