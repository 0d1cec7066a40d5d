"""One scene, run for real: make its geometry, settle its heap, spread it.

Each step renders a template from ``templates/``, runs LIGGGHTS through
:mod:`analysis.run_liggghts` and checks the result's health; an unsound run
raises :class:`~analysis.run_liggghts.LiggghtsError`, never passes a result on.

Command line (the workflow's rules call the same functions)::

    python -m analysis.simulate geometry --level smoke --out results/smoke/meshes
    python -m analysis.simulate settle   --level smoke --meshes results/smoke/meshes --out results/smoke/settle
    python -m analysis.simulate spread   --level smoke --U 70 --omega -5 --meshes ... --settled ... --out ...
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import sys
from math import ceil, pi, sqrt
from pathlib import Path

import numpy as np
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import cKDTree

from analysis import geometry
from analysis.config import ConfigError, Scene, liggghts_seeds, load_config, roller_motion, scene
from analysis.dump import read_dump
from analysis.run_liggghts import LiggghtsError, render, run

THERMO_EVERY = 1000
#: A particle counts as "through the substrate" when its centre is this many
#: radii below the substrate surface under it.
BELOW_SUBSTRATE_RADII = 0.5
#: Largest tolerated particle-particle overlap, as a fraction of the smaller
#: radius: in the sampling region (what is measured), and anywhere. Particles
#: jammed under the kinematic roller, ahead of the region, are squeezed far
#: harder (20 % seen at U = 40 mm/s); past 50 % spheres pass through each other.
MAX_OVERLAP = 0.05
MAX_OVERLAP_ANYWHERE = 0.5
#: A run "blows up" when any particle moves faster than the fastest speed a
#: sound run can give it: at least BLOWUP_FLOOR_M_S (a fall from the top of the
#: box is under 1 m/s), BLOWUP_SPEED_FACTOR times the fastest wall (U + |omega| R),
#: and the speed a particle squeezed against a wall to the largest tolerated
#: overlap (MAX_OVERLAP_ANYWHERE) gets back when the stored Hertz energy is
#: released (squeeze_out_speed: 5.4 m/s at E = 5 MPa). With a fed pile, sound
#: runs squeeze single particles out of the roller's nip at up to 2.6 m/s; one
#: at 0.4 T_R reached 6.65 m/s (under 1 m/s at 0.35 and 0.3 T_R), and unstable
#: time steps reach 12-34 m/s (benchmarks/measured/stress.md, docs/scene_size.md).
#: Checked on the thermo output during the run (every THERMO_EVERY steps), not
#: only on the final state.
BLOWUP_SPEED_FACTOR = 10
BLOWUP_FLOOR_M_S = 2.0
#: Largest share of the heap that may roll ahead, to the sampling region, while
#: it slumps; these strays are removed before the spread (more: a scene error).
MAX_STRAYS = 0.01
#: The generated substrate's peaks are clipped at this fraction of the roller's
#: gap (3.4 Sq at the configured 300 um gap and Sq 79 um): otherwise the paper
#: level's large field puts a node through the roller.
PEAK_CAP = 0.9
#: Length [m] over which the rough substrate ramps to flat outside the sampling region.
ROUGH_TAPER = 0.5e-3


def seeds(config: dict, s: Scene, replicate: int = 0) -> list[int]:
    """LIGGGHTS seeds of a replicate: one per size class, the distribution, the insertion."""
    return liggghts_seeds(config["random_seed"] + 1000 * replicate, len(s.diameters) + 2)


def contact_model(s: Scene) -> str:
    """The granular contact model: Hertz with tangential history, plus rolling
    friction and cohesion only where their coefficients are non-zero."""
    model = "model hertz tangential history"
    if s.rolling_friction > 0:
        model += " rolling_friction epsd2"
    if s.cohesion_energy_density > 0:
        model += " cohesion sjkr"
    return model


SKIN_DIAMETERS = 0.2
REST_CHUNK_S = 0.005  # [s] between two at-rest checks


def rest_loop(s: Scene, max_time: float, stop_at_rest: bool = True) -> dict:
    """Template values for ``_until_rest.j2``: chunks of REST_CHUNK_S up to ``max_time``,
    stopping early (``stop_at_rest``) once the kinetic energy per particle [J] is
    that of the RMS speed ``rest_rms_speed_mm_s``."""
    chunk = THERMO_EVERY * max(1, round(REST_CHUNK_S / s.timestep / THERMO_EVERY))
    return {"chunk_steps": chunk, "max_chunks": max(1, ceil(max_time / (chunk * s.timestep))),
            "rest_speed": s.rest_speed, "rest_ke": 0.5 * s.mean_particle_mass * s.rest_speed**2,
            "stop_at_rest": stop_at_rest}


def binsize(s: Scene) -> float:
    """Neighbour bin size [m]: the neighbour cutoff (largest diameter + skin).

    Each rebuild tests every particle in the bins a mesh facet's box touches,
    and the rotating roller forces a rebuild every ~10-20 steps: these bins
    are 9 % faster than bins of 4 largest diameters, and LIGGGHTS' own (half
    the cutoff) 28 % slower than those (benchmarks/measured/spread_profile.md)."""
    return max(s.diameters) + skin(s)


def skin(s: Scene) -> float:
    """Neighbour-list skin [m]: 20 % of the mean class diameter. Each particle
    checks every substrate triangle within its radius + skin, every step."""
    return SKIN_DIAMETERS * float(np.mean(s.diameters))


# --------------------------------------------------------------------------
# Geometry

def substrate_seed(config: dict, replicate: int = 0) -> int:
    """Seed of the substrate's random field for ``replicate``: every replicate is a new
    heap packing *and* a new realisation of the same rough surface (same Sq and
    correlation length), so the seed-to-seed spread includes the substrate's."""
    return config["substrate"]["seed"] + replicate


