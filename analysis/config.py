"""Load and check ``config.yaml``; derive the scene of one fidelity level in SI units.

The configuration is checked twice: by its JSON Schema (types, ranges, unknown
keys) and by :func:`check_config` (facts that relate two keys). Both raise
:class:`ConfigError` with the dotted key and the offending value, before any
simulation starts.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass
from math import sqrt
from pathlib import Path

import jsonschema
import numpy as np
import yaml

from analysis.physics import INSERTION_SOLID_FRACTION, feed_length, number_mean_volume, psd_classes, rayleigh_time

#: The project folder: config.yaml, templates/, Snakefile (the package is installed in place).
PROJECT_DIR = Path(__file__).resolve().parents[1]
SCHEMA_PATH = Path(__file__).with_name("schemas") / "config.schema.yaml"


class ConfigError(ValueError):
    """A configuration value is wrong; the message names its key and value."""


def coerce_cli_values(value):
    """Numbers, booleans and nulls from strings, recursively.

    Snakemake parses nested ``--config key='{...}'`` values with YAML's
    BaseLoader, which leaves every scalar a string; this restores the types
    so that ``--config sweep='{"U_mm_s": [40, 70]}'`` works.
    """
    if isinstance(value, dict):
        return {k: coerce_cli_values(v) for k, v in value.items()}
    if isinstance(value, list):
        return [coerce_cli_values(v) for v in value]
    if isinstance(value, str):
        return yaml.safe_load(value) if value.strip() else value
    return value


def load_schema() -> dict:
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
        config = yaml.safe_load(path.read_text())
        base_dir = path.parent if base_dir is None else base_dir
    else:
        config = copy.deepcopy(source)
    check_finite(config)
    validate_schema(config)
    check_config(config, Path(base_dir or "."))
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


def validate_schema(config: dict) -> None:
    """Raise :class:`ConfigError` on the first schema violation, naming key and value."""
    validator = jsonschema.Draft202012Validator(load_schema())
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if errors:
        error = errors[0]
        key = ".".join(str(p) for p in error.absolute_path) or "<top level>"
        raise ConfigError(f"config key {key!r}: {error.message} (value: {error.instance!r})")


def _fail(key: str, value, why: str):
    raise ConfigError(f"config key {key!r} = {value!r}: {why}")


def check_config(config: dict, base_dir: Path = Path(".")) -> None:
    """Cross-key checks the schema cannot express."""
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
        if lvl["sampling_start_mm"] < lvl["heap_length_mm"]:
            _fail(f"fidelity.{name}.sampling_start_mm", lvl["sampling_start_mm"],
                  f"starts inside the heap (heap_length_mm = {lvl['heap_length_mm']})")
    points = design_points(config)
    names = [run_name(U, w, 0) for U, w in points]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        _fail("sweep.points_mm_s_rad_s", config["sweep"]["points_mm_s_rad_s"],
              f"lists the same run folder twice: {', '.join(repeated)}")
    n_points = len(points)
    if config["surrogate"]["n_test"] > n_points - 3:
        _fail("surrogate.n_test", config["surrogate"]["n_test"],
              f"leaves fewer than 3 of the sweep's {n_points} (U, omega) points to train on")


#: Fidelity keys that say how a run is executed, not what it computes.
EXECUTION_KEYS = ("mpi_ranks", "runtime_min", "mem_mb_per_rank", "checkpoints_per_run", "profilometer_lines")


#: Top-level sections whose values a settle or spread computes with.
SIMULATION_SECTIONS = ("random_seed", "material", "psd", "roller", "substrate", "rest_rms_speed_mm_s", "timestep")


def simulation_fingerprint(config: dict, level: str, sections=SIMULATION_SECTIONS) -> str:
    """A short hash of everything in ``config`` that a simulation of ``level``
    computes with (``sections`` and the level's fidelity keys but
    EXECUTION_KEYS). The workflow passes it as a rule parameter, so that
    Snakemake re-runs the simulations when the physics changes (and not when
    only the MPI ranks or the cluster limits do)."""
    relevant = {key: config.get(key) for key in sections}
    relevant["fidelity"] = {k: v for k, v in config["fidelity"][level].items() if k not in EXECUTION_KEYS}
    return hashlib.sha256(json.dumps(relevant, sort_keys=True, default=str).encode()).hexdigest()[:16]


def run_name(U: float, omega: float, replicate: int) -> str:
    """Folder name of one run: U in mm/s, omega in rad/s, replicate index (``U70_w-2.5_r0``)."""
    return f"U{U:g}_w{omega:g}_r{replicate}"


def design_points(config: dict) -> list[tuple[float, float]]:
    """The sweep's (U [mm/s], omega [rad/s]) points: ``sweep.points_mm_s_rad_s`` if given,
    else the grid ``U_mm_s x omega_rad_s`` (U outer)."""
    sweep = config["sweep"]
    if sweep.get("points_mm_s_rad_s"):
        return [(float(U), float(w)) for U, w in sweep["points_mm_s_rad_s"]]
    return [(float(U), float(w)) for U in sweep["U_mm_s"] for w in sweep["omega_rad_s"]]


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
    box = (-(2 * heap_height + sqrt(2 * radius * heap_height) + radius + 2 * mm),
           sample_x1 + lvl["run_out_mm"] * mm + max(radius, feed_len) + 2 * mm,
           0.0, width,
           -max(gap, 6 * sub["sq_um"] * um) - 0.2 * mm, gap + 2 * radius + 5 * mm)
    return Scene(
        level=level, strip_width=width,
        heap=(0.0, heap_length, gap, gap + heap_height), heap_particles=lvl["heap_particles"],
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
