"""Is a finished LIGGGHTS run sound? Lost, sunk and squeezed-through
particles, overlaps, kinetic-energy blow-ups against the squeeze-out speed,
the time step against the Rayleigh time, and the supply still ahead of the
roller. :mod:`analysis.dem.simulate` calls these after each run and refuses
an unsound one (:class:`~analysis.dem.liggghts.LiggghtsError`).
"""
from __future__ import annotations

from math import pi, sqrt
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import RegularGridInterpolator
from scipy.spatial import cKDTree

from analysis.config.fidelity import Scene
from analysis.dem import geometry
from analysis.dem.liggghts import LiggghtsError, UnstableRunError
from analysis.metrics.dump import read_dump
from analysis.metrics.profilometer import substrate_height
from analysis.physics import MAX_OVERLAP

#: A particle counts as "through the substrate" when its centre is this many
#: radii below the substrate surface under it.
BELOW_SUBSTRATE_RADII = 0.5


#: Largest tolerated particle-particle overlap anywhere, as a fraction of the smaller radius
#: (in the sampling region: :data:`analysis.physics.MAX_OVERLAP`), outside the stopped roller's nip
#: (:func:`layer_health`), where the kinematic roller squeezes the powder it stops on (62 % seen with
#: the calibrated powder at U = 70 mm/s, omega = -5 rad/s); past 50 % spheres pass through each other.
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
#: Checked on the thermo output during the run (every THERMO_EVERY steps; the run
#: is stopped at the first line past it), not only on the final state.
BLOWUP_SPEED_FACTOR = 10


BLOWUP_FLOOR_M_S = 2.0


#: Largest share of the heap that may roll ahead, to the sampling region, while
#: it slumps; these strays are removed before the spread (more: a scene error).
MAX_STRAYS = 0.01


#: The surface under scattered points is the profilometer's on a grid this many times
#: finer than the mesh's vertex lines, bilinear in between: within 2 um of the mesh's own
#: triangles on the default substrate (Sq 79 um, 100 um vertex spacing).
SURFACE_REFINE = 8


def substrate_height_at(substrate_stl: str | Path):
    """A vectorised z(x, y) [m] of a height-field STL at scattered points (particle centres).

    The surface is the profilometer's (:func:`analysis.metrics.profilometer.substrate_height`:
    the mesh's highest triangle over a point), evaluated on a grid :data:`SURFACE_REFINE`
    times finer than the mesh's vertex lines and interpolated bilinearly in between, so
    the health checks and the layer metrics see one substrate. Outside the mesh it is
    extrapolated linearly.
    """
    mesh = geometry.load_stl(substrate_stl)
    lines = []
    for axis in (0, 1):
        v = np.unique(mesh.vertices[:, axis].round(12))
        if len(v) > 4000:  # an irregular scan: a uniform grid instead of its vertex lines
            v = np.linspace(v[0], v[-1], 4000)
        fine = np.append((v[:-1, None] + np.diff(v)[:, None] * np.arange(SURFACE_REFINE) / SURFACE_REFINE).ravel(),
                         v[-1])
        fine[[0, -1]] += [1e-9, -1e-9]  # probes on the mesh's outer edge count as covered
        lines.append(fine)
    surface = RegularGridInterpolator(lines, substrate_height(mesh, *lines), bounds_error=False, fill_value=None)
    return lambda x, y: surface(np.column_stack([np.ravel(x), np.ravel(y)])).reshape(np.shape(x))


