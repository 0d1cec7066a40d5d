"""The facts of a configuration that relate two keys, which its JSON Schema cannot express: the
physics and the scene (:func:`check_physics`), the bounds of a LIGGGHTS run (:func:`check_bounds`,
:func:`check_speeds`), the sweep (:func:`check_sweep`) and the maps (:func:`check_maps`). Each
raises :class:`~analysis.config.errors.ConfigError` naming the key and its value."""
from __future__ import annotations

from math import sqrt
from pathlib import Path

import numpy as np

from analysis.config.errors import ConfigError, refuse
from analysis.config.fidelity import scene
from analysis.config.reading import check_finite, validate_schema
from analysis.config.sweep import (
    EXECUTION_KEYS,
    SPEED_AXES,
    SPREAD_ONLY_AXES,
    SWEEP_KEYS,
    config_value,
    resolve,
    sweep_axes,
    sweep_points,
    sweep_runs,
    variants,
)
from analysis.physics import feed_length, psd_classes

#: The most time steps one LIGGGHTS ``run`` command takes (a signed 32-bit count):
#: beyond it LIGGGHTS stops with "Invalid run command".
MAX_RUN_STEPS = 2**31 - 1

#: Nodes of the generated rough substrate at most (its random field and mesh: about 1 kB a node).
MAX_SUBSTRATE_NODES = 10_000_000

#: The roller's surface moves at most this fraction of the smallest particle's radius in a time step.
MAX_WALL_STEP = 0.1


def check_config(config: dict, base_dir: Path = Path(".")) -> None:
    """Cross-key checks the schema cannot express, then the sweep's (:func:`check_sweep`)."""
    check_physics(config, base_dir)
    check_peak_cap(config)
    check_sweep(config, base_dir)
    check_maps(config)


def check_peak_cap(config: dict) -> None:
    """The generated substrate's peaks are clipped at ``substrate.peak_cap_fraction_of_gap`` x
    ``roller.gap_um`` above the region's mean plane: at least 2 Sq, or the surface is no longer
    a Gaussian field's. The gap is the config's own: a swept gap spreads on the same substrate."""
    sub, gap = config["substrate"], config["roller"]["gap_um"]
    cap = sub["peak_cap_fraction_of_gap"] * gap
    if sub["mesh"] is None and cap < 2 * sub["sq_um"]:
        refuse("substrate.peak_cap_fraction_of_gap", sub["peak_cap_fraction_of_gap"],
               f"clips the generated substrate {cap:.0f} um (that fraction of roller.gap_um = {gap}) above the "
               f"region's mean plane, under 2 x substrate.sq_um = {sub['sq_um']}: a Gaussian surface has 2.3 % of "
               "its area above 2 Sq, and clipped there it is no longer one; raise the fraction or the gap, or lower "
               "the Sq")


def check_maps(config: dict) -> None:
    """``maps`` names inputs of the sweep (U_mm_s, omega_rad_s, its extra axes): two to span,
    others to hold inside their swept range, one other for the panels."""
    maps, points = config["maps"], sweep_points(config)
    inputs = [*SPEED_AXES, *sweep_axes(config)]
    known = f"the sweep's inputs are {', '.join(inputs)}"
    for axis in maps["axes"]:
        if axis not in inputs:
            refuse("maps.axes", maps["axes"], f"names {axis!r}, not an input: {known}")
    for name, value in maps["hold"].items():
        if name not in inputs or name in maps["axes"]:
            refuse(f"maps.hold.{name}", value, f"holds what is not an input outside maps.axes: {known}")
        lo, hi = min(p[name] for p in points), max(p[name] for p in points)
        if not lo <= value <= hi:
            refuse(f"maps.hold.{name}", value, f"lies outside the swept range {lo:g}..{hi:g}")
    panels = maps["panels"]
    if panels is not None and (panels not in inputs or panels in maps["axes"] or panels in maps["hold"]):
        refuse("maps.panels", panels, f"must be an input neither mapped (maps.axes) nor held (maps.hold): {known}")


