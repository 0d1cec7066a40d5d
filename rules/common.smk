# Shared by every rule file: the checked configuration, the fidelity level and the runs.
from analysis.metrics.deposit import profile_runs as deposit_profile_runs
from analysis.rule import by_folder
from analysis.config.errors import ConfigError
from analysis.config.fidelity import scene
from analysis.config.folders import find_heap, find_run
from analysis.config.load import load_config
from analysis.config.sweep import (
    heap_config,
    heaps_by_name,
    run_config,
    runs_by_name,
    simulation_fingerprint,
    sweep_runs,
)

try:  # the one check of the workflow's config (schema, then facts across keys); jobs trust it
    CONFIG = load_config(config, base_dir=workflow.basedir)
except ConfigError as err:
    raise WorkflowError(f"config.yaml: {err}") from None

LEVEL = CONFIG["level"]
SCENE = scene(CONFIG, LEVEL)
# The geometry, settle and spread rules carry the fingerprint of the physics of their heap or run
# (its swept values in place) as a parameter: Snakemake re-runs them when it changes (but not for
# MPI ranks or cluster limits).
PROFILOMETER = {**CONFIG["profilometer"], "lines": SCENE.profilometer_lines}
OUT = f"results/{LEVEL}"
LOGS = f"results/logs/{LEVEL}"
BENCH = f"results/benchmarks/{LEVEL}"


# The runs: the U x omega grid (times every extra axis' values: sweep.<config key>), or the explicit
# sweep.points (sweep.points_mm_s_rad_s), each with sweep.replicates heap packings. A run's folder is
# U{U:g}_w{omega:g}_r{rep}, inside one folder per extra axis' value (roller.gap_um=200/...), so a
# point already run under another design is reused; its heap (geometry and settle) is r{rep} inside
# the folders of the axes the heap depends on (a gap reuses the heap settled at roller.gap_um).
RUN_TABLE = runs_by_name(CONFIG)
HEAP_TABLE = heaps_by_name(CONFIG)
RUNS = list(RUN_TABLE)
# Deposit profiles and top views: the runs of the first combination of the extra axes' values.
_FIRST = sweep_runs(CONFIG)[0].values
FIRST_RUNS = {(r.U, r.omega, r.replicate): r.name for r in sweep_runs(CONFIG) if r.values == _FIRST}
POINTS = [(U, w) for U, w, rep in FIRST_RUNS if rep == 0]
# Deposit profiles: the middle U, the omegas nearest -10, 0, +10 rad/s, every replicate.
PROFILE_RUNS = deposit_profile_runs(POINTS, CONFIG["sweep"]["replicates"])
# Top views (the paper's Figure 4): the fastest U at the omegas nearest -5, 0, +5 rad/s.
_U_MAX = max(U for U, _ in POINTS)
_OMEGAS = sorted({min([w for U, w in POINTS if U == _U_MAX], key=lambda w: abs(w - t)) for t in (-5, 0, 5)})
TOP_VIEWS = [f"{OUT}/top_views/{FIRST_RUNS[(_U_MAX, w, 0)]}.png" for w in _OMEGAS]


# The heap folder each run starts from.
HEAP_OF = {name: run.heap for name, run in RUN_TABLE.items()}


# The run of a folder under runs/ (and the first run of a heap folder): the sweep's, or a point
# outside it asked for by its path (results/<level>/runs/U100_w-7_r0/metrics.json), checked as a
# swept point; else one line naming the folder.
run_of = by_folder(find_run, CONFIG, RUN_TABLE, workflow.basedir)
heap_of = by_folder(find_heap, CONFIG, HEAP_TABLE, workflow.basedir)


# A user's substrate mesh is an input of the geometry (its content is in the fingerprints too).
USER_MESH = [str(Path(workflow.basedir) / CONFIG["substrate"]["mesh"])] if CONFIG["substrate"]["mesh"] else []


wildcard_constraints:
    run=r"([A-Za-z_.]+=[^/]+/)*U[0-9.e+-]+_w-?[0-9.e+-]+_r\d+",
    heap=r"([A-Za-z_.]+=[^/]+/)*r\d+",