def make_geometry(config: dict, level: str, outdir: str | Path, base_dir: Path = Path("."),
                  replicate: int = 0) -> dict:
    """Write ``substrate.stl``, ``roller.stl`` (closed) and ``roller_shell.stl``
    (its lateral surface, what the periodic strip loads) into ``outdir``.

    The generated substrate is realisation :func:`substrate_seed` of ``replicate``.
    A user's STL (``substrate.stl`` in the config, metres) replaces it for every
    replicate; it must cover the bed, and no substrate peak may reach the roller.
    """
    s, out = scene(config, level), Path(outdir)
    if s.substrate["stl"]:
        substrate = geometry.load_stl(base_dir / s.substrate["stl"])
        lo, hi = substrate.bounds
        need = (s.substrate_x[0], s.substrate_x[1], 0.0, s.strip_width)
        if lo[0] > need[0] or hi[0] < need[1] or lo[1] > 1e-9 or hi[1] < s.strip_width - 1e-9:
            raise ConfigError(f"config key 'substrate.stl' = {s.substrate['stl']!r}: covers x {lo[0]:.4g}..{hi[0]:.4g} m,"
                              f" y {lo[1]:.4g}..{hi[1]:.4g} m; the bed needs x {need[0]:.4g}..{need[1]:.4g},"
                              f" y 0..{s.strip_width:.4g} m")
    else:
        sub = s.substrate
        substrate = geometry.rough_substrate(s.substrate_x, s.strip_width, sub["grid_spacing"],
                                             sub["correlation_length"], sub["sq"], substrate_seed(config, replicate),
                                             rough_x=s.rough_x, taper=ROUGH_TAPER,
                                             peak_cap=PEAK_CAP * s.roller_gap)
        clipped_sq = geometry.substrate_rms(substrate, s.rough_x)[1]
        if clipped_sq < 0.99 * sub["sq"]:
            raise ConfigError(f"config key 'roller.gap_um' = {s.roller_gap * 1e6:g}: the substrate's peaks reach "
                              f"the roller; clipping them at {PEAK_CAP:g} x the gap would lower Sq from "
                              f"{sub['sq'] * 1e6:.0f} to {clipped_sq * 1e6:.0f} um")
    peak = substrate.vertices[:, 2].max()
    if peak >= s.roller_gap:
        raise ConfigError(f"config key 'roller.gap_um' = {s.roller_gap * 1e6:g}: the substrate's highest peak "
                          f"({peak * 1e6:.0f} um) reaches the roller")
    if substrate.vertices[:, 2].min() <= s.box[4]:
        raise ConfigError(f"substrate reaches below the simulation box (z = {s.box[4]:.4g} m)")
    mean, sq = geometry.substrate_rms(substrate, s.sampling_region[:2])
    paths = {"substrate": geometry.write_stl(substrate, out / "substrate.stl"),
             "roller": geometry.write_stl(geometry.roller(2 * s.roller_radius, s.strip_width, s.roller_facets),
                                          out / "roller.stl"),
             "roller_shell": geometry.write_stl(
                 geometry.roller(2 * s.roller_radius, s.strip_width, s.roller_facets, capped=False),
                 out / "roller_shell.stl")}
    return {**{k: str(v) for k, v in paths.items()}, "substrate_seed": None if s.substrate["stl"] else
            substrate_seed(config, replicate), "substrate_mean_m": mean, "substrate_sq_m": sq,
            "substrate_peak_m": float(peak), "substrate_triangles": len(substrate.faces)}


