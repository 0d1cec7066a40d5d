# Calibration of the virtual powder (docs/calibration.md): `snakemake calibrate` runs the
# characterisation tests (angle of repose, bulk density) over a design of contact coefficients,
# fits the surrogate, solves for the coefficients that reproduce calibration.measured, writes them
# as a config file for --configfile and a report page, and re-runs them with new seeds.
from analysis.calibration.calibrate import CalibrationError, calibration_run, check_calibration, heap_bases_mm
from analysis.calibration.calibrate import design as calibration_design
from analysis.calibration.calibrate import tests_needed as calibration_tests

CAL = "results/calibration"
CAL_CONFIG = CONFIG.get("calibration") or {}
try:
    if CAL_CONFIG:
        check_calibration(CONFIG)
except CalibrationError as err:
    raise WorkflowError(f"config.yaml: {err}") from None
CAL_DESIGN = calibration_design(CAL_CONFIG) if CAL_CONFIG else None
CAL_TESTS = calibration_tests(CAL_CONFIG) if CAL_CONFIG else []
CAL_REPLICATES = CAL_CONFIG.get("replicates", 1)
CAL_RUNS = [] if CAL_DESIGN is None else [f"{p}_r{r}" for r in range(CAL_REPLICATES) for p in CAL_DESIGN.index]
CAL_CALIBRATED = f"{CAL}/calibrated.yaml"
# the heap's bases (mm): with two or more, the angle is the large-heap limit of their size trend
CAL_HEAP_BASES = [f"{d:g}" for d in heap_bases_mm(CAL_CONFIG)] if CAL_CONFIG else []
# what a heap (besides its coefficients, seeds and base) and a cup depend on: a change re-runs them
CAL_HEAP_KEYS = ("level", "max_time_s")
CAL_CUP_KEYS = ("level", "cup_diameter_mm", "cup_height_mm", "max_time_s")
# the tests' physics (material, PSD, time step, seeds): a change re-runs them
CAL_PHYSICS = (
    simulation_fingerprint(
        CONFIG,
        CAL_CONFIG["level"],
        sections=("random_seed", "material", "psd", "rest_rms_speed_mm_s", "timestep"),
    )
    if CAL_CONFIG
    else ""
)


wildcard_constraints:
    calset=r"runs/p\d+_r\d+|check/r\d+",
    base=r"\d+(\.\d+)?",


localrules:
    calibration_angle,
    calibration_fit,
    calibration_report,
    calibrate,


rule calibration_cup:
    """The bulk-density cup of one design run or check."""
    input:
        lambda w: CAL_CALIBRATED if w.calset.startswith("check/") else [],
    output:
        f"{CAL}/{{calset}}/bulk_density/bulk_density.json",
    log:
        f"results/logs/calibration/{{calset}}_bulk_density.log",
    benchmark:
        f"results/benchmarks/calibration/{{calset}}_bulk_density.tsv"
    params:
        run=lambda w: calibration_run(CAL_DESIGN, CAL_REPLICATES, w.calset),
        physics=CAL_PHYSICS,
        calibration=lambda w: {k: CAL_CONFIG[k] for k in CAL_CUP_KEYS},
    script:
        "../scripts/calibration_test.py"


rule calibration_heap:
    """The angle-of-repose heap of one design run or check on one base."""
    input:
        lambda w: CAL_CALIBRATED if w.calset.startswith("check/") else [],
    output:
        f"{CAL}/{{calset}}/repose/d{{base}}/repose.json",
    log:
        f"results/logs/calibration/{{calset}}_repose_d{{base}}.log",
    benchmark:
        f"results/benchmarks/calibration/{{calset}}_repose_d{{base}}.tsv"
    params:
        run=lambda w: calibration_run(CAL_DESIGN, CAL_REPLICATES, w.calset),
        physics=CAL_PHYSICS,
        calibration=lambda w: {k: CAL_CONFIG[k] for k in CAL_HEAP_KEYS},
    script:
        "../scripts/calibration_test.py"


rule calibration_angle:
    """A run's angle of repose from its heaps: the large-heap limit of their size trend (one base: its angle)."""
    input:
        lambda w: expand(f"{CAL}/{w.calset}/repose/d{{base}}/repose.json", base=CAL_HEAP_BASES),
    output:
        json=f"{CAL}/{{calset}}/repose/repose.json",
        image=f"{CAL}/{{calset}}/repose/repose.png",
    log:
        f"results/logs/calibration/{{calset}}_repose.log",
    script:
        "../scripts/calibration_angle.py"


rule calibration_fit:
    """Surrogates of the tests' results over the coefficients; the coefficients that reproduce the measurements."""
    input:
        expand(f"{CAL}/runs/{{calrun}}/{{caltest}}/{{caltest}}.json", calrun=CAL_RUNS, caltest=CAL_TESTS),
    output:
        config=CAL_CALIBRATED,
        solution=f"{CAL}/solution.json",
        results=f"{CAL}/results.csv",
        surfaces=f"{CAL}/response_surfaces.png",
    log:
        "results/logs/calibration/fit.log",
    params:
        calibration=CAL_CONFIG,
        confidence=CONFIG["surrogate"]["confidence"],
        gp_restarts=CONFIG["surrogate"]["gp_restarts"],
    script:
        "../scripts/calibration_fit.py"


rule calibration_report:
    """The report page: measured and calibrated values, response surfaces, tests' images, the check."""
    input:
        solution=rules.calibration_fit.output.solution,
        results=rules.calibration_fit.output.results,
        checks=expand(
            f"{CAL}/check/r{{rep}}/{{caltest}}/{{caltest}}.json",
            rep=range(CAL_CONFIG.get("check_replicates", 0)),
            caltest=CAL_TESTS,
        ),
    output:
        f"{CAL}/report.md",
    log:
        "results/logs/calibration/report.log",
    params:
        level=CAL_CONFIG.get("level"),
        tests=CAL_TESTS,
    script:
        "../scripts/calibration_report.py"


rule calibrate:
    """Target: the calibrated coefficients (results/calibration/calibrated.yaml) and their report."""
    input:
        rules.calibration_fit.output.config,
        rules.calibration_report.output,
