"""Load and check ``config.yaml``; derive the scene of one fidelity level in SI units.

The configuration is checked twice: by its JSON Schema (types, ranges, unknown
keys) and by :func:`check_config` (facts that relate two keys). Both raise
:class:`ConfigError` with the dotted key and the offending value, before any
simulation starts.
"""
from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass
from math import sqrt
from pathlib import Path

import jsonschema
import numpy as np
import yaml

from analysis.physics import (
    INSERTION_SOLID_FRACTION,
    feed_length,
    number_mean_volume,
    polygon_bottom_range,
    psd_classes,
    rayleigh_time,
)

#: The project folder: config.yaml, templates/, Snakefile (the package is installed in place).
PROJECT_DIR = Path(__file__).resolve().parents[1]
SCHEMA_PATH = Path(__file__).with_name("schemas") / "config.schema.yaml"


class ConfigError(ValueError):
    """A configuration value is wrong; the message names its key and value."""


class StrictLoader(yaml.SafeLoader):
    """YAML as its 1.2 core schema reads it: ``true``/``false`` are the only booleans (``yes``,
    ``on``, ``y`` stay strings, which the schema then refuses where a boolean is wanted), and
    ``1e9`` is a number (YAML 1.1 wants ``1.0e+9``)."""


StrictLoader.yaml_implicit_resolvers = {
    first: [(tag, regex) for tag, regex in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
StrictLoader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                                   list("tTfF"))
StrictLoader.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$"),
                                   list("-+0123456789"))


def parse_yaml(text: str, source: str):
    """``text`` parsed by :class:`StrictLoader`; a syntax error is one :class:`ConfigError` line
    naming ``source`` (a file, or a ``--config`` argument) and the line and column."""
    try:
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = " ".join(str(getattr(err, "problem", None) or err).split())
        raise ConfigError(f"{source}: YAML syntax error{where}: {what}") from None


def coerce_cli_values(value, key: str = ""):
    """Numbers, booleans and nulls from strings, recursively.

    Snakemake parses nested ``--config key='{...}'`` values with YAML's
    BaseLoader, which leaves every scalar a string; this restores the types
    so that ``--config sweep='{"U_mm_s": [40, 70]}'`` works. A value that is
    not YAML raises :class:`ConfigError` naming ``--config <key>=<value>``.
    """
    if isinstance(value, dict):
        return {k: coerce_cli_values(v, f"{key}.{k}" if key else str(k)) for k, v in value.items()}
    if isinstance(value, list):
        return [coerce_cli_values(v, key) for v in value]
    if isinstance(value, str):
        return parse_yaml(value, f"--config {key}={value}".replace("\n", "\\n")) if value.strip() else value
    return value


@functools.cache
def load_schema() -> dict:
    """The config's JSON Schema (read once; not to be changed in place)."""
    return yaml.safe_load(SCHEMA_PATH.read_text())


def load_config(source: str | Path | dict, base_dir: str | Path | None = None) -> dict:
    """Read (if a path), validate and return the configuration.

    Parameters
    ----------
    source : path or dict
        ``config.yaml`` or an already-parsed mapping (e.g. Snakemake's ``config``).
    base_dir : path, optional
        Folder that a relative ``substrate.mesh`` is resolved against; defaults to
        the config file's folder, or the working directory for a mapping.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        if not path.is_file():
            raise ConfigError(f"config file {str(path)!r} does not exist")
        config = read_config_file(path)
        base_dir = path.parent if base_dir is None else base_dir
    else:
        config = copy.deepcopy(source)
    check_finite(config)
    validate_schema(config)
    check_config(config, Path(base_dir or "."))
    return config


def read_config_file(path: str | Path) -> dict:
    """The mapping in a YAML config file; an empty file, a syntax error or a top level that is
    not a mapping raises one :class:`ConfigError` line naming the file (and the line, column)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a YAML text file ({err.reason} at byte {err.start})") from None
    config = parse_yaml(text, str(path))
    if not isinstance(config, dict):
        raise ConfigError(f"{path}: " + ("empty: no config keys" if config is None else
                                         f"holds a {type(config).__name__}, not a mapping of config keys"))
    return config


def check_finite(config, key: str = "") -> None:
    """Raise :class:`ConfigError` naming the first NaN or infinite number in ``config``.

    JSON Schema cannot say "finite": NaN fails no ``minimum`` and infinity passes
    every ``minimum``, so this walks the mapping before the schema does.
    """
    if isinstance(config, dict):
        for k, v in config.items():
            check_finite(v, f"{key}.{k}" if key else str(k))
    elif isinstance(config, list):
        for i, v in enumerate(config):
            check_finite(v, f"{key}[{i}]")
    elif isinstance(config, float) and not math.isfinite(config):
        _fail(key or "<top level>", config, "must be a finite number")


#: JSON Schema counts 2.0 as an integer; a count or a seed written 2.0 is refused instead
#: (``range(2.0)`` and a seed of '11027.0' fail later, far from the key).
_Validator = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine(
        "integer", lambda _, value: isinstance(value, int) and not isinstance(value, bool)))


@functools.cache
def _validator():
    return _Validator(load_schema())


def _non_text_key(node, path=()):
    """The dotted path of the first mapping key that is not text (YAML's ``null:``, ``1:``), or None."""
    if isinstance(node, dict):
        for key, value in node.items():
            if not isinstance(key, str):
                return ".".join([*path, repr(key)])
            found = _non_text_key(value, (*path, key))
            if found:
                return found
    elif isinstance(node, list):
        for item in node:
            found = _non_text_key(item, path)
            if found:
                return found
    return None


