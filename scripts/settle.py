"""Snakemake entry: settle the heap of one replicate."""
from pathlib import Path

from analysis.dem.simulate import settle
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    settle(config, snakemake.params.level, Path(snakemake.input.substrate).parent,
           Path(snakemake.output.restart).parent, replicate=int(snakemake.wildcards.rep))
