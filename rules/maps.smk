rule maps:
    """Figures 6-10: regressed surfaces, parity plots, the hybrid process map; contour maps, operating window."""
    input:
        model=rules.surrogate.output.model,
        dataset=rules.dataset.output[0],
        split=rules.surrogate.output.split,
        predictions=rules.model_choice.output.predictions,  # a smooth model's lines when trees are chosen
    output:
        report(directory(f"{OUT}/maps"), patterns=["{name}.png"], caption="../report/maps.rst", category="Process maps"),
    log:
        f"{LOGS}/maps.log",
    benchmark:
        f"{BENCH}/maps.tsv"
    params:
        maps=CONFIG["maps"],
        surrogate=CONFIG["surrogate"],
    script:
        "../scripts/render_maps.py"


rule front_page:
    """The finished map's facts for the report's front page (report/workflow.rst includes them)."""
    input:
        model=rules.surrogate.output.model,
        scores=rules.surrogate.output.scores,
        choice=rules.model_choice.output.csv,
    output:
        f"{OUT}/front_page.rst",
    log:
        f"{LOGS}/front_page.log",
    benchmark:
        f"{BENCH}/front_page.tsv"
    params:
        window=CONFIG["maps"].get("operating_window"),
    script:
        "../scripts/front_page.py"


rule top_view:
    """Top view of the sampling region, particles coloured by size (Figure 4)."""
    input:
        rules.spread.output.dump,
    output:
        report(f"{OUT}/top_views/{{run}}.png", caption="../report/top_view.rst", category="Top views"),
    log:
        f"{LOGS}/top_view/{{run}}.log",
    benchmark:
        f"{BENCH}/top_view/{{run}}.tsv"
    params:
        region=SCENE.sampling_region,
    script:
        "../scripts/top_view.py"
