"""Snakemake entry: settle one heap (a replicate, with the values of the axes the heap depends on)."""
from pathlib import Path

from analysis.config import heap_config, heaps_by_name
from analysis.dem.simulate import settle
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    run = heaps_by_name(config)[snakemake.wildcards.heap]
    settle(heap_config(config, run), snakemake.params.level, Path(snakemake.input.substrate).parent,
           Path(snakemake.output.restart).parent, replicate=run.replicate)
