"""Snakemake entry: Figures 6-10 (surfaces, parity plots, process map) into a directory."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
import pandas as pd  # noqa: E402

from analysis.maps import render_maps  # noqa: E402
from analysis.surrogate import load_surrogate, read_split  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake):
    model, _ = load_surrogate(snakemake.input.model)
    df = pd.read_csv(snakemake.input.dataset)
    for path in render_maps(model, df, read_split(snakemake.input.split, df), snakemake.output[0]):
        print(path)
