"""Snakemake entry: gather every run's metrics, cost and health into one CSV."""

from analysis.metrics.dataset import build_dataset
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    build_dataset(snakemake.input.metrics, snakemake.input.health, snakemake.input.benchmarks, snakemake.output[0],
                  level=config["level"], keep_supply_limited=config["keep_supply_limited_runs"],
                  points=snakemake.params.points)
