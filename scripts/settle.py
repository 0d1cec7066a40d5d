"""Snakemake entry: settle the heap of one replicate."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.simulate import settle  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake) as config:
    settle(config, snakemake.params.level, Path(snakemake.input.substrate).parent,
           Path(snakemake.output.restart).parent, replicate=int(snakemake.wildcards.rep))
