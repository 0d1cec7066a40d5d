"""Snakemake entry: the paper's trends beside the dataset's, as Markdown."""

import pandas as pd

from analysis.io import write_text
from analysis.metrics.trends import markdown, trend_table
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    table = trend_table(pd.read_csv(snakemake.input[0]), roller_radius_mm=config["roller"]["diameter_mm"] / 2,
                        mean_diameter_um=config["psd"]["mean_diameter_um"])
    write_text(markdown(table) + "\n", snakemake.output[0])
