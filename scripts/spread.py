"""Snakemake entry: one spreading pass at the run's U [mm/s] and omega [rad/s]."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.simulate import spread  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake) as config:
    w = snakemake.wildcards
    spread(config, snakemake.params.level, float(w.U), float(w.omega), Path(snakemake.input.substrate).parent,
           Path(snakemake.input.restart).parent, Path(snakemake.output.dump).parent, replicate=int(w.rep))