def layer_health(atoms, s: Scene, substrate_stl, expected_atoms: int, roller: tuple | None = None) -> dict:
    """Check a final state: lost particles, particles through the substrate,
    overlaps (in the sampling region and anywhere), kinetic energy.

    ``roller``: the stopped roller's ``(axis_x, axis_z, radius)`` [m]. Pairs with a particle in its
    nip (centre within a largest diameter of its surface, below its axis) are left out of the
    check anywhere and reported as ``max_overlap_nip``: the kinematic roller squeezes the powder
    it stops on as hard as it squeezes the nip during a run, where overlaps past a radius are
    recorded, not refused (``inrun_max_overlap_fraction``).
    Returns the figures; raises :class:`LiggghtsError` on a failure."""
    xyz = atoms[["x", "y", "z"]].to_numpy()
    radius = atoms["radius"].to_numpy()
    below = (xyz[:, 2] - substrate_height_at(substrate_stl)(xyz[:, 0], xyz[:, 1])) / radius
    pairs = cKDTree(xyz, boxsize=None).query_pairs(2 * radius.max(initial=0.0), output_type="ndarray")
    gaps = np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1) - radius[pairs].sum(1)
    overlaps = -gaps / radius[pairs].min(1)
    x0, x1, y0, y1 = s.sampling_region
    inside = ((xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1))[pairs].any(1)
    overlap = np.max(overlaps[inside], initial=0.0)
    in_nip = np.zeros(len(xyz), dtype=bool)
    if roller is not None:
        axis_x, axis_z, roller_radius = roller
        from_axis = np.hypot(xyz[:, 0] - axis_x, xyz[:, 2] - axis_z)
        in_nip = (from_axis < roller_radius + 2 * radius.max(initial=0.0)) & (xyz[:, 2] < axis_z)
    nip_pair = in_nip[pairs].any(1)
    overlap_anywhere = np.max(overlaps[~nip_pair], initial=0.0)
    overlap_nip = np.max(overlaps[nip_pair], initial=0.0)
    mass = s.density * 4 / 3 * np.pi * radius**3
    speed2 = (atoms[["vx", "vy", "vz"]].to_numpy() ** 2).sum(1)
    health = {"atoms": len(atoms), "lost": expected_atoms - len(atoms),
              "through_substrate": int(np.sum(np.nan_to_num(below, nan=0.0) < -BELOW_SUBSTRATE_RADII)),
              "max_overlap_fraction": float(overlap), "max_overlap_anywhere": float(overlap_anywhere),
              "max_overlap_nip": float(overlap_nip),
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


def blowup_limit(wall_speed: float = 0.0, squeeze_speed: float = 0.0) -> float:
    """The blow-up limit [m/s]: the largest of BLOWUP_FLOOR_M_S, BLOWUP_SPEED_FACTOR x
    ``wall_speed`` [m/s] (the fastest wall, the roller's surface) and ``squeeze_speed`` [m/s]
    (``squeeze_out_speed``). :func:`analysis.dem.liggghts.run` stops a run at the first thermo
    line past it; :func:`check_kinetic_energy` judges the finished log by it."""
    return max(BLOWUP_FLOOR_M_S, BLOWUP_SPEED_FACTOR * wall_speed, squeeze_speed)


def check_kinetic_energy(log: dict, wall_speed: float = 0.0, squeeze_speed: float = 0.0) -> dict:
    """Refuse a run whose thermo output shows a non-finite kinetic energy or a
    particle faster than the blow-up limit: the largest of BLOWUP_FLOOR_M_S,
    BLOWUP_SPEED_FACTOR x ``wall_speed`` [m/s] (the fastest wall, the roller's
    surface) and ``squeeze_speed`` [m/s] (``squeeze_out_speed``). Returns the
    peak particle speed [m/s]."""
    thermo = log["thermo"]
    limit = blowup_limit(wall_speed, squeeze_speed)
    energy, vmax = thermo["KinEng"].to_numpy(), thermo["vmax"].to_numpy()
    bad = ~np.isfinite(energy) | ~np.isfinite(vmax)
    if bad.any():
        raise UnstableRunError(f"unsound run: kinetic energy not finite at step {int(thermo['Step'][bad].iloc[0])}")
    fast = vmax > limit
    if fast.any():
        first = np.argmax(fast)
        raise UnstableRunError(f"unsound run: kinetic-energy blow-up, a particle at {vmax[first]:.3g} m/s at step "
                               f"{int(thermo['Step'].iloc[first])} (limit {limit:.3g} m/s = max({BLOWUP_FLOOR_M_S:g}, "
                               f"{BLOWUP_SPEED_FACTOR} x the fastest wall's {wall_speed:.3g} m/s, squeeze-out "
                               f"{squeeze_speed:.3g} m/s)): lower the time step")
    return {"peak_speed_m_s": float(vmax.max(initial=0.0))}


#: A squeeze-out: a particle faster than this many times the roller's fastest surface speed
#: (U + |omega| R), and than a fall from the top of the feed zone (``squeeze_threshold``).
SQUEEZE_FACTOR = 3.0


def squeeze_threshold(wall_speed: float, fall_height: float) -> float:
    """Speed [m/s] above which a particle counts as squeezed out of the nip:
    :data:`SQUEEZE_FACTOR` x ``wall_speed`` [m/s], and at least the speed of a free fall
    from ``fall_height`` [m] (a fed particle landing on the pile is no squeeze-out)."""
    return max(SQUEEZE_FACTOR * wall_speed, sqrt(2 * 9.81 * max(fall_height, 0.0)))


def inrun_health(log: dict, s: Scene) -> dict:
    """Overlaps and squeeze-outs during the run, from the thermo lines (every
    ``THERMO_EVERY`` steps) of ``spread.in.j2``: the largest particle-particle and
    particle-wall (substrate or roller) overlap [um] and as a fraction of the smallest
    particle's radius, the most squeeze-outs in one sample and the samples with any."""
    thermo, r_min = log["thermo"], min(s.diameters) / 2
    if "ovpp" not in thermo:
        return {}
    pp = float(np.nanmax(thermo["ovpp"].to_numpy(), initial=0.0))
    wall = float(np.nanmax(thermo["ovwall"].to_numpy(), initial=0.0))
    squeezed = thermo["squeezed"].to_numpy()
    return {"inrun_max_overlap_um": pp * 1e6, "inrun_max_overlap_fraction": pp / r_min,
            "inrun_max_wall_overlap_um": wall * 1e6, "inrun_max_wall_overlap_fraction": wall / r_min,
            "squeeze_outs_max": int(np.nanmax(squeezed, initial=0)),
            "squeeze_out_samples": int(np.sum(squeezed > 0))}


def feed_landings(folder: Path, printed: dict, roller_x, landed_at: dict) -> pd.DataFrame:
    """Where each fed particle landed: one row per particle of the top-up dumps
    ``folder/landed.<step>.dump`` (written by ``spread.in.j2`` at the next top-up or the
    travel's end, step ``landed_at[step]``).

    ``roller_x(step)`` is the roller axis' x [m] at a step. Columns: ``id``, ``topup_step``,
    ``x_landed_m``, ``radius_m``, ``front_m`` (the pile's front measured at the top-up),
    ``front_at_landing_m`` (the pile's front when the landing was written down: ``front_m``
    carried on by the roller's travel since, or the next top-up's measured front where the pile
    has slumped further forward than that), ``ahead_of_front_m`` (landed x less
    ``front_at_landing_m``: powder on a pile that slumps forward goes with it, a sphere rolled
    onto bare bed lies ahead of it) and ``ahead_of_roller_m`` (landed x less the
    roller axis' x when it was written down). A run resumed from a checkpoint has the dumps its
    killed attempt wrote, but their fronts (NaN) only where its own log printed them."""
    rows = []
    for path in sorted(Path(folder).glob("landed.*.dump"), key=lambda p: int(p.name.split(".")[1])):
        step = int(path.name.split(".")[1])
        atoms = read_dump(path).atoms
        end = landed_at[step]
        # a top-up before a resumed attempt printed its front in the killed attempt's log
        front = printed.get(f"feed_front_{step}", np.nan)
        carried = front + roller_x(end) - roller_x(step)
        front_then = np.fmax(printed.get(f"feed_front_{end}", carried), carried)
        rows.append(pd.DataFrame({
            "id": atoms["id"].to_numpy(), "topup_step": step, "x_landed_m": atoms["x"].to_numpy(),
            "radius_m": atoms["radius"].to_numpy(), "front_m": front, "front_at_landing_m": front_then,
            "ahead_of_front_m": atoms["x"].to_numpy() - front_then,
            "ahead_of_roller_m": atoms["x"].to_numpy() - roller_x(end)}))
    columns = ["id", "topup_step", "x_landed_m", "radius_m", "front_m", "front_at_landing_m", "ahead_of_front_m",
               "ahead_of_roller_m"]
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=columns)


