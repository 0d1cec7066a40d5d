"""Snakemake entry: one spreading pass at the run's U [mm/s] and omega [rad/s]."""
from pathlib import Path

from analysis.dem.simulate import spread
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    w = snakemake.wildcards
    spread(config, snakemake.params.level, float(w.U), float(w.omega), Path(snakemake.input.substrate).parent,
           Path(snakemake.input.restart).parent, Path(snakemake.output.dump).parent, replicate=int(w.rep))
