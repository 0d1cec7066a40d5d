"""Snakemake entry: gather every run's metrics, cost and health into one CSV."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.dataset import build_dataset  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake) as config:
    build_dataset(snakemake.input.metrics, snakemake.input.health, snakemake.input.benchmarks, snakemake.output[0],
                  level=config["level"], keep_supply_limited=config["keep_supply_limited_runs"])