def substrate_height(substrate_stl: str | Path):
    """A vectorised z(x, y) [m] of a height-field STL (linear between its vertices)."""
    mesh = geometry.load_stl(substrate_stl)
    xy, inverse = np.unique(mesh.vertices[:, :2].round(12), axis=0, return_inverse=True)
    z = np.full(len(xy), -np.inf)
    np.maximum.at(z, inverse.ravel(), mesh.vertices[:, 2])
    return LinearNDInterpolator(xy, z)


# --------------------------------------------------------------------------
# Health of a finished run

def layer_health(atoms, s: Scene, substrate_stl, expected_atoms: int) -> dict:
    """Check a final state: lost particles, particles through the substrate,
    overlaps (in the sampling region and anywhere), kinetic energy.
    Returns the figures; raises :class:`LiggghtsError` on a failure."""
    xyz = atoms[["x", "y", "z"]].to_numpy()
    radius = atoms["radius"].to_numpy()
    below = (xyz[:, 2] - substrate_height(substrate_stl)(xyz[:, 0], xyz[:, 1])) / radius
    pairs = cKDTree(xyz, boxsize=None).query_pairs(2 * radius.max(initial=0.0), output_type="ndarray")
    gaps = np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1) - radius[pairs].sum(1)
    overlaps = -gaps / radius[pairs].min(1)
    x0, x1, y0, y1 = s.sampling_region
    inside = ((xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1))[pairs].any(1)
    overlap = np.max(overlaps[inside], initial=0.0)
    overlap_anywhere = np.max(overlaps, initial=0.0)
    mass = s.density * 4 / 3 * np.pi * radius**3
    speed2 = (atoms[["vx", "vy", "vz"]].to_numpy() ** 2).sum(1)
    health = {"atoms": len(atoms), "lost": expected_atoms - len(atoms),
              "through_substrate": int(np.sum(np.nan_to_num(below, nan=0.0) < -BELOW_SUBSTRATE_RADII)),
              "max_overlap_fraction": float(overlap), "max_overlap_anywhere": float(overlap_anywhere),
              "kinetic_energy_J": float(0.5 * np.sum(mass * speed2)),
              "max_speed_m_s": float(np.sqrt(speed2.max(initial=0.0)))}
    problems = []
    if health["lost"]:
        problems.append(f"{health['lost']} particles lost (left the box)")
    if health["through_substrate"]:
        problems.append(f"{health['through_substrate']} particles fell through the substrate")
    if overlap > MAX_OVERLAP:
        problems.append(f"largest overlap in the sampling region {overlap:.1%} of a radius exceeds {MAX_OVERLAP:.0%}")
    if overlap_anywhere > MAX_OVERLAP_ANYWHERE:
        problems.append(f"largest overlap {overlap_anywhere:.1%} of a radius exceeds {MAX_OVERLAP_ANYWHERE:.0%}")
    if not np.all(np.isfinite(xyz)):
        problems.append("non-finite positions")
    if problems:
        raise LiggghtsError("unsound run: " + "; ".join(problems))
    return health


def squeeze_out_speed(density: float, youngs_modulus: float, poisson_ratio: float,
                      overlap_fraction: float = MAX_OVERLAP_ANYWHERE) -> float:
    """Speed [m/s] a sphere gets when the Hertz energy of an overlap of
    ``overlap_fraction`` of its radius against a wall of its own material is
    released into its translation.

    ``W = 8/15 E* sqrt(r) d^(5/2)`` with ``d = f r`` and ``E* = E / (2 (1 - nu^2))``,
    over ``m = 4/3 pi rho r^3``: ``v = sqrt(4 E* f^(5/2) / (5 pi rho))``, the same for
    every radius. SI units.
    """
    effective_modulus = youngs_modulus / (2.0 * (1.0 - poisson_ratio**2))
    return sqrt(4.0 * effective_modulus * overlap_fraction**2.5 / (5.0 * pi * density))


