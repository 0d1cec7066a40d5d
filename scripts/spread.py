"""Snakemake entry: one spreading pass at the run's U [mm/s] and omega [rad/s], its extra axes' values in place."""
from pathlib import Path

from analysis.config.folders import find_run
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import run_config
from analysis.dem.simulate import spread
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    run = find_run(config, snakemake.wildcards.run, base_dir=PROJECT_DIR)
    spread(run_config(config, run), snakemake.params.level, run.U, run.omega, Path(snakemake.input.substrate).parent,
           Path(snakemake.input.restart).parent, Path(snakemake.output.dump).parent, replicate=run.replicate)