def validate_schema(config: dict) -> None:
    """Raise :class:`ConfigError` on the first schema violation, naming key and value."""
    bad = _non_text_key(config)
    if bad:
        raise ConfigError(f"config key {bad!r}: a key must be a name (text), e.g. U_mm_s")
    validator = _validator()
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if errors:
        error = errors[0]
        key = ".".join(str(p) for p in error.absolute_path) or "<top level>"
        raise ConfigError(f"config key {key!r}: {error.message} (value: {error.instance!r})")


def _fail(key: str, value, why: str):
    raise ConfigError(f"config key {key!r} = {value!r}: {why}")


def check_config(config: dict, base_dir: Path = Path(".")) -> None:
    """Cross-key checks the schema cannot express, then the sweep's (:func:`check_sweep`)."""
    check_physics(config, base_dir)
    check_sweep(config, base_dir)
    check_maps(config)


def check_maps(config: dict) -> None:
    """``maps`` names inputs of the sweep (U_mm_s, omega_rad_s, its extra axes): two to span,
    others to hold inside their swept range, one other for the panels."""
    maps, points = config["maps"], sweep_points(config)
    inputs = [*SPEED_AXES, *sweep_axes(config)]
    known = f"the sweep's inputs are {', '.join(inputs)}"
    for axis in maps["axes"]:
        if axis not in inputs:
            _fail("maps.axes", maps["axes"], f"names {axis!r}, not an input: {known}")
    for name, value in maps["hold"].items():
        if name not in inputs or name in maps["axes"]:
            _fail(f"maps.hold.{name}", value, f"holds what is not an input outside maps.axes: {known}")
        lo, hi = min(p[name] for p in points), max(p[name] for p in points)
        if not lo <= value <= hi:
            _fail(f"maps.hold.{name}", value, f"lies outside the swept range {lo:g}..{hi:g}")
    panels = maps["panels"]
    if panels is not None and (panels not in inputs or panels in maps["axes"] or panels in maps["hold"]):
        _fail("maps.panels", panels, f"must be an input neither mapped (maps.axes) nor held (maps.hold): {known}")


def check_physics(config: dict, base_dir: Path = Path(".")) -> None:
    """Cross-key checks of the physics, scene and fidelity sections (one set of values)."""
    level = config["level"]
    if level not in config["fidelity"]:
        _fail("level", level, f"no such fidelity level; choose one of {sorted(config['fidelity'])}")
    psd = config["psd"]
    if psd["min_diameter_um"] >= psd["max_diameter_um"]:
        _fail("psd.min_diameter_um", psd["min_diameter_um"],
              f"must be below psd.max_diameter_um = {psd['max_diameter_um']}")
    if not psd["min_diameter_um"] <= psd["mean_diameter_um"] <= psd["max_diameter_um"]:
        _fail("psd.mean_diameter_um", psd["mean_diameter_um"], "must lie between the min and max diameters")
    far = max(("min_diameter_um", "max_diameter_um"),
              key=lambda k: abs(psd[k] - psd["mean_diameter_um"]) / psd["std_diameter_um"])
    for name, lvl in config["fidelity"].items():
        d, w = psd_classes(psd["mean_diameter_um"], psd["std_diameter_um"], psd["min_diameter_um"],
                           psd["max_diameter_um"], lvl["size_classes"])
        if not (np.isfinite(d).all() and (w > 1e-9).all()):
            _fail(f"psd.{far}", psd[far], f"leaves a size class of fidelity.{name} ({lvl['size_classes']} classes) "
                  f"with no particles of the Gaussian (mean {psd['mean_diameter_um']}, sd {psd['std_diameter_um']} "
                  "um): bring the range within a few sds of the mean, or use fewer size_classes")
    gap = config["roller"]["gap_um"]
    if gap < psd["min_diameter_um"]:
        _fail("roller.gap_um", gap, f"is below the smallest particle diameter ({psd['min_diameter_um']} um)")
    step = config["timestep"]
    if step["rayleigh_fraction"] > step["max_rayleigh_fraction"]:
        _fail("timestep.rayleigh_fraction", step["rayleigh_fraction"],
              f"exceeds timestep.max_rayleigh_fraction = {step['max_rayleigh_fraction']}")
    mesh = config["substrate"]["mesh"]
    if mesh is not None and not (base_dir / mesh).is_file():
        _fail("substrate.mesh", mesh, "file not found")
    for name, lvl in config["fidelity"].items():
        width = lvl.get("sampling_width_mm", lvl["strip_width_mm"])
        if width > lvl["strip_width_mm"]:
            _fail(f"fidelity.{name}.sampling_width_mm", width,
                  f"exceeds the strip width {lvl['strip_width_mm']} mm")
        pile = lvl.get("feed_pile_mg_per_mm")
        if pile is not None:
            try:
                feed_length(pile * 1e-3, config["material"]["density_kg_m3"], config["roller"]["diameter_mm"] / 2e3,
                            config["roller"]["gap_um"] * 1e-6)
            except ValueError as err:
                _fail(f"fidelity.{name}.feed_pile_mg_per_mm", pile,
                      f"{err} mg/mm at material.density_kg_m3 = {config['material']['density_kg_m3']!r}, "
                      f"roller.diameter_mm = {config['roller']['diameter_mm']!r} and "
                      f"roller.gap_um = {config['roller']['gap_um']!r}")
        if lvl["sampling_start_mm"] < lvl.get("heap_start_mm", 0) + lvl["heap_length_mm"]:
            _fail(f"fidelity.{name}.sampling_start_mm", lvl["sampling_start_mm"],
                  f"starts inside the heap (heap_length_mm = {lvl['heap_length_mm']})")
    check_bounds(config)


