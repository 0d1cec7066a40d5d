"""Snakemake entry: fit the surrogate (paper, Table 2); write model, scores, split, grid."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
import pandas as pd  # noqa: E402

from analysis.surrogate import (atomic_path, fit_surrogate, format_scores, predict_grid,  # noqa: E402
                                save_surrogate, split_table)
from analysis.workflow import rule_context, write_json  # noqa: E402

with rule_context(snakemake):
    out = snakemake.output
    df = pd.read_csv(snakemake.input.dataset)
    model, scores = fit_surrogate(df, snakemake.params.surrogate)
    print(format_scores(scores))
    save_surrogate(model, out.model, scores)
    write_json(scores, out.scores)
    with atomic_path(out.split) as tmp:
        split_table(df, scores["split"]["train"], scores["split"]["test"]).to_csv(tmp, index=False)
    span = scores["input_range"]
    grid = predict_grid(model, span["U_mm_s"], span["omega_rad_s"], snakemake.params.grid_points)
    with atomic_path(out.grid) as tmp:
        grid.to_csv(tmp, index=False)
