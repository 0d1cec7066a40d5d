rule geometry:
    """Rough substrate (or the user's STL) and roller meshes of the level."""
    output:
        substrate=f"{OUT}/meshes/substrate.stl",
        roller=f"{OUT}/meshes/roller.stl",
        roller_shell=f"{OUT}/meshes/roller_shell.stl",
        summary=f"{OUT}/meshes/geometry.json",
    params:
        level=LEVEL,
        physics=GEOMETRY_FINGERPRINT,
    log:
        f"{LOGS}/geometry.log",
    benchmark:
        f"{BENCH}/geometry.tsv"
    script:
        "../scripts/geometry.py"