#: The most time steps one LIGGGHTS ``run`` command takes (a signed 32-bit count):
#: beyond it LIGGGHTS stops with "Invalid run command".
MAX_RUN_STEPS = 2**31 - 1

#: Nodes of the generated rough substrate at most (its random field and mesh: about 1 kB a node).
MAX_SUBSTRATE_NODES = 10_000_000

#: The roller's surface moves at most this fraction of the smallest particle's radius in a time step.
MAX_WALL_STEP = 0.1


def check_bounds(config: dict) -> None:
    """Bounds that hold between keys: each level's settle and rest fit LIGGGHTS' run command
    (:data:`MAX_RUN_STEPS`) and its generated substrate the memory (:data:`MAX_SUBSTRATE_NODES`)."""
    fraction = config["timestep"]["rayleigh_fraction"]
    for name, lvl in config["fidelity"].items():
        s = scene(config, name)
        for key in ("settle_time_s", "rest_time_s"):
            steps = lvl[key] / s.timestep
            if steps > MAX_RUN_STEPS:
                _fail(f"fidelity.{name}.{key}", lvl[key],
                      f"takes {steps:.3g} time steps of {s.timestep:.3g} s (timestep.rayleigh_fraction = {fraction!r}):"
                      f" at most {MAX_RUN_STEPS} fit a LIGGGHTS run")
        if config["substrate"]["mesh"] is None:
            spacing = config["substrate"]["grid_spacing_um"] * 1e-6
            nodes = ((s.rough_x[1] - s.rough_x[0] + 1e-3) / spacing + 1) * (s.strip_width / spacing + 1)
            if nodes > MAX_SUBSTRATE_NODES:
                _fail("substrate.grid_spacing_um", config["substrate"]["grid_spacing_um"],
                      f"gives fidelity.{name}'s rough substrate {nodes:.3g} nodes: at most {MAX_SUBSTRATE_NODES:.0e}"
                      " (memory)")


def check_sweep(config: dict, base_dir: Path = Path(".")) -> None:
    """The sweep's own checks: its axes name sweepable keys (:func:`check_axis_key`), each
    value of an axis and each combination of the swept values passes the schema and
    :func:`check_physics` as if written in its place, a gap reuses the heap settled
    under ``roller.gap_um`` only where it fits, and run folders are unique.

    A bad swept value raises :class:`ConfigError` naming ``sweep.<axis>`` and the value."""
    sweep, axes = config["sweep"], sweep_axes(config)
    for axis in axes:
        check_axis_key(config, axis)
    if sweep.get("points") and sweep.get("points_mm_s_rad_s"):
        _fail("sweep.points", "...", "and sweep.points_mm_s_rad_s are both given: keep one")
    if axes and sweep.get("points_mm_s_rad_s"):
        _fail("sweep.points_mm_s_rad_s", sweep["points_mm_s_rad_s"],
              f"gives (U, omega) only, but the sweep also has {', '.join(axes)}: list the points "
              "over all axes in sweep.points")
    for i, point in enumerate(sweep.get("points") or []):
        if set(point) != {*SPEED_AXES, *axes}:
            _fail(f"sweep.points[{i}]", point, f"must name exactly {', '.join([*SPEED_AXES, *axes])}"
                  + ("" if axes else " (list an extra axis' values in sweep as well: its range)"))
    run = variants(config)
    for axis in axes:                       # each value alone (listed or in sweep.points): the message names it
        labels = {f"{config_value(config, axis):g}": config_value(config, axis)}
        for value in dict.fromkeys([*sweep[axis], *(v[axis] for v in run)]):
            _check_variant(config, {axis: value}, base_dir, f"sweep.{axis}", value)
            other = labels.setdefault(f"{value:g}", value)
            if other != value:
                _fail(f"sweep.{axis}", value, f"has the folder name {axis}={value:g} of {other!r} (the config's "
                      "own value, or another listed one): sweep values that differ in their first 6 digits")
    for values in run:                      # and every combination run (cross-key facts between axes)
        if len(values) > 1:
            _check_variant(config, values, base_dir, "sweep", values)
    for value in dict.fromkeys([*sweep.get("roller.gap_um", []), *(v["roller.gap_um"] for v in run
                                                                    if "roller.gap_um" in v)]):
        check_swept_gap(config, value)
    runs = sweep_runs(config)
    names = [run.name for run in runs]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        key = "sweep.points" if sweep.get("points") else "sweep.points_mm_s_rad_s" \
            if sweep.get("points_mm_s_rad_s") else "sweep"
        _fail(key, sweep.get(key.split(".", 1)[-1]) if key != "sweep" else axes,
              f"lists the same run folder twice: {', '.join(repeated[:3])}")
    n_points = len(sweep_points(config))
    if config["surrogate"]["n_test"] > n_points - 3:
        _fail("surrogate.n_test", config["surrogate"]["n_test"],
              f"leaves fewer than 3 of the sweep's {n_points} points to train on")
    if config["surrogate"]["cv_folds"] > n_points:
        _fail("surrogate.cv_folds", config["surrogate"]["cv_folds"],
              f"exceeds the sweep's {n_points} points (each fold holds out whole points)")
    check_speeds(config)


