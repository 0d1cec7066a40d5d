"""Snakemake entry: the paper's layer metrics (eqs. 1-7) of one run, and its final state as VTK."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(snakemake.scriptdir).parent))
from analysis.config import scene  # noqa: E402
from analysis.dump import read_dump  # noqa: E402
from analysis.layer_metrics import spread_layer_metrics, to_report_units  # noqa: E402
from analysis.render import write_vtk  # noqa: E402
from analysis.workflow import rule_context, write_json  # noqa: E402

with rule_context(snakemake) as config:
    s = scene(config, snakemake.params.level)
    U = float(snakemake.wildcards.U)
    frame = read_dump(snakemake.input.dump)
    metrics = spread_layer_metrics(frame, s.sampling_region, U * 1e-3, s.density,
                                   substrate=snakemake.input.substrate, n_lines=s.profilometer_lines,
                                   seed=config["profilometer"]["seed"])
    write_json({"U_mm_s": U, "omega_rad_s": float(snakemake.wildcards.omega),
                "replicate": int(snakemake.wildcards.rep), **to_report_units(metrics)}, snakemake.output.metrics)
    write_vtk(frame, snakemake.output.vtk)
