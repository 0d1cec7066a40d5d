rule geometry:
    """Rough substrate (a new realisation per replicate, or the user's STL) and roller meshes of one heap."""
    input:
        USER_MESH,
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
            heap_config(CONFIG, heap_of(wc.heap)),
            LEVEL,
            sections=("roller", "substrate"),
            base_dir=workflow.basedir,
        ),
    script:
        "../scripts/geometry.py"