def fed_in_region(atoms, first_fed_id: int, region: tuple) -> tuple:
    """Masks of the particles whose centres lie over ``region`` (x0, x1, y0, y1 [m]) and of those
    of them the feed added (ids from ``first_fed_id``: the feed numbers its particles after the
    settled heap's)."""
    x0, x1, y0, y1 = region
    x, y = atoms["x"].to_numpy(), atoms["y"].to_numpy()
    inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    return inside, inside & (atoms["id"].to_numpy() >= first_fed_id)


def fed_share(atoms, first_fed_id: int, region: tuple) -> float:
    """Share of the particles over ``region`` (x0, x1, y0, y1 [m]) that the feed added; 0 if none."""
    inside, fed = fed_in_region(atoms, first_fed_id, region)
    return float(fed.sum() / max(inside.sum(), 1))


def feed_health(landings: pd.DataFrame, atoms, first_fed_id: int, region: tuple) -> dict:
    """What the feed did to the measured layer: the farthest any fed particle landed ahead
    of the pile's front [mm], the share of the final layer in the sampling ``region``
    (x0, x1, y0, y1 [m]) that was fed (ids from ``first_fed_id``), and how far ahead of the
    roller those fed particles had landed (median and largest, mm)."""
    _, fed = fed_in_region(atoms, first_fed_id, region)
    in_layer = landings[landings["id"].isin(atoms["id"].to_numpy()[fed])]
    ahead = in_layer["ahead_of_roller_m"].to_numpy() * 1e3
    ahead_of_front = landings["ahead_of_front_m"].dropna()
    return {"fed_max_ahead_of_front_mm": float(ahead_of_front.max() * 1e3) if len(ahead_of_front) else 0.0,
            "fed_share_of_region_layer": fed_share(atoms, first_fed_id, region),
            "fed_in_region_landed_ahead_of_roller_mm_median": float(np.median(ahead)) if len(ahead) else 0.0,
            "fed_in_region_landed_ahead_of_roller_mm_max": float(ahead.max()) if len(ahead) else 0.0}