def check_kinetic_energy(log: dict, wall_speed: float = 0.0, squeeze_speed: float = 0.0) -> dict:
    """Refuse a run whose thermo output shows a non-finite kinetic energy or a
    particle faster than the blow-up limit: the largest of BLOWUP_FLOOR_M_S,
    BLOWUP_SPEED_FACTOR x ``wall_speed`` [m/s] (the fastest wall, the roller's
    surface) and ``squeeze_speed`` [m/s] (``squeeze_out_speed``). Returns the
    peak particle speed [m/s]."""
    thermo = log["thermo"]
    limit = max(BLOWUP_FLOOR_M_S, BLOWUP_SPEED_FACTOR * wall_speed, squeeze_speed)
    energy, vmax = thermo["KinEng"].to_numpy(), thermo["vmax"].to_numpy()
    bad = ~np.isfinite(energy) | ~np.isfinite(vmax)
    if bad.any():
        raise LiggghtsError(f"unsound run: kinetic energy not finite at step {int(thermo['Step'][bad].iloc[0])}")
    fast = vmax > limit
    if fast.any():
        first = np.argmax(fast)
        raise LiggghtsError(f"unsound run: kinetic-energy blow-up, a particle at {vmax[first]:.3g} m/s at step "
                            f"{int(thermo['Step'].iloc[first])} (limit {limit:.3g} m/s = max({BLOWUP_FLOOR_M_S:g}, "
                            f"{BLOWUP_SPEED_FACTOR} x the fastest wall's {wall_speed:.3g} m/s, squeeze-out "
                            f"{squeeze_speed:.3g} m/s)): lower the time step")
    return {"peak_speed_m_s": float(vmax.max(initial=0.0))}


def through_roller(atoms, axis_x: float, axis_z: float, radius: float) -> int:
    """Particles whose centre is inside the roller (axis along y at ``axis_x``,
    ``axis_z`` [m], ``radius`` [m]): they passed through its surface."""
    distance = np.hypot(atoms["x"].to_numpy() - axis_x, atoms["z"].to_numpy() - axis_z)
    return int(np.sum(distance < radius))


def _publish(out: Path, summary: dict, *names: str) -> None:
    """Rename the run's ``<name>.part`` files to ``<name>``, then write
    ``health.json``: a run killed or refused earlier leaves nothing that looks finished."""
    for name in names:
        os.replace(out / f"{name}.part", out / name)
    (out / "health.json.part").write_text(json.dumps(summary, indent=2))
    os.replace(out / "health.json.part", out / "health.json")


def heap_supply(ahead: int, heap_particles: int) -> dict:
    """Powder left ahead of the roller when it stops, ``run_out_mm`` past the
    sampling region (``ahead`` particles of a heap of ``heap_particles``).

    ``supply_margin`` is that share of the heap; none left (``heap_exhausted``)
    means the heap ran out before the roller reached the end of the sampling
    region (forward rolling lays several layers and eats a small heap): the
    layer there is supply-limited, its M_s and Q_s lower bounds of the scene's
    physics."""
    return {"particles_ahead_of_roller": int(ahead), "supply_margin": ahead / heap_particles,
            "heap_exhausted": ahead == 0}


def _check_timestep(log: dict, s: Scene) -> None:
    if log["max_rayleigh_fraction"] > s.max_rayleigh_fraction * (1 + 1e-6):
        raise LiggghtsError(f"time step is {log['max_rayleigh_fraction']:.3f} of the Rayleigh time, above "
                            f"timestep.max_rayleigh_fraction = {s.max_rayleigh_fraction}")


# --------------------------------------------------------------------------
# Settle and spread

