rule settle:
    """Insert the heap and let it come to rest, once per replicate; every run starts here."""
    input:
        substrate=rules.geometry.output.substrate,
    output:
        restart=f"{OUT}/settle/r{{rep}}/settled.restart",
        dump=f"{OUT}/settle/r{{rep}}/settled.dump",
        health=f"{OUT}/settle/r{{rep}}/health.json",
    log:
        f"{LOGS}/settle/r{{rep}}.log",
    benchmark:
        f"{BENCH}/settle/r{{rep}}.tsv"
    threads: SCENE.mpi_ranks
    resources:
        mpi=SCENE.mpi_ranks if SCENE.mpi_ranks > 1 else None,  # SLURM plugin: mpi means tasks > 1
        tasks=SCENE.mpi_ranks,
        runtime=SCENE.runtime_min,
        mem_mb=SCENE.mem_mb_per_rank * SCENE.mpi_ranks if SCENE.mem_mb_per_rank else None,
        mem_mb_per_cpu=SCENE.mem_mb_per_rank,  # SLURM: --mem-per-cpu, one CPU per rank
    params:
        level=LEVEL,
        physics=SIMULATION_FINGERPRINT,
    script:
        "../scripts/settle.py"


rule spread:
    """One spreading pass at U [mm/s] and omega [rad/s] from the settled heap."""
    input:
        substrate=rules.geometry.output.substrate,
        roller_shell=rules.geometry.output.roller_shell,
        restart=f"{OUT}/settle/r{{rep}}/settled.restart",
        settled=f"{OUT}/settle/r{{rep}}/settled.dump",
    output:
        dump=f"{OUT}/runs/U{{U}}_w{{omega}}_r{{rep}}/final.dump",
        health=f"{OUT}/runs/U{{U}}_w{{omega}}_r{{rep}}/health.json",
    log:
        f"{LOGS}/spread/U{{U}}_w{{omega}}_r{{rep}}.log",
    benchmark:
        f"{BENCH}/spread/U{{U}}_w{{omega}}_r{{rep}}.tsv"
    threads: SCENE.mpi_ranks
    resources:
        mpi=SCENE.mpi_ranks if SCENE.mpi_ranks > 1 else None,  # SLURM plugin: mpi means tasks > 1
        tasks=SCENE.mpi_ranks,
        runtime=SCENE.runtime_min,
        mem_mb=SCENE.mem_mb_per_rank * SCENE.mpi_ranks if SCENE.mem_mb_per_rank else None,
        mem_mb_per_cpu=SCENE.mem_mb_per_rank,  # SLURM: --mem-per-cpu, one CPU per rank
    params:
        level=LEVEL,
        physics=SIMULATION_FINGERPRINT,
    script:
        "../scripts/spread.py"
