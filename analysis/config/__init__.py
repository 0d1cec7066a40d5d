"""The configuration: read ``config.yaml``, check it, and derive from it what a run computes with.

One concern a module, in the order a config goes through them:

- :mod:`~analysis.config.errors`: :class:`ConfigError`, whose message names the key and the value;
- :mod:`~analysis.config.reading`: YAML as its 1.2 core schema reads it, Snakemake's ``--config``
  values, the JSON Schema; :data:`PROJECT_DIR`;
- :mod:`~analysis.config.checks`: the facts that relate two keys (physics, run bounds, sweep, maps);
- :mod:`~analysis.config.load`: :func:`load_config`, reading and both checks;
- :mod:`~analysis.config.fidelity`: the :class:`Scene` of a fidelity level, in SI units;
- :mod:`~analysis.config.sweep`: the sweep's runs (:class:`Run`), their folders and configs, the
  physics fingerprint;
- :mod:`~analysis.config.folders`: a run or a heap found by its folder name.

Import a name from the module that owns it. The names below are also re-exported here, so that
code written against the single module this package replaced keeps working while it moves.
"""
from analysis.config.checks import MAX_RUN_STEPS, check_config
from analysis.config.errors import ConfigError
from analysis.config.fidelity import PEAK_CAP, Scene, scene
from analysis.config.folders import find_heap, find_run
from analysis.config.load import load_config
from analysis.config.reading import PROJECT_DIR, coerce_cli_values, load_schema, read_config_file
from analysis.config.sweep import (
    SPEED_AXES,
    Run,
    design_points,
    heap_config,
    heaps_by_name,
    run_config,
    run_name,
    run_parameters,
    runs_at,
    runs_by_name,
    simulation_fingerprint,
    sweep_axes,
    sweep_points,
    sweep_runs,
    variant_path,
    variants,
)

__all__ = [
    "MAX_RUN_STEPS", "PEAK_CAP", "PROJECT_DIR", "SPEED_AXES", "ConfigError", "Run", "Scene", "check_config",
    "coerce_cli_values", "design_points", "find_heap", "find_run", "heap_config", "heaps_by_name", "load_config",
    "load_schema", "read_config_file", "run_config", "run_name", "run_parameters", "runs_at", "runs_by_name", "scene",
    "simulation_fingerprint", "sweep_axes", "sweep_points", "sweep_runs", "variant_path", "variants",
]
