rule settle:
    """Insert the heap and let it come to rest, once per replicate and heap-changing value; runs start here."""
    input:
        substrate=rules.geometry.output.substrate,
    output:
        restart=f"{OUT}/settle/{{heap}}/settled.restart",
        dump=f"{OUT}/settle/{{heap}}/settled.dump",
        health=f"{OUT}/settle/{{heap}}/health.json",
    log:
        f"{LOGS}/settle/{{heap}}.log",
    benchmark:
        f"{BENCH}/settle/{{heap}}.tsv"
    threads: SCENE.mpi_ranks
    resources:
        mpi=SCENE.mpi_ranks if SCENE.mpi_ranks > 1 else None,  # SLURM plugin: mpi means tasks > 1
        tasks=SCENE.mpi_ranks,
        runtime=SCENE.runtime_min,
        mem_mb=SCENE.mem_mb_per_rank * SCENE.mpi_ranks if SCENE.mem_mb_per_rank else None,
        mem_mb_per_cpu=SCENE.mem_mb_per_rank,  # SLURM: --mem-per-cpu, one CPU per rank
    params:
        level=LEVEL,
        physics=lambda wc: simulation_fingerprint(
            heap_config(CONFIG, heap_of(wc.heap)), LEVEL, base_dir=workflow.basedir
        ),
    script:
        "../scripts/settle.py"


rule spread:
    """One spreading pass at U [mm/s] and omega [rad/s] (and the run's extra axes' values) from its settled heap."""
    input:
        substrate=lambda wc: f"{OUT}/meshes/{run_of(wc.run).heap}/substrate.stl",
        roller_shell=lambda wc: f"{OUT}/meshes/{run_of(wc.run).heap}/roller_shell.stl",
        restart=lambda wc: f"{OUT}/settle/{run_of(wc.run).heap}/settled.restart",
        settled=lambda wc: f"{OUT}/settle/{run_of(wc.run).heap}/settled.dump",
    output:
        dump=f"{OUT}/runs/{{run}}/final.dump",
        health=f"{OUT}/runs/{{run}}/health.json",
    log:
        f"{LOGS}/spread/{{run}}.log",
    benchmark:
        f"{BENCH}/spread/{{run}}.tsv"
    threads: SCENE.mpi_ranks
    resources:
        mpi=SCENE.mpi_ranks if SCENE.mpi_ranks > 1 else None,  # SLURM plugin: mpi means tasks > 1
        tasks=SCENE.mpi_ranks,
        runtime=SCENE.runtime_min,
        mem_mb=SCENE.mem_mb_per_rank * SCENE.mpi_ranks if SCENE.mem_mb_per_rank else None,
        mem_mb_per_cpu=SCENE.mem_mb_per_rank,  # SLURM: --mem-per-cpu, one CPU per rank
    params:
        level=LEVEL,
        physics=lambda wc: simulation_fingerprint(run_config(CONFIG, run_of(wc.run)), LEVEL, base_dir=workflow.basedir),
    script:
        "../scripts/spread.py"


rule run_parameters:
    """Each run's full resolved parameters (its extra axes' values in place), beside its results."""
    output:
        expand(f"{OUT}/runs/{{run}}/parameters.yaml", run=RUNS),
    log:
        f"{LOGS}/run_parameters.log",
    params:
        physics=[
            simulation_fingerprint(run_config(CONFIG, run), LEVEL, base_dir=workflow.basedir)
            for run in RUN_TABLE.values()
        ],
    script:
        "../scripts/run_parameters.py"
