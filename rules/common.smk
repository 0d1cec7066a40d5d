# Shared by every rule file: the checked configuration, the fidelity level and the runs.
from analysis.config import ConfigError, load_config, scene  # noqa: E402

try:
    CONFIG = load_config(config, base_dir=workflow.basedir)
except ConfigError as err:
    raise WorkflowError(f"config.yaml: {err}") from None

LEVEL = CONFIG["level"]
SCENE = scene(CONFIG, LEVEL)
OUT = f"results/{LEVEL}"
LOGS = f"results/logs/{LEVEL}"
BENCH = f"results/benchmarks/{LEVEL}"


def run_name(U, omega, replicate):
    """Folder name of one run: U in mm/s, omega in rad/s, replicate index."""
    return f"U{U:g}_w{omega:g}_r{replicate}"


RUNS = [run_name(U, w, r) for U in CONFIG["sweep"]["U_mm_s"] for w in CONFIG["sweep"]["omega_rad_s"]
        for r in range(CONFIG["sweep"]["replicates"])]
# Top views (the paper's Figure 4): the fastest U at the omegas nearest -5, 0, +5 rad/s.
_U_MAX = max(CONFIG["sweep"]["U_mm_s"])
_OMEGAS = sorted({min(CONFIG["sweep"]["omega_rad_s"], key=lambda w: abs(w - t)) for t in (-5, 0, 5)})
TOP_VIEWS = [f"{OUT}/top_views/{run_name(_U_MAX, w, 0)}.png" for w in _OMEGAS]

wildcard_constraints:
    U=r"[0-9.e+-]+",
    omega=r"-?[0-9.e+-]+",
    rep=r"\d+",