def settle(config: dict, level: str, meshes: str | Path, outdir: str | Path, replicate: int = 0,
           max_steps: int | None = None) -> dict:
    """Insert the heap and let it settle on the substrate; writes ``settled.restart``,
    ``settled.dump``, ``settle.in``, ``settle.log`` and ``health.json`` into ``outdir``.

    ``max_steps`` cuts each settling phase to that many steps: a start-up check
    of a big scene (benchmarks/bench_scaling.py), not a settled heap."""
    s, out, meshes = scene(config, level), Path(outdir), Path(meshes).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if s.timestep > s.max_rayleigh_fraction * s.rayleigh_time:
        raise LiggghtsError(f"time step {s.timestep:.3g} s exceeds the allowed fraction of the Rayleigh time")
    text = render("settle.in.j2", s=s, contact=contact_model(s), seeds=seeds(config, s, replicate), box=[f"{v:.6g}" for v in s.box],
                  processors=processors_grid(s),
                  skin=skin(s), binsize=binsize(s), thermo_every=THERMO_EVERY,
                  **(rest_loop(s, s.settle_time) if max_steps is None else
                     {**rest_loop(s, s.settle_time), "chunk_steps": max_steps, "max_chunks": 1}),
                  substrate_stl=meshes / "substrate.stl", restart="settled.restart.part", dump="settled.dump.part",
                  stray_x=s.sampling_region[0] - max(s.diameters), max_strays=MAX_STRAYS)
    (out / "settle.in").write_text(text)
    log = run(out / "settle.in", out / "settle.log", ranks=s.mpi_ranks)
    _check_timestep(log, s)
    peak = check_kinetic_energy(log, squeeze_speed=squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio))
    if log["inserted"] != s.heap_particles:
        raise LiggghtsError(f"inserted {log['inserted']} of {s.heap_particles} particles: the heap region is too "
                            "small for heap_particles (see fidelity level)")
    atoms = read_dump(out / "settled.dump.part").atoms
    before_strays = int(log["thermo"]["Atoms"].iloc[-2])  # the last row is the `run 0` after delete_atoms
    strays = before_strays - len(atoms)
    if strays > MAX_STRAYS * s.heap_particles:
        raise LiggghtsError(f"{strays} of {s.heap_particles} particles rolled ahead of the slumped heap into the "
                            f"sampling region (from {s.sampling_region[0] * 1e3:.2f} mm; at most "
                            f"{MAX_STRAYS:.0%} may): raise fidelity.{level}.sampling_start_mm or heap_length_mm")
    health = layer_health(atoms, s, meshes / "substrate.stl", s.heap_particles - strays)
    health["strays_removed"] = strays
    health["heap_toe_m"] = float(atoms["x"].max() + atoms["radius"].max())
    summary = {"wall_s": log["wall_s"], "cpu_s": log["cpu_s"], "steps": int(log["thermo"]["Step"].iloc[-1]),
               "timestep_s": s.timestep, "rayleigh_fraction": log["max_rayleigh_fraction"],
               "hertz_fraction": log["max_hertz_fraction"], "inserted": log["inserted"], **peak, **health}
    _publish(out, summary, "settled.restart", "settled.dump")
    return summary


def roller_start(atoms, s: Scene, clearance: float | None = None) -> float:
    """x [m] of the roller axis just behind the settled heap (no particle touched).

    For each particle, the axis at height ``gap + R`` must stay ``R + r + clearance``
    away; the start is the smallest such x over all particles.
    """
    clearance = 0.2 * min(s.diameters) if clearance is None else clearance
    zc = s.roller_gap + s.roller_radius
    reach = s.roller_radius + atoms["radius"].to_numpy() + clearance
    dz = np.minimum(np.abs(atoms["z"].to_numpy() - zc), reach)
    return float(np.min(atoms["x"].to_numpy() - np.sqrt(reach**2 - dz**2)))


CHECKPOINT_DIR = "checkpoint"


def processors_grid(s: Scene) -> str:
    """LIGGGHTS ``processors`` grid for ``s.mpi_ranks`` ranks.

    The powder is a thin bed under a box as tall as the roller, so z is never
    split. LIGGGHTS 3.8 has no load balancing (no ``balance`` command), and
    along the travel the particles crowd into the heap: a cut across x leaves
    ranks idle. A narrow periodic strip is uniform across its width, so it is
    cut across y into equal shares, each at least the ghost cutoff (largest
    diameter + skin) wide; a wide scene (the paper level) lets LIGGGHTS
    choose the grid in x and y.
    """
    slab = max(s.diameters) + skin(s)  # the ghost cutoff
    if s.mpi_ranks <= 1:
        return "1 1 1"
    if s.strip_width / s.mpi_ranks >= slab and s.strip_width < 0.1 * (s.box[1] - s.box[0]):
        return f"1 {s.mpi_ranks} 1"
    return "* * 1"