def check_speeds(config: dict) -> None:
    """Each run's speeds against its time step: the slowest travel fits a LIGGGHTS run
    (:data:`MAX_RUN_STEPS`), the roller's surface moves less than :data:`MAX_WALL_STEP` of the
    smallest radius a step."""
    for values in variants(config):
        s = scene(resolve(config, values))
        points = [p for p in sweep_points(config) if all(p[k] == v for k, v in values.items())]
        slowest = min(points, key=lambda p: p["U_mm_s"])
        steps = (s.travel_end - s.box[0]) / (slowest["U_mm_s"] * 1e-3) / s.timestep
        if steps > MAX_RUN_STEPS:
            _fail("sweep.U_mm_s", slowest["U_mm_s"], f"needs {steps:.3g} time steps of {s.timestep:.3g} s to travel "
                  f"{(s.travel_end - s.box[0]) * 1e3:.3g} mm (from behind the heap, fidelity.{s.level}.heap_start_mm, "
                  f"heap_length_mm and heap_particles, to the end of fidelity.{s.level}.sampling_start_mm + "
                  f"sampling_length_mm + run_out_mm; the step is timestep.rayleigh_fraction of the Rayleigh time of "
                  f"material.youngs_modulus_dem_Pa): at most {MAX_RUN_STEPS} fit a LIGGGHTS run")
        r_min = min(s.diameters) / 2
        for p in points:
            wall = (p["U_mm_s"] * 1e-3 + abs(p["omega_rad_s"]) * s.roller_radius) * s.timestep
            if wall > MAX_WALL_STEP * r_min:
                key = "sweep.U_mm_s" if p["U_mm_s"] * 1e-3 >= abs(p["omega_rad_s"]) * s.roller_radius \
                    else "sweep.omega_rad_s"
                _fail(key, p[key.split(".")[1]],
                      f"moves the roller's surface {wall * 1e6:.3g} um a time step of {s.timestep:.3g} s (U = "
                      f"{p['U_mm_s']:g} mm/s, omega = {p['omega_rad_s']:g} rad/s): more than {MAX_WALL_STEP:g} of the "
                      f"smallest radius ({r_min * 1e6:.3g} um); lower the speeds or the time step "
                      "(timestep.rayleigh_fraction of the Rayleigh time set by material.youngs_modulus_dem_Pa, "
                      "density_kg_m3 and psd.min_diameter_um)")


def check_swept_gap(config: dict, value: float) -> None:
    """A swept gap spreads the heap settled under ``roller.gap_um``: at least that gap, and in its box."""
    gap = config["roller"]["gap_um"]
    if value < gap:
        _fail("sweep.roller.gap_um", value,
              f"is below roller.gap_um = {gap!r}, the gap the heap is settled and the substrate's peaks "
              f"are capped under (at {PEAK_CAP:g} x) for every swept gap: set roller.gap_um to the "
              "smallest swept gap")
    spread, heap_box = scene(resolve(config, {"roller.gap_um": value})), scene(config).box
    if spread.box[1] > heap_box[1] or spread.roller_gap + 2 * spread.roller_radius > heap_box[5]:
        _fail("sweep.roller.gap_um", value,
              f"puts the roller or its feed outside the simulation box of the heap settled at "
              f"roller.gap_um = {gap!r} (the spread starts from its restart): sweep gaps closer to it")


def _check_variant(config: dict, values: dict, base_dir: Path, key: str, shown) -> None:
    """Schema and :func:`check_physics` on ``config`` with ``values`` in place; a failure
    names ``key`` = ``shown`` and what is wrong, in one line."""
    resolved = resolve(config, values)
    resolved["sweep"] = {k: v for k, v in resolved["sweep"].items() if k not in values}
    try:
        check_finite(resolved)
        validate_schema(resolved)
        check_physics(resolved, base_dir)
    except ConfigError as err:
        where = "in its place" if len(values) == 1 else "in that combination"
        raise ConfigError(f"config key {key!r} = {shown!r}: {where}, {err}") from None


#: The sweep's keys that are not extra axes.
SWEEP_KEYS = ("U_mm_s", "omega_rad_s", "replicates", "points_mm_s_rad_s", "points")

#: The spreader's speeds: the two axes of every sweep (mm/s, rad/s).
SPEED_AXES = ("U_mm_s", "omega_rad_s")

#: Swept keys that the heap and the substrate do not depend on: their values share the
#: settle (and geometry) of the config's own value. Every other axis settles its own heap.
SPREAD_ONLY_AXES = ("roller.gap_um",)

#: The generated substrate's peaks are clipped at this fraction of ``roller.gap_um``
#: (3.4 Sq at the configured 300 um gap and Sq 79 um): otherwise the paper
#: level's large field puts a node through the roller.
PEAK_CAP = 0.9


def sweep_axes(config: dict) -> list[str]:
    """The sweep's extra axes: config keys by dotted path (``roller.gap_um``), in the order written."""
    return [k for k in config["sweep"] if k not in SWEEP_KEYS]


def check_axis_key(config: dict, axis: str) -> None:
    """Raise :class:`ConfigError` unless ``axis`` is a numeric key a simulation computes with:
    a key of ``material``, ``psd``, ``roller``, ``substrate`` or ``timestep``, or of the running
    fidelity level but its execution keys; not a seed (``sweep.replicates`` varies those)."""
    *path, last = axis.split(".")
    level = config["level"]
    if not path:
        _fail(f"sweep.{axis}", config["sweep"][axis],
              f"is not a sweep key; sweep other config keys by their dotted path, e.g. roller.gap_um "
              f"(the sweep's own keys: {', '.join(SWEEP_KEYS)})")
    section = path[0]
    allowed = section in ("material", "psd", "roller", "substrate", "timestep") and len(path) == 1 or \
        section == "fidelity" and len(path) == 2 and path[1] == level and last not in EXECUTION_KEYS
    node = config_value(config, axis)
    numeric = isinstance(node, (int, float)) and not isinstance(node, bool)
    if not allowed or not numeric or last.endswith("seed"):
        why = ("is a seed: sweep.replicates varies the seeds" if last.endswith("seed") else
               f"names fidelity level {path[1]!r}, but level is {level!r}"
               if section == "fidelity" and len(path) == 2 and path[1] != level else
               "is not a numeric config key a simulation computes with (material, psd, roller, substrate, "
               f"timestep, or fidelity.{level} but its execution keys)")
        _fail(f"sweep.{axis}", config["sweep"][axis], why)


