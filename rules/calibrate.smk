# Calibration of the virtual powder (docs/calibration.md): `snakemake calibrate` runs the
# characterisation tests (angle of repose, bulk density) over a design of contact coefficients,
# fits the surrogate, solves for the coefficients that reproduce calibration.measured, writes them
# as a config file for --configfile and a report page, and re-runs them with new seeds.
from analysis.calibration.calibrate import CalibrationError, check_calibration, design_run
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
# what a test run depends on besides its coefficients and seeds: a change re-runs it
CAL_TEST_KEYS = ("level", "repose_base_diameter_mm", "cup_diameter_mm", "cup_height_mm", "max_time_s")
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
    calrun=r"p\d+_r\d+",
    caltest="repose|bulk_density",
    check=r"r\d+",


localrules:
    calibration_fit,
    calibration_report,
    calibrate,


rule calibration_test:
    """One characterisation test (repose heap or bulk-density cup) at one design point and replicate."""
    output:
        f"{CAL}/runs/{{calrun}}/{{caltest}}/{{caltest}}.json",
    log:
        f"results/logs/calibration/{{calrun}}_{{caltest}}.log",
    benchmark:
        f"results/benchmarks/calibration/{{calrun}}_{{caltest}}.tsv"
    params:
        run=lambda w: design_run(CAL_DESIGN, w.calrun),
        physics=CAL_PHYSICS,
        calibration=lambda w: {k: CAL_CONFIG[k] for k in CAL_TEST_KEYS},
    script:
        "../scripts/calibration_test.py"


rule calibration_fit:
    """Surrogates of the tests' results over the coefficients; the coefficients that reproduce the measurements."""
    input:
        expand(f"{CAL}/runs/{{calrun}}/{{caltest}}/{{caltest}}.json", calrun=CAL_RUNS, caltest=CAL_TESTS),
    output:
        config=f"{CAL}/calibrated.yaml",
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


rule calibration_check:
    """One characterisation test at the calibrated coefficients with new seeds."""
    input:
        calibrated=rules.calibration_fit.output.config,
    output:
        f"{CAL}/check/{{check}}/{{caltest}}/{{caltest}}.json",
    log:
        f"results/logs/calibration/check_{{check}}_{{caltest}}.log",
    params:
        run=lambda w: {
            "coefficients": None,
            "seed_index": CAL_REPLICATES * len(CAL_DESIGN) + int(w.check[1:]),
        },
        physics=CAL_PHYSICS,
        calibration=lambda w: {k: CAL_CONFIG[k] for k in CAL_TEST_KEYS},
    script:
        "../scripts/calibration_test.py"


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
