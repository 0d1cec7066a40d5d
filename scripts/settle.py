"""Snakemake entry: settle one heap (a replicate, with the values of the axes the heap depends on)."""
from pathlib import Path

from analysis.config.folders import find_heap
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import heap_config
from analysis.dem.simulate import settle
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    run = find_heap(config, snakemake.wildcards.heap, base_dir=PROJECT_DIR)
    settle(heap_config(config, run), snakemake.params.level, Path(snakemake.input.substrate).parent,
           Path(snakemake.output.restart).parent, replicate=run.replicate)
