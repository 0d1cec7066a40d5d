rule noise_floor:
    """Seed-to-seed spread of each metric per (U, omega) point (needs sweep.replicates >= 2)."""
    input:
        dataset=rules.dataset.output[0],
    output:
        csv=f"{OUT}/surrogate/noise_floor.csv",
        md=report(f"{OUT}/surrogate/noise_floor.md", caption="../report/noise_floor.rst", category="Surrogate"),
    log:
        f"{LOGS}/noise_floor.log",
    benchmark:
        f"{BENCH}/noise_floor.tsv"
    params:
        level=LEVEL,
    script:
        "../scripts/noise_floor.py"


rule model_choice:
    """Candidate surrogates (paper MLP, GP, trees) and their intervals scored by grouped repeated k-fold and LOO CV."""
    input:
        dataset=rules.dataset.output[0],
    output:
        csv=f"{OUT}/surrogate/model_choice.csv",
        md=report(f"{OUT}/surrogate/model_choice.md", caption="../report/model_choice.rst", category="Surrogate"),
        predictions=f"{OUT}/surrogate/cv_predictions.csv",
    log:
        f"{LOGS}/model_choice.log",
    benchmark:
        f"{BENCH}/model_choice.tsv"
    threads: 4  # folds fitted at once; Snakemake caps it at --cores
    params:
        surrogate=CONFIG["surrogate"],
        level=LEVEL,
    script:
        "../scripts/model_choice.py"


rule surrogate:
    """The paper's Table 2 network's scores, and the chosen model (with its calibrated intervals) and grid."""
    input:
        dataset=rules.dataset.output[0],
        choice=rules.model_choice.output.csv,
        predictions=rules.model_choice.output.predictions,
    output:
        model=f"{OUT}/surrogate/model.joblib",
        scores=report(f"{OUT}/surrogate/scores.json", caption="../report/scores.rst", category="Surrogate"),
        split=f"{OUT}/surrogate/split.csv",
        grid=report(f"{OUT}/surrogate/grid.csv", caption="../report/grid.rst", category="Surrogate"),
    log:
        f"{LOGS}/surrogate.log",
    benchmark:
        f"{BENCH}/surrogate.tsv"
    threads: 4  # the network refitted on surrogate.test_splits splits at once; capped at --cores
    params:
        surrogate=CONFIG["surrogate"],
        grid_points=CONFIG["surrogate"]["grid_points"],
    script:
        "../scripts/fit_surrogate.py"
