"""Snakemake entry: write one heap's substrate and roller meshes (its replicate and heap-changing values)."""
from pathlib import Path

from analysis.config.folders import find_heap
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import heap_config
from analysis.dem.simulate import make_geometry
from analysis.io import write_json
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    run = find_heap(config, snakemake.wildcards.heap, base_dir=PROJECT_DIR)
    summary = make_geometry(heap_config(config, run), snakemake.params.level, Path(snakemake.output.substrate).parent,
                            base_dir=Path(snakemake.scriptdir).parent, replicate=run.replicate)
    write_json(summary, snakemake.output.summary)
