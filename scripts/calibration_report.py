"""Snakemake entry: the calibration's report page (Markdown, next to its images)."""
import json
from pathlib import Path

import pandas as pd

from analysis.calibration.calibrate import coefficient_bounds, read_checks
from analysis.calibration.report import copy_images, nearest_run, report_markdown
from analysis.rule import rule_context

with rule_context(snakemake) as config:
    out = Path(snakemake.output[0])
    solution = json.loads(Path(snakemake.input.solution).read_text())
    results = pd.read_csv(snakemake.input.results)
    bounds = coefficient_bounds(config["calibration"])
    run = nearest_run(results, list(bounds), solution["chosen"], bounds)
    images = {"surfaces": "response_surfaces.png",
              **copy_images(out.parent / "runs" / f"{run}_r0", out.parent, snakemake.params.tests)}
    checks = read_checks([Path(p) for p in snakemake.input.checks])
    out.write_text(report_markdown(solution, results, solution["responses"], checks, images, snakemake.params.level))
