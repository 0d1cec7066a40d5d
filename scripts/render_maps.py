"""Snakemake entry: Figures 6-10 (surfaces, parity plots, process map), contour maps and the operating
window over maps.axes into a directory; the process map's iso-lines from a smooth model."""

import pandas as pd

from analysis.rule import rule_context
from analysis.surrogate.data import read_split
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.selection import smooth_stand_in
from analysis.viz.maps import render_maps

with rule_context(snakemake):
    model, meta = load_surrogate(snakemake.input.model)
    df = pd.read_csv(snakemake.input.dataset)
    split = read_split(snakemake.input.split, df)
    maps = snakemake.params.maps
    name = (meta.get("model") or {}).get("name")
    smooth, smooth_name = None, None
    if name and getattr(snakemake.input, "predictions", None):   # trees chosen: a smooth model draws the lines
        smooth, smooth_name = smooth_stand_in(df, snakemake.params.surrogate, name, split[0],
                                              pd.read_csv(snakemake.input.predictions))
    note = (f"Iso-lines of the {smooth_name} (fitted on the same runs): the chosen {name} is piecewise flat"
            if smooth is not None else None)
    for path in render_maps(model, df, split, snakemake.output[0], axes=maps["axes"], hold=maps["hold"],
                            panels=maps["panels"], window=maps.get("operating_window"), lines_model=smooth,
                            lines_note=note):
        print(path)