def _checkpoints(out: Path, fingerprint: str) -> list[tuple[int, Path]]:
    """(step, restart file) of an earlier, killed attempt at this same input, newest first."""
    folder = out / CHECKPOINT_DIR
    stamp = folder / "input.sha256"
    if not stamp.is_file() or stamp.read_text() != fingerprint:
        return []
    found = [(int(p.name.split(".")[1]), p) for p in folder.glob("travel.*.restart")]
    return sorted(found, reverse=True)


def checkpoint_plan(travel_steps: int, count: int, resume_step: int = 0) -> list[tuple[int, int | None]]:
    """(step, previous checkpoint's step) of the checkpoints still to write after ``resume_step``:
    ``count`` evenly spaced over the travel (none at its end)."""
    if not count:
        return []
    every = ceil(travel_steps / (count + 1))
    steps = [k * every for k in range(1, count + 1) if resume_step < k * every < travel_steps]
    return list(zip(steps, [resume_step or None] + steps[:-1]))


#: Travel [m] of the roller between two top-ups of a fed pile (``feed_pile_mg_per_mm``):
#: the pile dips by at most the layer laid over it (about 2 % of a 20 mg/mm pile).
FEED_EVERY = 0.5e-3


def feed_plan(s: Scene, x0: float, speed: float, travel_steps: int, heap_toe: float) -> list[int]:
    """Steps of the travel at which a fed pile is topped up: every :data:`FEED_EVERY`
    of travel, from the step at which the feed zone (``s.feed_length`` ahead of the
    roller axis, which starts at ``x0`` [m]) first covers the settled heap's toe
    ``heap_toe`` [m], so the heap itself is counted before anything is added.
    Empty without a feed."""
    if s.feed_pile_mass is None:
        return []
    every = max(1, round(FEED_EVERY / (speed * s.timestep)))
    first = max(0, ceil((heap_toe - s.feed_length - x0) / (speed * s.timestep)))
    return list(range(first, travel_steps, every))


def feed_zone(s: Scene, x_axis: float, floor: float) -> dict:
    """The feed zone [m] when the roller axis is at ``x_axis``: a block from the axis
    to ``s.feed_length`` ahead, from ``floor`` (above the substrate's highest point)
    to the roller's height there, less a cylinder of the roller's radius plus the
    largest particle's (nothing is inserted into the roller or the substrate)."""
    r = s.roller_radius
    top = s.roller_gap + r - sqrt(r**2 - s.feed_length**2)
    return {"x0": x_axis, "x1": x_axis + s.feed_length, "z0": floor, "z1": top,
            "axis_z": s.roller_gap + r, "radius": r + max(s.diameters) / 2}


def travel_segments(travel_steps: int, checkpoints: list, feeds: list, resume_step: int = 0) -> list[dict]:
    """The travel after ``resume_step`` cut at every checkpoint and feed step: a list of
    ``{"end", "feed", "checkpoint"}`` in order; ``feed`` is true if the pile is topped up at
    the segment's start, ``checkpoint`` the ``(step, previous)`` written at its end or None."""
    at_end = {step: (step, previous) for step, previous in checkpoints}
    feeds = [f for f in feeds if f >= resume_step]
    cuts = sorted(set(at_end) | {f for f in feeds if f > resume_step} | {travel_steps})
    segments, start = [], resume_step
    for end in cuts:
        segments.append({"start": start, "end": end, "feed": start in feeds, "checkpoint": at_end.get(end)})
        start = end
    return segments


#: What a spreading run leaves out because its scene does not need it (README:
#: skips): the wait for a fixed duration once the layer is at rest, the powder
#: pushed past the stopped roller, and every dump but the final one. (Settling
#: once per replicate is the workflow's: rules/simulate.smk.) The empty set is
#: the "no skips" baseline of benchmarks/bench_skips.py.
SKIPS = frozenset({"stop_at_rest", "remove_ahead", "final_dump_only"})
#: Dump interval [s of simulated time] of the baseline without ``final_dump_only``.
BASELINE_DUMP_EVERY_S = 0.002