def config_value(config: dict, key: str):
    """The config's value at a dotted key (``roller.gap_um``); None where there is none."""
    node = config
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def resolve(config: dict, values: dict) -> dict:
    """A copy of ``config`` with each dotted key of ``values`` set to its value
    (the speeds, ``U_mm_s`` and ``omega_rad_s``, are not config keys and are left out)."""
    out = copy.deepcopy(config)
    for key, value in values.items():
        if key in SPEED_AXES:
            continue
        *path, last = key.split(".")
        node = out
        for k in path:
            node = node[k]
        if isinstance(node[last], int) and not isinstance(node[last], bool) and float(value).is_integer():
            value = int(value)      # a swept count stays an integer (the sweep reads its values as floats)
        if node[last] != value:     # the config's own value keeps its type (300, not 300.0): same fingerprint
            node[last] = value
    return out


#: Fidelity keys that say how a run is executed, not what it computes.
EXECUTION_KEYS = ("mpi_ranks", "runtime_min", "mem_mb_per_rank", "checkpoints_per_run", "profilometer_lines")


#: Top-level sections whose values a settle or spread computes with.
SIMULATION_SECTIONS = ("random_seed", "material", "psd", "roller", "substrate", "rest_rms_speed_mm_s", "timestep")


def simulation_fingerprint(config: dict, level: str, sections=SIMULATION_SECTIONS,
                           base_dir: str | Path = ".") -> str:
    """A short hash of everything in ``config`` that a simulation of ``level``
    computes with (``sections`` and the level's fidelity keys but
    EXECUTION_KEYS), a user's ``substrate.mesh`` (relative to ``base_dir``) by its content.
    The workflow passes it as a rule parameter, so that
    Snakemake re-runs the simulations when the physics changes (and not when
    only the MPI ranks or the cluster limits do)."""
    relevant = {key: config.get(key) for key in sections}
    relevant["fidelity"] = {k: v for k, v in config["fidelity"][level].items() if k not in EXECUTION_KEYS}
    mesh = config["substrate"]["mesh"] if "substrate" in sections else None
    if mesh is not None:
        relevant["substrate_mesh_sha256"] = file_digest(Path(base_dir) / mesh)
    return hashlib.sha256(json.dumps(relevant, sort_keys=True, default=str).encode()).hexdigest()[:16]


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's content (cached by path, size and modification time); '' if it is missing."""
    path = Path(path).resolve()
    try:
        stat = path.stat()
    except OSError:
        return ""
    return _digest(path, stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _digest(path: Path, size: int, mtime_ns: int) -> str:
    sha = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            sha.update(block)
    return sha.hexdigest()


def run_name(U: float, omega: float, replicate: int) -> str:
    """Folder name of one run: U in mm/s, omega in rad/s, replicate index (``U70_w-2.5_r0``)."""
    return f"U{U:g}_w{omega:g}_r{replicate}"


def variant_path(values: dict) -> str:
    """Folders of the extra axes' values, outer first: ``roller.gap_um=200/`` ('' for none)."""
    return "".join(f"{k}={v:g}/" for k, v in values.items())


def design_points(config: dict) -> list[tuple[float, float]]:
    """The sweep's distinct (U [mm/s], omega [rad/s]) points, in order of first appearance:
    ``sweep.points_mm_s_rad_s`` or ``sweep.points`` if given, else the grid ``U_mm_s x omega_rad_s``
    (U outer)."""
    return list(dict.fromkeys((p["U_mm_s"], p["omega_rad_s"]) for p in sweep_points(config)))


def sweep_points(config: dict) -> list[dict]:
    """Every point of the sweep over all its axes: ``{"U_mm_s": U, "omega_rad_s": omega,
    <axis>: value, ...}`` (mm/s, rad/s, the axes' config units). ``sweep.points`` or
    ``sweep.points_mm_s_rad_s`` if given, else the full grid: U outer, then omega, then
    the extra axes (:func:`sweep_axes`) in the order written."""
    sweep, axes = config["sweep"], sweep_axes(config)
    if sweep.get("points_mm_s_rad_s"):
        return [{"U_mm_s": float(U), "omega_rad_s": float(w)} for U, w in sweep["points_mm_s_rad_s"]]
    if sweep.get("points"):
        return [{k: float(p[k]) for k in (*SPEED_AXES, *axes)} for p in sweep["points"]]
    grids = [sweep[k] for k in (*SPEED_AXES, *axes)]
    return [dict(zip((*SPEED_AXES, *axes), map(float, combo))) for combo in itertools.product(*grids)]


def variants(config: dict) -> list[dict]:
    """The distinct combinations of the extra axes' values the sweep runs (``[{}]`` for none)."""
    axes = sweep_axes(config)
    seen = {tuple(p[a] for a in axes): None for p in sweep_points(config)}
    return [dict(zip(axes, combo)) for combo in seen]


@dataclass(frozen=True)
class Run:
    """One run of the sweep: its speeds, replicate and extra axes' values, and where it lives.

    A value equal to the config's own (``own``) is left out of the folder names, so a run at the
    config's values of every extra axis is the plain (U, omega) run: adding an axis to a finished
    study reuses its runs and heaps (their physics fingerprints guard the reuse)."""
    U: float                # mm/s
    omega: float            # rad/s
    replicate: int
    values: tuple           # ((axis, value), ...) of the extra axes, in sweep order
    own: tuple = ()         # ((axis, the config's own value), ...)

    def _folders(self, values: dict) -> str:
        return variant_path({k: v for k, v in values.items() if (k, v) not in self.own})

    @property
    def name(self) -> str:
        """Its folder under ``runs/``: ``U70_w-10_r0``, or ``roller.gap_um=400/U70_w-10_r0``."""
        return self._folders(dict(self.values)) + run_name(self.U, self.omega, self.replicate)

    @property
    def heap(self) -> str:
        """Its heap's (geometry's and settle's) folder: ``r0``, or the values of the axes the heap
        depends on (all but :data:`SPREAD_ONLY_AXES`) before it: ``psd.mean_diameter_um=150/r0``."""
        return self._folders(self.heap_values) + f"r{self.replicate}"

    @property
    def heap_values(self) -> dict:
        """The extra axes' values its heap and substrate depend on."""
        return {k: v for k, v in self.values if k not in SPREAD_ONLY_AXES}

    @property
    def point(self) -> dict:
        """``{"U_mm_s": U, "omega_rad_s": omega, <axis>: value, ...}``."""
        return {"U_mm_s": self.U, "omega_rad_s": self.omega, **dict(self.values)}


def sweep_runs(config: dict) -> list[Run]:
    """Every run: each point of :func:`sweep_points` times ``sweep.replicates``."""
    axes = sweep_axes(config)
    own = tuple((a, config_value(config, a)) for a in axes)
    return [Run(p["U_mm_s"], p["omega_rad_s"], r, tuple((a, p[a]) for a in axes), own)
            for p in sweep_points(config) for r in range(config["sweep"]["replicates"])]


def runs_at(config: dict, points) -> list[Run]:
    """The runs of :func:`sweep_runs` at ``points``: every replicate of each, in the order of ``points``.

    Parameters
    ----------
    config : dict
        A loaded config whose sweep runs the points.
    points : iterable of dict
        ``{"U_mm_s": U, "omega_rad_s": omega, <axis>: value, ...}`` over every axis of the sweep
        (mm/s, rad/s, the axes' config units), as :func:`sweep_points` gives them; matched to
        6 decimals.

    Raises
    ------
    KeyError
        A point the sweep does not run (named).
    """
    inputs = (*SPEED_AXES, *sweep_axes(config))

    def key(point):
        return tuple(round(float(point[a]), 6) for a in inputs)

    table = {}
    for run in sweep_runs(config):
        table.setdefault(key(run.point), []).append(run)
    runs = []
    for point in points:
        if key(point) not in table:
            raise KeyError(f"the sweep does not run the point {point}")
        runs += table[key(point)]
    return runs


def run_config(config: dict, run: Run) -> dict:
    """``config`` with the run's extra axes' values in place: what its spread computes with."""
    return resolve(config, dict(run.values))


def heap_config(config: dict, run: Run) -> dict:
    """``config`` with the values its heap depends on in place: what its geometry and settle compute with
    (a spread-only axis, e.g. the gap, keeps the config's own value)."""
    return resolve(config, run.heap_values)


def run_parameters(config: dict, run: Run, base_dir: str | Path = ".") -> dict:
    """Everything a run computes with, resolved (its extra axes' values in place), JSON/YAML-ready:
    ``run`` (folder), ``U_mm_s``, ``omega_rad_s``, ``replicate``, ``swept`` (the extra axes'
    values), ``heap`` (its settle's folder), ``level``, ``roller_gap`` (the gap as built, um),
    ``physics`` (the fingerprint Snakemake re-runs on), and ``config``: the sections of
    :data:`SIMULATION_SECTIONS`, ``profilometer`` and the level's ``fidelity`` keys."""
    resolved, level = run_config(config, run), config["level"]
    roller = resolved["roller"]
    near, far = polygon_bottom_range(roller["diameter_mm"] / 2, roller["facets_around"])
    radius_mm, gap_um, mm_to_um = roller["diameter_mm"] / 2, roller["gap_um"], 1e3
    gap = {"datum": "the substrate's mean plane under the sampling region", "mean_over_a_turn_um": gap_um,
           "still_roller_um": gap_um, "min_um": gap_um - (far - radius_mm) * mm_to_um,
           "max_um": gap_um + (radius_mm - near) * mm_to_um}
    return {"run": run.name, "U_mm_s": run.U, "omega_rad_s": run.omega, "replicate": run.replicate,
            "swept": dict(run.values), "heap": run.heap, "level": level, "roller_gap": gap,
            "physics": simulation_fingerprint(resolved, level, base_dir=base_dir),
            "config": {**{k: resolved[k] for k in (*SIMULATION_SECTIONS, "profilometer")},
                       "fidelity": {level: resolved["fidelity"][level]}}}


def runs_by_name(config: dict) -> dict[str, Run]:
    """:func:`sweep_runs` by folder name (``Run.name``)."""
    return {run.name: run for run in sweep_runs(config)}


_AXIS_FOLDER = re.compile(r"([A-Za-z_][A-Za-z0-9_.]*)=([^/]+)")
_RUN_FOLDER = re.compile(r"U([^_/]+)_w([^_/]+)_r(\d+)")


def find_run(config: dict, name: str, table: dict | None = None, base_dir: str | Path = ".") -> Run:
    """The run of folder ``name`` (its path under ``runs/``): the sweep's (``table``, default
    :func:`runs_by_name`), or a point outside the sweep named by its folder, e.g.
    ``U100_w-7_r0`` or ``roller.gap_um=350/U70_w-5_r1``: its speeds, replicate and the extra axes'
    values, each checked as a swept one is (the axes not named take the config's own values).

    Raises :class:`ConfigError` naming the folder and what is wrong with it, in one line."""
    table = runs_by_name(config) if table is None else table
    if name in table:
        return table[name]
    *folders, leaf = name.split("/")
    match = _RUN_FOLDER.fullmatch(leaf)
    if not match:
        raise ConfigError(f"run folder {name!r}: not a run's folder name, U<mm/s>_w<rad/s>_r<replicate> "
                          "(e.g. U70_w-5_r0), after a folder <axis>=<value>/ for each extra sweep axis")
    U, omega = (_folder_number(name, key, text) for key, text in (("U_mm_s", match[1]), ("omega_rad_s", match[2])))
    values = _folder_values(config, name, folders, SPEED_AXES)
    trial = copy.deepcopy(config)
    trial["sweep"] = {"U_mm_s": [U], "omega_rad_s": [omega], "replicates": int(match[3]) + 1,
                      **{axis: [value] for axis, value in values.items()}}
    try:
        check_finite(trial["sweep"], "sweep")
        validate_schema(trial)
        if values:
            _check_variant(config, values, Path(base_dir), "sweep", values)
        if "roller.gap_um" in values:
            check_swept_gap(config, values["roller.gap_um"])
        check_speeds(trial)
    except ConfigError as err:
        raise ConfigError(f"run folder {name!r}: {err}") from None
    return _named(config, name, Run(U, omega, int(match[3]), tuple(values.items()), _own(config)), "name")


def find_heap(config: dict, name: str, table: dict | None = None, base_dir: str | Path = ".") -> Run:
    """The first run of heap folder ``name`` (``r0``, ``psd.mean_diameter_um=150/r1``): the sweep's
    (``table``, default :func:`heaps_by_name`), or a heap outside it named by its folder (a new
    replicate, or values of the axes the heap depends on). Raises :class:`ConfigError` naming it."""
    table = heaps_by_name(config) if table is None else table
    if name in table:
        return table[name]
    *folders, leaf = name.split("/")
    if not re.fullmatch(r"r\d+", leaf):
        raise ConfigError(f"heap folder {name!r}: not a heap's folder name, r<replicate> (e.g. r0), after a "
                          "folder <axis>=<value>/ for each extra sweep axis the heap depends on")
    values = _folder_values(config, name, folders, (*SPEED_AXES, *SPREAD_ONLY_AXES))
    if values:
        try:
            _check_variant(config, values, Path(base_dir), "sweep", values)
        except ConfigError as err:
            raise ConfigError(f"heap folder {name!r}: {err}") from None
    first = sweep_runs(config)[0]
    return _named(config, name, Run(first.U, first.omega, int(leaf[1:]), tuple(values.items()), _own(config)),
                  "heap")


def _own(config: dict) -> tuple:
    return tuple((a, config_value(config, a)) for a in sweep_axes(config))


def _named(config: dict, name: str, run: Run, attribute: str) -> Run:
    """``run`` if its folder is spelt ``name``; else a ConfigError giving its spelling."""
    if getattr(run, attribute) != name:
        raise ConfigError(f"{'run' if attribute == 'name' else 'heap'} folder {name!r}: its point's folder is "
                          f"{getattr(run, attribute)!r} (numbers as :g writes them, the sweep's axes in order)")
    return run


def _folder_number(name: str, key: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"folder {name!r}: {key} = {text!r} is not a number") from None


def _folder_values(config: dict, name: str, folders: list, excluded) -> dict:
    """The extra axes' values named by the ``<axis>=<value>`` folders of ``name``, in sweep order."""
    axes = [a for a in sweep_axes(config) if a not in excluded]
    values = {}
    for folder in folders:
        match = _AXIS_FOLDER.fullmatch(folder)
        if not match or match[1] not in axes:
            raise ConfigError(f"folder {name!r}: {folder!r} does not name an axis of the sweep as <axis>=<value> "
                              f"(its axes here: {', '.join(axes) or 'none'})")
        values[match[1]] = _folder_number(name, match[1], match[2])
    return {a: values[a] for a in axes if a in values}


def heaps_by_name(config: dict) -> dict[str, Run]:
    """The first run of each heap folder (``Run.heap``): what the geometry and settle of that heap need."""
    table = {}
    for run in sweep_runs(config):
        table.setdefault(run.heap, run)
    return table


@dataclass(frozen=True)
class Scene:
    """Everything a run needs, in SI units. Built by :func:`scene`."""
    level: str
    strip_width: float
    heap: tuple            # (xlo, xhi, zlo, zhi) of the insertion block [m]
    heap_particles: int
    sampling_region: tuple  # (xmin, xmax, ymin, ymax) [m]
    travel_end: float       # x of the roller axis when it stops [m]
    roller_radius: float
    roller_gap: float
    roller_facets: int
    diameters: tuple        # size-class diameters [m]
    mass_fractions: tuple
    density: float
    youngs_modulus: float
    poisson_ratio: float
    restitution: float
    friction_particle: float
    friction_wall: float
    rolling_friction: float
    cohesion_energy_density: float
    timestep: float
    rayleigh_time: float
    max_rayleigh_fraction: float
    settle_time: float
    rest_time: float
    rest_speed: float       # RMS speed [m/s] below which particles are at rest
    profilometer_lines: int
    mpi_ranks: int
    runtime_min: int | None      # cluster wall-clock limit of a settle or spread job [min]; None: the cluster's
    mem_mb_per_rank: int | None  # cluster memory per MPI rank [MB]; None: the cluster's
    checkpoints_per_run: int     # restart files written over a spread's travel (0: none)
    feed_pile_mass: float | None  # powder mass [kg] held ahead of the roller over the strip; None: no feed
    feed_length: float      # x-extent [m] of the feed zone ahead of the roller axis (0 without feed)
    substrate: dict
    substrate_x: tuple      # (xlo, xhi) the substrate must cover: the whole box [m]
    rough_x: tuple          # (xlo, xhi) where the substrate is rough (around the sampling region) [m]
    box: tuple              # (xlo, xhi, ylo, yhi, zlo, zhi) of the simulation box [m]

    @property
    def mean_particle_mass(self) -> float:
        """Number-mean particle mass [kg]."""
        return self.density * number_mean_volume(self.diameters, self.mass_fractions)


def scene(config: dict, level: str | None = None) -> Scene:
    """Resolve fidelity level ``level`` (default ``config['level']``) into a :class:`Scene`."""
    level = level or config["level"]
    if level not in config["fidelity"]:
        _fail("level", level, f"no such fidelity level; choose one of {sorted(config['fidelity'])}")
    lvl, mat, psd, roller = config["fidelity"][level], config["material"], config["psd"], config["roller"]
    mm, um = 1e-3, 1e-6
    diameters, fractions = psd_classes(psd["mean_diameter_um"] * um, psd["std_diameter_um"] * um,
                                       psd["min_diameter_um"] * um, psd["max_diameter_um"] * um,
                                       lvl["size_classes"])
    width = lvl["strip_width_mm"] * mm
    heap_length = lvl["heap_length_mm"] * mm
    heap_start = lvl.get("heap_start_mm", 0.0) * mm
    mean_volume = number_mean_volume(diameters, fractions)
    heap_height = lvl["heap_particles"] * mean_volume / (INSERTION_SOLID_FRACTION * width * heap_length)
    gap = roller["gap_um"] * um
    radius = roller["diameter_mm"] * mm / 2
    sample_x0 = lvl["sampling_start_mm"] * mm
    sample_x1 = sample_x0 + lvl["sampling_length_mm"] * mm
    sample_w = lvl.get("sampling_width_mm", lvl["strip_width_mm"]) * mm
    y0 = (width - sample_w) / 2
    t_r = rayleigh_time(diameters.min() / 2, mat["density_kg_m3"], mat["youngs_modulus_dem_Pa"],
                        mat["poisson_ratio"])
    sub = config["substrate"]
    pile = lvl.get("feed_pile_mg_per_mm")
    feed_pile_mass = None if pile is None else pile * 1e-6 / mm * width
    try:
        feed_len = 0.0 if pile is None else feed_length(feed_pile_mass / width, mat["density_kg_m3"], radius, gap)
    except ValueError as err:
        _fail(f"fidelity.{level}.feed_pile_mg_per_mm", pile, str(err))
    box = (heap_start - (2 * heap_height + sqrt(2 * radius * heap_height) + radius + 2 * mm),
           sample_x1 + lvl["run_out_mm"] * mm + max(radius, feed_len) + 2 * mm,
           0.0, width,
           -max(gap, 6 * sub["sq_um"] * um) - 0.2 * mm, gap + 2 * radius + 5 * mm)
    return Scene(
        level=level, strip_width=width,
        heap=(heap_start, heap_start + heap_length, gap, gap + heap_height), heap_particles=lvl["heap_particles"],
        sampling_region=(sample_x0, sample_x1, y0, y0 + sample_w),
        travel_end=sample_x1 + lvl["run_out_mm"] * mm,
        roller_radius=radius, roller_gap=gap, roller_facets=roller["facets_around"],
        diameters=tuple(diameters), mass_fractions=tuple(fractions),
        density=mat["density_kg_m3"], youngs_modulus=mat["youngs_modulus_dem_Pa"],
        poisson_ratio=mat["poisson_ratio"], restitution=mat["restitution"],
        friction_particle=mat["sliding_friction_particle"], friction_wall=mat["sliding_friction_wall"],
        rolling_friction=mat["rolling_friction"], cohesion_energy_density=mat["cohesion_energy_density_J_m3"],
        timestep=config["timestep"]["rayleigh_fraction"] * t_r, rayleigh_time=t_r,
        max_rayleigh_fraction=config["timestep"]["max_rayleigh_fraction"],
        settle_time=lvl["settle_time_s"], rest_time=lvl["rest_time_s"],
        rest_speed=config["rest_rms_speed_mm_s"] * mm,
        profilometer_lines=lvl["profilometer_lines"], mpi_ranks=lvl["mpi_ranks"],
        runtime_min=lvl.get("runtime_min"), mem_mb_per_rank=lvl.get("mem_mb_per_rank"),
        checkpoints_per_run=lvl.get("checkpoints_per_run", 0),
        feed_pile_mass=feed_pile_mass, feed_length=feed_len,
        substrate={"sq": sub["sq_um"] * um, "correlation_length": sub["correlation_length_um"] * um,
                   "grid_spacing": sub["grid_spacing_um"] * um, "seed": sub["seed"], "mesh": sub["mesh"]},
        rough_x=(sample_x0 - 0.5 * mm, sample_x1 + 0.5 * mm),
        box=box,
        substrate_x=box[:2],
    )
