rule layer_metrics:
    """The paper's eqs. 1-7 from the final dump, by the virtual profilometer; the layer as VTK for ParaView."""
    input:
        dump=rules.spread.output.dump,
        substrate=lambda wc: f"{OUT}/meshes/{run_of(wc.run).heap}/substrate.stl",
    output:
        metrics=f"{OUT}/runs/{{run}}/metrics.json",
        vtk=f"{OUT}/runs/{{run}}/final.vtp",  # here, not in a rule of its own: one Python start per run
    log:
        f"{LOGS}/metrics/{{run}}.log",
    benchmark:
        f"{BENCH}/metrics/{{run}}.tsv"
    params:
        level=LEVEL,
        profilometer=PROFILOMETER,
    script:
        "../scripts/layer_metrics.py"


rule dataset:
    """One row per run: speeds, the four metrics, extras, cost and health."""
    input:
        metrics=expand(f"{OUT}/runs/{{run}}/metrics.json", run=RUNS),
        health=expand(f"{OUT}/runs/{{run}}/health.json", run=RUNS),
        benchmarks=expand(f"{BENCH}/spread/{{run}}.tsv", run=RUNS),
    output:
        report(f"{OUT}/dataset.csv", caption="../report/dataset.rst", category="Dataset"),
    log:
        f"{LOGS}/dataset.log",
    benchmark:
        f"{BENCH}/dataset.tsv"
    params:
        points=[RUN_TABLE[run].point for run in RUNS],  # each run's inputs, from the run table
    script:
        "../scripts/dataset.py"


rule trends:
    """The paper's section-3 trends beside this dataset's (Markdown table)."""
    input:
        rules.dataset.output[0],
    output:
        report(f"{OUT}/trends.md", caption="../report/trends.rst", category="Dataset"),
    log:
        f"{LOGS}/trends.log",
    script:
        "../scripts/trends.py"


rule deposit_profile:
    """Layer mass along the travel for a few omegas, sampling region shaded: is the region in steady state?"""
    input:
        [f"{OUT}/runs/{FIRST_RUNS[(U, w, r)]}/final.dump" for U, w, r in PROFILE_RUNS],
    output:
        csv=f"{OUT}/deposit_profile.csv",
        png=report(f"{OUT}/deposit_profile.png", caption="../report/deposit_profile.rst", category="Dataset"),
    log:
        f"{LOGS}/deposit_profile.log",
    benchmark:
        f"{BENCH}/deposit_profile.tsv"
    params:
        level=LEVEL,
        runs=PROFILE_RUNS,
    script:
        "../scripts/deposit_profile.py"
