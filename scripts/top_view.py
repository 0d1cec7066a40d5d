"""Snakemake entry: top view of a run's sampling region, coloured by particle size."""

from analysis.metrics.dump import read_dump
from analysis.rule import rule_context
from analysis.viz.views import render_top_view

with rule_context(snakemake):
    render_top_view(read_dump(snakemake.input[0]), snakemake.params.region, snakemake.output[0])
