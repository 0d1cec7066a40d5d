"""Snakemake entry: the paper's trends beside the dataset's, as Markdown."""
import sys
from pathlib import Path

import pandas as pd

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.trends import markdown, trend_table  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake):
    Path(snakemake.output[0]).write_text(markdown(trend_table(pd.read_csv(snakemake.input[0]))) + "\n")
