"""The scene of one fidelity level in SI units: :func:`scene` resolves a checked config into a :class:`Scene`."""
from __future__ import annotations

from dataclasses import dataclass
from math import sqrt

from analysis.config.errors import refuse
from analysis.physics import INSERTION_SOLID_FRACTION, feed_length, number_mean_volume, psd_classes, rayleigh_time


@dataclass(frozen=True)
class Scene:
    """Everything a run needs, in SI units. Built by :func:`scene`."""
    level: str
    strip_width: float
    heap: tuple            # (xlo, xhi, zlo, zhi) of the insertion block [m]
    heap_particles: int
    sampling_region: tuple  # (xmin, xmax, ymin, ymax) [m]
    travel_end: float       # x of the roller axis where it stops, or (with ``run_out_max_mm``) may first stop [m]
    travel_end_max: float   # x of the roller axis where it stops at the latest [m] (= travel_end: a fixed stop)
    laid_speed: float       # RMS speed [m/s] below which the sampling region's layer is laid (layer_laid)
    laid_checks: int        # checks in a row at which it must be so before the roller may stop
    laid_check_every: float  # roller travel [m] between two checks
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
    feed_every: float       # roller travel [m] between two top-ups of a fed pile
    freeze_lag: float | None  # the laid layer before the region is frozen this far behind the roller [m]; None: never
    freeze_x_max: float     # x [m] before which a laid particle may be frozen (FREEZE_MARGIN_MM before the region)
    substrate: dict
    substrate_x: tuple      # (xlo, xhi) the substrate must cover: the whole box [m]
    rough_x: tuple          # (xlo, xhi) where the substrate is rough (around the sampling region) [m]
    box: tuple              # (xlo, xhi, ylo, yhi, zlo, zhi) of the simulation box [m]

    @property
    def mean_particle_mass(self) -> float:
        """Number-mean particle mass [kg]."""
        return self.density * number_mean_volume(self.diameters, self.mass_fractions)


#: Only the layer more than this far [mm] before the sampling region is frozen (``freeze_lag_mm``): the
#: region's particles and their neighbours (about 4 largest diameters) stay free.
FREEZE_MARGIN_MM = 1.0


#: Roller travel [mm] between two top-ups of a fed pile, unless the level sets ``feed_every_mm``:
#: the pile dips by at most the layer laid over it (about 2 % of a 20 mg/mm pile).
FEED_EVERY_MM = 0.5


def youngs_modulus(config: dict, level: str) -> float:
    """Young's modulus [Pa] of the particles at fidelity level ``level``: the level's own
    ``youngs_modulus_dem_Pa`` where it sets one (the smoke level, which checks the workflow, not
    the physics), else the material's."""
    return config["fidelity"][level].get("youngs_modulus_dem_Pa", config["material"]["youngs_modulus_dem_Pa"])


def scene(config: dict, level: str | None = None) -> Scene:
    """Resolve fidelity level ``level`` (default ``config['level']``) into a :class:`Scene`."""
    level = level or config["level"]
    if level not in config["fidelity"]:
        refuse("level", level, f"no such fidelity level; choose one of {sorted(config['fidelity'])}")
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
    youngs = youngs_modulus(config, level)
    t_r = rayleigh_time(diameters.min() / 2, mat["density_kg_m3"], youngs, mat["poisson_ratio"])
    sub = config["substrate"]
    pile = lvl.get("feed_pile_mg_per_mm")
    feed_pile_mass = None if pile is None else pile * 1e-6 / mm * width
    try:
        feed_len = 0.0 if pile is None else feed_length(feed_pile_mass / width, mat["density_kg_m3"], radius, gap)
    except ValueError as err:
        refuse(f"fidelity.{level}.feed_pile_mg_per_mm", pile, str(err))
    run_out = lvl["run_out_mm"] * mm
    run_out_max = lvl.get("run_out_max_mm", lvl["run_out_mm"]) * mm
    if run_out_max < run_out:
        refuse(f"fidelity.{level}.run_out_mm", lvl["run_out_mm"],
               f"the roller may first stop there, past the latest stop, run_out_max_mm ({lvl['run_out_max_mm']:g} mm)")
    laid = config["layer_laid"]
    box = (heap_start - (2 * heap_height + sqrt(2 * radius * heap_height) + radius + 2 * mm),
           sample_x1 + run_out_max + max(radius, feed_len) + 2 * mm,
           0.0, width,
           -max(gap, 6 * sub["sq_um"] * um) - 0.2 * mm, gap + 2 * radius + 5 * mm)
    return Scene(
        level=level, strip_width=width,
        heap=(heap_start, heap_start + heap_length, gap, gap + heap_height), heap_particles=lvl["heap_particles"],
        sampling_region=(sample_x0, sample_x1, y0, y0 + sample_w),
        travel_end=sample_x1 + run_out, travel_end_max=sample_x1 + run_out_max,
        laid_speed=laid["rms_speed_mm_s"] * mm, laid_checks=laid["checks"],
        laid_check_every=laid["check_every_mm"] * mm,
        roller_radius=radius, roller_gap=gap, roller_facets=roller["facets_around"],
        diameters=tuple(diameters), mass_fractions=tuple(fractions),
        density=mat["density_kg_m3"], youngs_modulus=youngs,
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
        feed_pile_mass=feed_pile_mass, feed_length=feed_len, feed_every=lvl.get("feed_every_mm", FEED_EVERY_MM) * mm,
        freeze_lag=None if lvl.get("freeze_lag_mm") is None else lvl["freeze_lag_mm"] * mm,
        freeze_x_max=sample_x0 - FREEZE_MARGIN_MM * mm,
        substrate={"sq": sub["sq_um"] * um, "correlation_length": sub["correlation_length_um"] * um,
                   "grid_spacing": sub["grid_spacing_um"] * um, "seed": sub["seed"], "mesh": sub["mesh"],
                   "peak_cap": sub["peak_cap_fraction_of_gap"] * config["roller"]["gap_um"] * um},
        rough_x=(sample_x0 - lvl.get("rough_before_mm", 0.5) * mm, sample_x1 + lvl.get("rough_past_mm", 0.5) * mm),
        box=box,
        substrate_x=box[:2],
    )
