"""Snakemake entry: Figures 6-10 (surfaces, parity plots, process map), contour maps and the operating
window over maps.axes into a directory."""

import pandas as pd

from analysis.rule import rule_context
from analysis.surrogate.data import read_split
from analysis.surrogate.persistence import load_surrogate
from analysis.viz.maps import render_maps

with rule_context(snakemake):
    model, _ = load_surrogate(snakemake.input.model)
    df = pd.read_csv(snakemake.input.dataset)
    maps = snakemake.params.maps
    for path in render_maps(model, df, read_split(snakemake.input.split, df), snakemake.output[0],
                            axes=maps["axes"], hold=maps["hold"], panels=maps["panels"],
                            window=maps.get("operating_window")):
        print(path)
