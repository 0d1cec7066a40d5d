# Shared by every rule file: the checked configuration, the fidelity level and the runs.
from analysis.metrics.deposit import profile_runs as deposit_profile_runs
from analysis.config import ConfigError, design_points, load_config, run_name, scene, simulation_fingerprint

try:  # the one check of the workflow's config (schema, then facts across keys); jobs trust it
    CONFIG = load_config(config, base_dir=workflow.basedir)
except ConfigError as err:
    raise WorkflowError(f"config.yaml: {err}") from None

LEVEL = CONFIG["level"]
SCENE = scene(CONFIG, LEVEL)
# Rule parameters that change when the physics of the level does: Snakemake then re-runs
# the geometry, settle and spread (but not for MPI ranks or cluster limits).
GEOMETRY_FINGERPRINT = simulation_fingerprint(CONFIG, LEVEL, sections=("roller", "substrate"))
SIMULATION_FINGERPRINT = simulation_fingerprint(CONFIG, LEVEL)
PROFILOMETER = {**CONFIG["profilometer"], "lines": SCENE.profilometer_lines}
OUT = f"results/{LEVEL}"
LOGS = f"results/logs/{LEVEL}"
BENCH = f"results/benchmarks/{LEVEL}"


# The runs: the U x omega grid, or the explicit sweep.points_mm_s_rad_s (an off-grid design),
# each with sweep.replicates heap packings; folders are named U{U:g}_w{omega:g}_r{rep}, so
# a point already run under another design is reused.
POINTS = design_points(CONFIG)
RUNS = [run_name(U, w, r) for U, w in POINTS for r in range(CONFIG["sweep"]["replicates"])]
# Deposit profiles: the middle U, the omegas nearest -10, 0, +10 rad/s, every replicate.
PROFILE_RUNS = deposit_profile_runs(POINTS, CONFIG["sweep"]["replicates"])
# Top views (the paper's Figure 4): the fastest U at the omegas nearest -5, 0, +5 rad/s.
_U_MAX = max(U for U, _ in POINTS)
_OMEGAS = sorted({min([w for U, w in POINTS if U == _U_MAX], key=lambda w: abs(w - t)) for t in (-5, 0, 5)})
TOP_VIEWS = [f"{OUT}/top_views/{run_name(_U_MAX, w, 0)}.png" for w in _OMEGAS]


wildcard_constraints:
    U=r"[0-9.e+-]+",
    omega=r"-?[0-9.e+-]+",
    rep=r"\d+",
