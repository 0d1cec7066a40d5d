"""Snakemake entry: score the candidate surrogates by cross-validation; name the chosen one."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
import pandas as pd  # noqa: E402

from analysis.model_choice import (choose_model, cross_validate_models,  # noqa: E402
                                   model_choice_markdown, write_model_choice)
from analysis.noise_floor import accuracy_ceiling  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

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