def check_physics(config: dict, base_dir: Path = Path(".")) -> None:
    """Cross-key checks of the physics, scene and fidelity sections (one set of values)."""
    level = config["level"]
    if level not in config["fidelity"]:
        refuse("level", level, f"no such fidelity level; choose one of {sorted(config['fidelity'])}")
    psd = config["psd"]
    if psd["min_diameter_um"] >= psd["max_diameter_um"]:
        refuse("psd.min_diameter_um", psd["min_diameter_um"],
              f"must be below psd.max_diameter_um = {psd['max_diameter_um']}")
    if not psd["min_diameter_um"] <= psd["mean_diameter_um"] <= psd["max_diameter_um"]:
        refuse("psd.mean_diameter_um", psd["mean_diameter_um"], "must lie between the min and max diameters")
    far = max(("min_diameter_um", "max_diameter_um"),
              key=lambda k: abs(psd[k] - psd["mean_diameter_um"]) / psd["std_diameter_um"])
    for name, lvl in config["fidelity"].items():
        d, w = psd_classes(psd["mean_diameter_um"], psd["std_diameter_um"], psd["min_diameter_um"],
                           psd["max_diameter_um"], lvl["size_classes"])
        if not (np.isfinite(d).all() and (w > 1e-9).all()):
            refuse(f"psd.{far}", psd[far], f"leaves a size class of fidelity.{name} ({lvl['size_classes']} classes) "
                  f"with no particles of the Gaussian (mean {psd['mean_diameter_um']}, sd {psd['std_diameter_um']} "
                  "um): bring the range within a few sds of the mean, or use fewer size_classes")
    gap = config["roller"]["gap_um"]
    if gap < psd["min_diameter_um"]:
        refuse("roller.gap_um", gap, f"is below the smallest particle diameter ({psd['min_diameter_um']} um)")
    step = config["timestep"]
    if step["rayleigh_fraction"] > step["max_rayleigh_fraction"]:
        refuse("timestep.rayleigh_fraction", step["rayleigh_fraction"],
              f"exceeds timestep.max_rayleigh_fraction = {step['max_rayleigh_fraction']}")
    mesh = config["substrate"]["mesh"]
    if mesh is not None and not (base_dir / mesh).is_file():
        refuse("substrate.mesh", mesh, "file not found")
    for name, lvl in config["fidelity"].items():
        width = lvl.get("sampling_width_mm", lvl["strip_width_mm"])
        if width > lvl["strip_width_mm"]:
            refuse(f"fidelity.{name}.sampling_width_mm", width,
                  f"exceeds the strip width {lvl['strip_width_mm']} mm")
        pile = lvl.get("feed_pile_mg_per_mm")
        if pile is not None:
            try:
                feed_length(pile * 1e-3, config["material"]["density_kg_m3"], config["roller"]["diameter_mm"] / 2e3,
                            config["roller"]["gap_um"] * 1e-6)
            except ValueError as err:
                refuse(f"fidelity.{name}.feed_pile_mg_per_mm", pile,
                      f"{err} mg/mm at material.density_kg_m3 = {config['material']['density_kg_m3']!r}, "
                      f"roller.diameter_mm = {config['roller']['diameter_mm']!r} and "
                      f"roller.gap_um = {config['roller']['gap_um']!r}")
        lag = lvl.get("freeze_lag_mm")
        if lag is not None:
            # the roller is a largest particle above the layer this far behind its axis
            roller = config["roller"]
            nip = sqrt(roller["diameter_mm"] * (roller["gap_um"] + config["psd"]["max_diameter_um"]) / 1e3)
            if lag < nip:
                refuse(f"fidelity.{name}.freeze_lag_mm", lag,
                      f"freezes powder still in the roller's nip: it must be at least {nip:.2f} mm (where the roller "
                      f"is a largest particle, psd.max_diameter_um, above a layer of roller.gap_um)")
        if lvl["sampling_start_mm"] < lvl.get("heap_start_mm", 0) + lvl["heap_length_mm"]:
            refuse(f"fidelity.{name}.sampling_start_mm", lvl["sampling_start_mm"],
                  f"starts inside the heap (heap_length_mm = {lvl['heap_length_mm']})")
    check_bounds(config)


