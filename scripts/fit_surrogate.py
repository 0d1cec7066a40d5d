"""Snakemake entry: the paper's network (Table 2) scores, then the model chosen by
cross-validation fitted on the same training points; write model, scores, split, grid."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
import pandas as pd  # noqa: E402

from analysis.model_choice import chosen_summary, fit_chosen, read_choice  # noqa: E402
from analysis.surrogate import (fit_surrogate, format_scores, predict_grid,  # noqa: E402
                                save_surrogate, split_table)
from analysis.workflow import atomic_path, rule_context, write_json  # noqa: E402

with rule_context(snakemake):
    out, params = snakemake.output, snakemake.params.surrogate
    df = pd.read_csv(snakemake.input.dataset)
    _, scores = fit_surrogate(df, params)          # the paper's network: the reference scores
    print(format_scores(scores))
    name, table = read_choice(snakemake.input.choice)
    model, info = fit_chosen(df, params, name, scores["split"]["train"])
    scores["model"] = chosen_summary(model, info, df, scores["split"], table)
    print(f"chosen by cross-validation: {name} ({info['description']}); test R "
          + " / ".join(f"{s['R']:.3f}" if s["R"] is not None else "n/a"
                       for s in scores["model"]["test"].values()))
    save_surrogate(model, out.model, scores)
    write_json(scores, out.scores)
    with atomic_path(out.split) as tmp:
        split_table(df, scores["split"]["train"], scores["split"]["test"]).to_csv(tmp, index=False)
    span = scores["input_range"]
    grid = predict_grid(model, span["U_mm_s"], span["omega_rad_s"], snakemake.params.grid_points)
    with atomic_path(out.grid) as tmp:
        grid.to_csv(tmp, index=False)
