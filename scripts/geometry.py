"""Snakemake entry: write one replicate's substrate and roller meshes."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.simulate import make_geometry  # noqa: E402
from analysis.workflow import rule_context, write_json  # noqa: E402

with rule_context(snakemake) as config:
    summary = make_geometry(config, snakemake.params.level, Path(snakemake.output.substrate).parent,
                            base_dir=Path(snakemake.scriptdir).parent,
                            replicate=int(snakemake.wildcards.rep))
    write_json(summary, snakemake.output.summary)
