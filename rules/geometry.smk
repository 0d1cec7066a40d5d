rule geometry:
    """Rough substrate (a new realisation per replicate, or the user's STL) and roller meshes of one heap."""
    output:
        substrate=f"{OUT}/meshes/{{heap}}/substrate.stl",
        roller=f"{OUT}/meshes/{{heap}}/roller.stl",
        roller_shell=f"{OUT}/meshes/{{heap}}/roller_shell.stl",
        summary=f"{OUT}/meshes/{{heap}}/geometry.json",
    log:
        f"{LOGS}/geometry/{{heap}}.log",
    benchmark:
        f"{BENCH}/geometry/{{heap}}.tsv"
    params:
        level=LEVEL,
        physics=lambda wc: simulation_fingerprint(
            heap_config(CONFIG, HEAP_TABLE[wc.heap]), LEVEL, sections=("roller", "substrate")
        ),
    script:
        "../scripts/geometry.py"