def spread(config: dict, level: str, U_mm_s: float, omega_rad_s: float, meshes: str | Path,
           settled: str | Path, outdir: str | Path, movie_every: int = 0, skips=SKIPS, replicate: int = 0) -> dict:
    """Spread the settled heap at ``U_mm_s`` [mm/s] and ``omega_rad_s`` [rad/s].

    Writes ``spread.in``, ``spread.log``, ``final.dump`` and ``health.json``
    into ``outdir`` and returns the health figures (with wall time and steps).

    With ``checkpoints_per_run`` > 0 in the fidelity level, LIGGGHTS writes
    restart files to ``outdir/checkpoint/`` during the travel; a later call
    for the same input (same rendered text) resumes from the newest one that
    loads, e.g. after a cluster's time limit killed the job. Continuing the
    roller's motion from a restart is LIGGGHTS' own (``fix move/mesh`` stores
    it); a checkpoint that fails to load is skipped, and the run starts over.

    With ``feed_pile_mg_per_mm`` in the fidelity level, the pile ahead of the
    roller is topped up to that mass every :data:`FEED_EVERY` of travel
    (:func:`feed_plan`, :func:`feed_zone`): the layer is laid from a pile of
    a set size, however much the roller lays; ``fed_particles`` in the
    health counts what was added. ``replicate`` seeds the feed.
    """
    s, out = scene(config, level), Path(outdir)
    meshes, settled = Path(meshes).resolve(), Path(settled).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if U_mm_s <= 0:
        raise ConfigError(f"spreader speed U = {U_mm_s} mm/s must be positive")
    speed = U_mm_s * 1e-3
    atoms0 = read_dump(settled / "settled.dump").atoms
    x0 = roller_start(atoms0, s)
    if x0 - s.roller_radius <= s.box[0]:
        raise LiggghtsError(f"roller start x = {x0:.4g} m puts the roller outside the box (x >= {s.box[0]:.4g} m)")
    travel_time = (s.travel_end - x0) / speed
    travel_steps = ceil(travel_time / s.timestep)
    unknown = set(skips) - SKIPS
    if unknown:
        raise ValueError(f"unknown skip(s) {sorted(unknown)}; known: {sorted(SKIPS)}")
    if not movie_every and "final_dump_only" not in skips:
        movie_every = max(1, round(BASELINE_DUMP_EVERY_S / s.timestep))
    motion = roller_motion(speed, omega_rad_s, s.roller_radius)
    heap_toe = float((atoms0["x"] + atoms0["radius"]).max())
    feeds = feed_plan(s, x0, speed, travel_steps, heap_toe)
    feed = None
    if feeds:
        floor = float(geometry.load_stl(meshes / "substrate.stl").vertices[:, 2].max()) + max(s.diameters) / 2
        feed_seeds = liggghts_seeds(config["random_seed"] + 1000 * replicate + 500, len(s.diameters) + 1 + len(feeds))
        feed = {"mass": s.feed_pile_mass, "floor": floor, "template_seeds": feed_seeds[:len(s.diameters) + 1],
                "seeds": dict(zip(feeds, feed_seeds[len(s.diameters) + 1:]))}
    context = dict(s=s, contact=contact_model(s), box=[f"{v:.6g}" for v in s.box], U_mm_s=U_mm_s,
                   omega_rad_s=omega_rad_s, motion=motion, restart=settled / "settled.restart", skin=skin(s),
                   binsize=binsize(s), thermo_every=THERMO_EVERY, processors=processors_grid(s),
                   substrate_stl=meshes / "substrate.stl", roller_stl=meshes / "roller_shell.stl",
                   roller_z=s.roller_gap + s.roller_radius, travel_steps=travel_steps,
                   **rest_loop(s, s.rest_time, stop_at_rest="stop_at_rest" in skips),
                   travel_end=s.travel_end, remove_ahead="remove_ahead" in skips,
                   movie_every=movie_every, movie="movie.dump",
                   dump="final.dump.part", checkpoint_dir=CHECKPOINT_DIR)

    def render_from(step: int, restart: Path | None) -> str:
        """The input starting at ``step`` of the travel (0: from the settled heap)."""
        elapsed = step * s.timestep
        segments = travel_segments(travel_steps, checkpoint_plan(travel_steps, s.checkpoints_per_run, step), feeds,
                                   step)
        for seg in segments:
            if seg["feed"]:
                seg["zone"] = feed_zone(s, x0 + speed * seg["start"] * s.timestep, feed["floor"])
                seg["seed"] = feed["seeds"][seg["start"]]
        return render("spread.in.j2", resume=restart, resume_step=step, sfx="_resumed" if step else "",
                      roller_x=x0 + speed * elapsed, roller_angle_deg=np.degrees(abs(omega_rad_s) * elapsed) % 360,
                      segments=segments, feed=feed, **context)

    fresh = render_from(0, None)
    fingerprint = hashlib.sha256(fresh.encode()).hexdigest()
    for step, restart in _checkpoints(out, fingerprint) + [(0, None)]:
        if restart is None:  # a fresh start: forget any other input's checkpoints
            shutil.rmtree(out / CHECKPOINT_DIR, ignore_errors=True)
            (out / CHECKPOINT_DIR).mkdir()
            (out / CHECKPOINT_DIR / "input.sha256").write_text(fingerprint)
        (out / "spread.in").write_text(fresh if restart is None else render_from(step, restart))
        try:
            log = run(out / "spread.in", out / "spread.log", ranks=s.mpi_ranks)
            break
        except LiggghtsError as err:
            if restart is None:
                raise
            print(f"warning: resuming from {restart} failed, trying an older checkpoint or a fresh start:\n{err}",
                  file=sys.stderr)
    _check_timestep(log, s)
    health = check_kinetic_energy(log, wall_speed=speed + abs(omega_rad_s) * s.roller_radius,
                                  squeeze_speed=squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio))
    atoms = read_dump(out / "final.dump.part").atoms
    inside = through_roller(atoms, x0 + speed * travel_steps * s.timestep, context["roller_z"], s.roller_radius)
    if inside:
        raise LiggghtsError(f"unsound run: {inside} particles passed through the roller (centre inside it): "
                            "lower the time step or stiffen the particles")
    ahead = int(log["printed"]["particles_ahead_of_roller"])
    # the powder ahead of the stopped roller, and what rolled on under it during the rest phase
    removed = ahead + int(log["printed"]["escaped_past_roller"]) if "remove_ahead" in skips else 0
    # particles fed before a resumed attempt are in its first thermo row
    fed = int(log["thermo"]["Atoms"].iloc[0]) - len(atoms0) + int(log["inserted"])
    health.update(through_roller=inside, fed_particles=fed,
                  **layer_health(atoms, s, meshes / "substrate.stl", len(atoms0) + fed - removed))
    health.update(heap_supply(ahead, s.heap_particles), removed_ahead_of_roller=removed,
                  mass_ahead_of_roller_kg=float(log["printed"]["mass_ahead_of_roller_kg"]))
    thermo = log["thermo"]
    first, last = int(thermo["Step"].iloc[0]), int(thermo["Step"].iloc[-1])
    summary = {"U_mm_s": U_mm_s, "omega_rad_s": omega_rad_s, "wall_s": log["wall_s"], "cpu_s": log["cpu_s"],
               "steps": last, "resumed_from_step": first, "timestep_s": s.timestep, "ranks": s.mpi_ranks,
               "processors": context["processors"],
               "roller_start_m": x0, "roller_travel_m": speed * travel_steps * s.timestep,
               "rayleigh_fraction": log["max_rayleigh_fraction"], "hertz_fraction": log["max_hertz_fraction"],
               "particle_steps_per_s": len(atoms) * (last - first) / log["wall_s"],
               **health}
    _publish(out, summary, "final.dump")
    shutil.rmtree(out / CHECKPOINT_DIR, ignore_errors=True)
    return summary


