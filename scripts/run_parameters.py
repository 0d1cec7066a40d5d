"""Snakemake entry: write each run's resolved parameters (parameters.yaml) into its folder."""

import yaml

from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import run_parameters, sweep_runs
from analysis.io import write_text
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    for run, path in zip(sweep_runs(config), snakemake.output, strict=True):
        write_text(yaml.safe_dump(run_parameters(config, run, PROJECT_DIR), sort_keys=False), path)