def feed_pile_fraction(printed: dict, pile_mass: float) -> float:
    """The lightest the pile was when a top-up weighed it, over the mass it is held at
    (``feed_pile_kg_<step>`` lines of the spread's log over ``pile_mass`` [kg]; NaN when no top-up
    was printed). Well below 1: the feed could not place what the pile lacked (LIGGGHTS' "Less
    insertions than requested"), so the layer was laid from a shrinking pile."""
    weighed = [v for k, v in printed.items() if k.startswith("feed_pile_kg_")]
    return float(min(weighed) / pile_mass) if weighed else float("nan")


def through_roller(atoms, axis_x: float, axis_z: float, radius: float) -> int:
    """Particles whose centre is inside the roller (axis along y at ``axis_x``,
    ``axis_z`` [m], ``radius`` [m]): they passed through its surface."""
    distance = np.hypot(atoms["x"].to_numpy() - axis_x, atoms["z"].to_numpy() - axis_z)
    return int(np.sum(distance < radius))


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


def check_timestep(log: dict, s: Scene) -> None:
    """Refuse a run whose measured time step (the log's ``measured_max_rayleigh_fraction``, LIGGGHTS'
    ``check/timestep/gran``) exceeds the scene's limit, ``timestep.max_rayleigh_fraction``."""
    if log["measured_max_rayleigh_fraction"] > s.max_rayleigh_fraction * (1 + 1e-6):
        raise LiggghtsError(f"time step is {log['measured_max_rayleigh_fraction']:.3f} of the Rayleigh time, above "
                            f"timestep.max_rayleigh_fraction = {s.max_rayleigh_fraction}")
