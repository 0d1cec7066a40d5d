"""Snakemake entry: the noise floor (seed-to-seed spread per point) as CSV and Markdown."""

import pandas as pd

from analysis.metrics.noise_floor import noise_floor_markdown, write_noise_floor
from analysis.rule import rule_context

with rule_context(snakemake):
    table = write_noise_floor(pd.read_csv(snakemake.input.dataset), snakemake.output.csv,
                              snakemake.output.md, snakemake.params.level)
    print(noise_floor_markdown(table, snakemake.params.level))
