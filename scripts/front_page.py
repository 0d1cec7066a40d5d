"""Snakemake entry: the finished map's facts for the report's front page (report/workflow.rst includes them)."""

import json

import pandas as pd

from analysis.rule import rule_context
from analysis.surrogate.persistence import load_surrogate
from analysis.viz.front_page import write_front_page

with rule_context(snakemake):
    model, meta = load_surrogate(snakemake.input.model)
    scores = json.loads(open(snakemake.input.scores).read())
    path = write_front_page(snakemake.output[0], scores, pd.read_csv(snakemake.input.choice), model, meta,
                            snakemake.params.window)
    print(open(path).read())
