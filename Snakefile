# spreadmap: DEM spreading simulations (LIGGGHTS) -> layer metrics -> surrogate -> process maps.
# The method is the paper's spreading process maps (Figures 6-10); see README.md.
import time
from pathlib import Path

from snakemake.utils import min_version

# the analysis package is installed by the README's setup (pip install -e .)
from analysis.config.errors import ConfigError
from analysis.config.reading import coerce_cli_values, read_config_file

min_version("9.0")

# A YAML error in config.yaml or a --config value: one line with the file (or the argument) and
# the line and column (Snakemake's own message names neither).
try:
    if Path("config.yaml").is_file():
        read_config_file("config.yaml")
except ConfigError as err:
    raise WorkflowError(str(err)) from None


configfile: "config.yaml"


report: "report/workflow.rst"  # the report's front page


try:
    config.update(coerce_cli_values(config))  # --config values arrive as strings
except ConfigError as err:
    raise WorkflowError(str(err)) from None


# rules/common.smk checks the config once, against analysis/schemas/config.schema.yaml and across keys


include: "rules/common.smk"
include: "rules/geometry.smk"
include: "rules/simulate.smk"
include: "rules/metrics.smk"
include: "rules/surrogate.smk"
include: "rules/maps.smk"
include: "rules/calibrate.smk"


# On a cluster (profiles/slurm) only settle and spread are submitted; the rest is light.
localrules:
    all,
    geometry,
    layer_metrics,
    dataset,
    deposit_profile,
    trends,
    noise_floor,
    model_choice,
    surrogate,
    maps,
    front_page,
    top_view,
    run_parameters,


STARTED = time.time()


onsuccess:
    # one line on what the spreads cost (runs, CPU, particle-steps/s, wall time); it never raises
    from analysis.metrics.dataset import workflow_summary_line

    print(workflow_summary_line(f"{OUT}/dataset.csv", STARTED))


rule all:
    input:
        f"{OUT}/dataset.csv",
        f"{OUT}/trends.md",
        f"{OUT}/deposit_profile.png",
        f"{OUT}/surrogate/noise_floor.md",
        f"{OUT}/surrogate/model_choice.md",
        f"{OUT}/surrogate/scores.json",
        f"{OUT}/surrogate/grid.csv",
        f"{OUT}/maps",
        f"{OUT}/front_page.rst",
        expand(f"{OUT}/runs/{{run}}/final.vtp", run=RUNS),
        rules.run_parameters.output,
        TOP_VIEWS,
