"""Snakemake entry: a run's final state as VTK polydata for ParaView."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.dump import read_dump  # noqa: E402
from analysis.render import write_vtk  # noqa: E402
from analysis.workflow import rule_context  # noqa: E402

with rule_context(snakemake):
    write_vtk(read_dump(snakemake.input[0]), snakemake.output[0])
