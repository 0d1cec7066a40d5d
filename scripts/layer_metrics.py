"""Snakemake entry: the paper's layer metrics (eqs. 1-7) of one run, and its final state as VTK."""

from analysis.config.fidelity import scene
from analysis.config.folders import find_run
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import run_config
from analysis.io import write_json
from analysis.metrics.dump import read_dump
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units
from analysis.rule import rule_context
from analysis.viz.views import write_vtk

with rule_context(snakemake) as config:
    run = find_run(config, snakemake.wildcards.run, base_dir=PROJECT_DIR)
    s = scene(run_config(config, run), snakemake.params.level)
    frame = read_dump(snakemake.input.dump)
    metrics = spread_layer_metrics(frame, s.sampling_region, run.U * 1e-3, s.density,
                                   substrate=snakemake.input.substrate, n_lines=s.profilometer_lines,
                                   seed=config["profilometer"]["seed"])
    write_json({**run.point, "replicate": run.replicate, **to_report_units(metrics)}, snakemake.output.metrics)
    write_vtk(frame, snakemake.output.vtk)
