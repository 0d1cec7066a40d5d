rule surrogate:
    """The paper's Table 2 network over (U, omega), with scores and a fine grid."""
    input:
        dataset=rules.dataset.output[0],
    output:
        model=f"{OUT}/surrogate/model.joblib",
        scores=report(f"{OUT}/surrogate/scores.json", category="Surrogate"),
        split=f"{OUT}/surrogate/split.csv",
        grid=report(f"{OUT}/surrogate/grid.csv", category="Surrogate"),
    params:
        surrogate=CONFIG["surrogate"],
        grid_points=CONFIG["surrogate"]["grid_points"],
    log:
        f"{LOGS}/surrogate.log",
    benchmark:
        f"{BENCH}/surrogate.tsv"
    script:
        "../scripts/fit_surrogate.py"