# --------------------------------------------------------------------------

def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Run one step of a spreading scene with LIGGGHTS.")
    parser.add_argument("step", choices=["geometry", "settle", "spread"])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--level", help="fidelity level (default: the config's `level`)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--meshes", type=Path)
    parser.add_argument("--settled", type=Path)
    parser.add_argument("--U", type=float, help="spreader translation speed, mm/s")
    parser.add_argument("--omega", type=float, help="roller angular speed, rad/s (+: counter-rotation)")
    parser.add_argument("--replicate", type=int, default=0, help="replicate: its heap, substrate and feed seeds")
    args = parser.parse_args(argv)
    try:
        config = load_config(args.config)
        level = args.level or config["level"]
        if args.step == "geometry":
            result = make_geometry(config, level, args.out, base_dir=args.config.parent, replicate=args.replicate)
        elif args.step == "settle":
            result = settle(config, level, args.meshes, args.out, replicate=args.replicate)
        else:
            if args.U is None or args.omega is None:
                parser.error("spread needs --U and --omega")
            result = spread(config, level, args.U, args.omega, args.meshes, args.settled, args.out,
                            replicate=args.replicate)
    except (ConfigError, LiggghtsError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2 if isinstance(err, ConfigError) else 1
    print(json.dumps(result, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
