"""Snakemake entry: top view of a run's sampling region, coloured by particle size."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.dump import read_dump  # noqa: E402
from analysis.render import render_top_view  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake):
    render_top_view(read_dump(snakemake.input[0]), snakemake.params.region, snakemake.output[0])
