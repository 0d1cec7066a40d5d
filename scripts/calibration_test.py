"""Snakemake entry: one characterisation test (a repose heap on one base, or the bulk-density cup)
of the virtual powder at a design point's coefficients, or at the calibrated ones (the check with new seeds)."""
from pathlib import Path

import yaml

from analysis.calibration.calibrate import with_coefficients
from analysis.calibration.characterise import bulk_density_test, repose_test
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    cal, run = snakemake.params.calibration, snakemake.params.run
    coefficients = run["coefficients"]
    if coefficients is None:  # a check: the calibrated config file's coefficients
        coefficients = yaml.safe_load(Path(snakemake.input[0]).read_text())["material"]
    config = with_coefficients(config, coefficients)
    out = Path(snakemake.output[0]).parent
    if snakemake.rule == "calibration_heap":
        repose_test(config, cal["level"], out, float(snakemake.wildcards.base), run["seed_index"], cal["max_time_s"])
    else:
        bulk_density_test(config, cal["level"], out, cal["cup_diameter_mm"], cal["cup_height_mm"], run["seed_index"],
                          cal["max_time_s"])
