"""Snakemake entry: write one replicate's substrate and roller meshes."""
from pathlib import Path

from analysis.dem.simulate import make_geometry
from analysis.io import write_json
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    summary = make_geometry(config, snakemake.params.level, Path(snakemake.output.substrate).parent,
                            base_dir=Path(snakemake.scriptdir).parent,
                            replicate=int(snakemake.wildcards.rep))
    write_json(summary, snakemake.output.summary)
