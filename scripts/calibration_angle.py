"""Snakemake entry: a calibration run's angle of repose from its heaps on one or more bases
(the large-heap limit of their size trend), with the largest heap's side view."""
import json
import shutil
from pathlib import Path

from analysis.calibration.characterise import repose_over_sizes
from analysis.io import write_json
from analysis.rule import rule_context

with rule_context(snakemake):
    heaps = [json.loads(Path(p).read_text()) for p in snakemake.input]
    write_json(repose_over_sizes(heaps), snakemake.output.json)
    largest = max(zip(heaps, snakemake.input), key=lambda heap: heap[0]["base_diameter_mm"])[1]
    shutil.copyfile(Path(largest).parent / "repose.png", snakemake.output.image)
