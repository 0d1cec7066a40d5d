rule geometry:
    """Rough substrate (a new realisation per replicate, or the user's STL) and roller meshes of the level."""
    output:
        substrate=f"{OUT}/meshes/r{{rep}}/substrate.stl",
        roller=f"{OUT}/meshes/r{{rep}}/roller.stl",
        roller_shell=f"{OUT}/meshes/r{{rep}}/roller_shell.stl",
        summary=f"{OUT}/meshes/r{{rep}}/geometry.json",
    log:
        f"{LOGS}/geometry/r{{rep}}.log",
    benchmark:
        f"{BENCH}/geometry/r{{rep}}.tsv"
    params:
        level=LEVEL,
        physics=GEOMETRY_FINGERPRINT,
    script:
        "../scripts/geometry.py"
