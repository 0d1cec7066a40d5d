"""Snakemake entry: the noise floor (seed-to-seed spread per point) as CSV and Markdown."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
import pandas as pd  # noqa: E402

from analysis.noise_floor import noise_floor_markdown, write_noise_floor  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake):
    table = write_noise_floor(pd.read_csv(snakemake.input.dataset), snakemake.output.csv,
                              snakemake.output.md, snakemake.params.level)
    print(noise_floor_markdown(table, snakemake.params.level))