def check_bounds(config: dict) -> None:
    """Bounds that hold between keys: each level's settle and rest fit LIGGGHTS' run command
    (:data:`MAX_RUN_STEPS`) and its generated substrate the memory (:data:`MAX_SUBSTRATE_NODES`)."""
    fraction = config["timestep"]["rayleigh_fraction"]
    for name, lvl in config["fidelity"].items():
        s = scene(config, name)
        for key in ("settle_time_s", "rest_time_s"):
            steps = lvl[key] / s.timestep
            if steps > MAX_RUN_STEPS:
                refuse(f"fidelity.{name}.{key}", lvl[key],
                      f"takes {steps:.3g} time steps of {s.timestep:.3g} s (timestep.rayleigh_fraction = {fraction!r}):"
                      f" at most {MAX_RUN_STEPS} fit a LIGGGHTS run")
        if config["substrate"]["mesh"] is None:
            spacing = config["substrate"]["grid_spacing_um"] * 1e-6
            nodes = ((s.rough_x[1] - s.rough_x[0] + 1e-3) / spacing + 1) * (s.strip_width / spacing + 1)
            if nodes > MAX_SUBSTRATE_NODES:
                refuse("substrate.grid_spacing_um", config["substrate"]["grid_spacing_um"],
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
    level = config["level"]
    if "material.youngs_modulus_dem_Pa" in axes and "youngs_modulus_dem_Pa" in config["fidelity"].get(level, {}):
        refuse("sweep.material.youngs_modulus_dem_Pa", sweep["material.youngs_modulus_dem_Pa"],
              f"is swept, but fidelity.{level}.youngs_modulus_dem_Pa sets the stiffness at level {level}: "
              f"sweep fidelity.{level}.youngs_modulus_dem_Pa instead, or remove it")
    if sweep.get("points") and sweep.get("points_mm_s_rad_s"):
        refuse("sweep.points", "...", "and sweep.points_mm_s_rad_s are both given: keep one")
    if axes and sweep.get("points_mm_s_rad_s"):
        refuse("sweep.points_mm_s_rad_s", sweep["points_mm_s_rad_s"],
              f"gives (U, omega) only, but the sweep also has {', '.join(axes)}: list the points "
              "over all axes in sweep.points")
    for i, point in enumerate(sweep.get("points") or []):
        if set(point) != {*SPEED_AXES, *axes}:
            refuse(f"sweep.points[{i}]", point, f"must name exactly {', '.join([*SPEED_AXES, *axes])}"
                  + ("" if axes else " (list an extra axis' values in sweep as well: its range)"))
    run = variants(config)
    for axis in axes:                       # each value alone (listed or in sweep.points): the message names it
        labels = {f"{config_value(config, axis):g}": config_value(config, axis)}
        for value in dict.fromkeys([*sweep[axis], *(v[axis] for v in run)]):
            check_variant(config, {axis: value}, base_dir, f"sweep.{axis}", value)
            other = labels.setdefault(f"{value:g}", value)
            if other != value:
                refuse(f"sweep.{axis}", value, f"has the folder name {axis}={value:g} of {other!r} (the config's "
                      "own value, or another listed one): sweep values that differ in their first 6 digits")
    for values in run:                      # and every combination run (cross-key facts between axes)
        if len(values) > 1:
            check_variant(config, values, base_dir, "sweep", values)
    for value in dict.fromkeys([*sweep.get("roller.gap_um", []), *(v["roller.gap_um"] for v in run
                                                                    if "roller.gap_um" in v)]):
        check_swept_gap(config, value)
    runs = sweep_runs(config)
    names = [run.name for run in runs]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        key = "sweep.points" if sweep.get("points") else "sweep.points_mm_s_rad_s" \
            if sweep.get("points_mm_s_rad_s") else "sweep"
        refuse(key, sweep.get(key.split(".", 1)[-1]) if key != "sweep" else axes,
              f"lists the same run folder twice: {', '.join(repeated[:3])}")
    n_points = len(sweep_points(config))
    if config["surrogate"]["n_test"] > n_points - 3:
        refuse("surrogate.n_test", config["surrogate"]["n_test"],
              f"leaves fewer than 3 of the sweep's {n_points} points to train on")
    if config["surrogate"]["cv_folds"] > n_points:
        refuse("surrogate.cv_folds", config["surrogate"]["cv_folds"],
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
        steps = (s.travel_end_max - s.box[0]) / (slowest["U_mm_s"] * 1e-3) / s.timestep
        if steps > MAX_RUN_STEPS:
            refuse("sweep.U_mm_s", slowest["U_mm_s"], f"needs {steps:.3g} time steps of {s.timestep:.3g} s to travel "
                  f"{(s.travel_end_max - s.box[0]) * 1e3:.3g} mm (from behind the heap, a roller.diameter_mm behind "
                  f"fidelity.{s.level}.heap_start_mm, heap_length_mm and heap_particles, to the end of "
                  f"fidelity.{s.level}.sampling_start_mm + sampling_length_mm + run_out_mm or run_out_max_mm; "
                  f"the step is "
                  f"timestep.rayleigh_fraction of the Rayleigh time of the level's Young's modulus): "
                  f"at most {MAX_RUN_STEPS} fit a LIGGGHTS run")
        r_min = min(s.diameters) / 2
        for p in points:
            wall = (p["U_mm_s"] * 1e-3 + abs(p["omega_rad_s"]) * s.roller_radius) * s.timestep
            if wall > MAX_WALL_STEP * r_min:
                key = "sweep.U_mm_s" if p["U_mm_s"] * 1e-3 >= abs(p["omega_rad_s"]) * s.roller_radius \
                    else "sweep.omega_rad_s"
                refuse(key, p[key.split(".")[1]],
                      f"moves the roller's surface {wall * 1e6:.3g} um a time step of {s.timestep:.3g} s (U = "
                      f"{p['U_mm_s']:g} mm/s, omega = {p['omega_rad_s']:g} rad/s): more than {MAX_WALL_STEP:g} of the "
                      f"smallest radius ({r_min * 1e6:.3g} um); lower the speeds or the time step "
                      "(timestep.rayleigh_fraction of the Rayleigh time set by the level's Young's modulus, "
                      "density_kg_m3 and psd.min_diameter_um)")


def check_swept_gap(config: dict, value: float) -> None:
    """A swept gap spreads the heap settled under ``roller.gap_um``: at least that gap, and in its box."""
    gap = config["roller"]["gap_um"]
    if value < gap:
        refuse("sweep.roller.gap_um", value,
              f"is below roller.gap_um = {gap!r}, the gap the heap is settled and the substrate's peaks "
              f"are capped under (substrate.peak_cap_fraction_of_gap) for every swept gap: set roller.gap_um to the "
              "smallest swept gap")
    spread, heap_box = scene(resolve(config, {"roller.gap_um": value})), scene(config).box
    if spread.box[1] > heap_box[1] or spread.roller_gap + 2 * spread.roller_radius > heap_box[5]:
        refuse("sweep.roller.gap_um", value,
              f"puts the roller or its feed outside the simulation box of the heap settled at "
              f"roller.gap_um = {gap!r} (the spread starts from its restart): sweep gaps closer to it")


def check_variant(config: dict, values: dict, base_dir: Path, key: str, shown) -> None:
    """Schema and :func:`check_physics` on ``config`` with ``values`` in place; a failure
    names ``key`` = ``shown`` and what is wrong, in one line."""
    resolved = resolve(config, values)
    resolved["sweep"] = {k: v for k, v in resolved["sweep"].items() if k not in values}
    try:
        check_finite(resolved)
        validate_schema(resolved)
        check_physics(resolved, base_dir)
        check_peak_cap(resolve(config, {k: v for k, v in values.items() if k not in SPREAD_ONLY_AXES}))
    except ConfigError as err:
        where = "in its place" if len(values) == 1 else "in that combination"
        raise ConfigError(f"config key {key!r} = {shown!r}: {where}, {err}") from None


def check_axis_key(config: dict, axis: str) -> None:
    """Raise :class:`ConfigError` unless ``axis`` is a numeric key a simulation computes with:
    a key of ``material``, ``psd``, ``roller``, ``substrate`` or ``timestep``, or of the running
    fidelity level but its execution keys; not a seed (``sweep.replicates`` varies those)."""
    *path, last = axis.split(".")
    level = config["level"]
    if not path:
        refuse(f"sweep.{axis}", config["sweep"][axis],
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
        refuse(f"sweep.{axis}", config["sweep"][axis], why)
