"""The virtual powder's characterisation tests in LIGGGHTS: a static angle of repose
(GranuHeap-like: a tube filled on a round base, then removed) and a poured bulk density
(a cup filled by a loose rain, struck off at its rim).

Both run the spreading scene's material, PSD and contact (``templates/_physics.j2``
through :func:`analysis.config.fidelity.scene`), from ``templates/repose.in.j2`` and
``templates/bulk_density.in.j2``, and are measured here from their final dump with
vectorised numpy (no loop over particles). docs/calibration.md says what they measure
and how big they must be.
"""
from __future__ import annotations

from math import ceil, pi, radians, tan
from pathlib import Path

import numpy as np
import trimesh

from analysis.config.fidelity import scene
from analysis.dem import geometry
from analysis.dem.health import check_kinetic_energy, check_timestep, squeeze_out_speed
from analysis.dem.inputs import THERMO_EVERY, contact_model, rest_loop, skin
from analysis.dem.liggghts import LiggghtsError, input_path, render, run
from analysis.io import write_json
from analysis.metrics.dump import read_dump
from analysis.physics import liggghts_seeds, number_mean_volume

#: Solid fraction of the loose insertion block (particles rain from it and settle): the heap's tube,
#: and the cup's (looser: a cup only a few large diameters wide packs its insertion block poorly).
INSERT_SOLID_FRACTION = 0.3
CUP_INSERT_SOLID_FRACTION = 0.2
#: Solid fraction assumed of the settled powder when sizing a fill.
SETTLED_SOLID_FRACTION = 0.6
#: The heap test's tube holds this many times the solid volume of a cone of HEAP_SIZING_ANGLE
#: on the base: a heap up to about 56 degrees still finds enough powder to cover the base.
HEAP_EXCESS = 1.5
HEAP_SIZING_ANGLE_DEG = 45.0
#: The cup is filled with this many times the powder it holds at SETTLED_SOLID_FRACTION.
CUP_EXCESS = 1.3
#: The heap's surface is fitted between these fractions of the base radius (apex and toe left out).
FIT_RANGE = (0.2, 0.8)
#: Azimuthal sectors of the surface profile; their slopes' spread gives the fit's standard error.
SECTORS = 12
#: Facets around the round base.
BASE_SEGMENTS = 96

DUMP = "final.dump"


def base_disk(radius: float, segments: int = BASE_SEGMENTS) -> trimesh.Trimesh:
    """A flat disk of ``radius`` [m] at z = 0 about the z axis, normals up (a fan of triangles)."""
    phi = np.linspace(0.0, 2 * pi, segments, endpoint=False)
    ring = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(segments)])
    k = np.arange(segments)
    faces = np.column_stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments])
    return trimesh.Trimesh(np.vstack([[0.0, 0.0, 0.0], ring]), faces, process=False)


def test_seeds(config: dict, s, seed_index: int) -> list[int]:
    """LIGGGHTS seeds of one characterisation run (one per size class, the distribution, the
    insertion): distinct primes from ``random_seed`` and ``seed_index`` (a replicate, or a
    design point's run), disjoint from the spreading runs' (:func:`analysis.dem.inputs.seeds`)."""
    return liggghts_seeds(config["random_seed"] + 500 + 7 * seed_index, len(s.diameters) + 2)


def _run_scene(template: str, config: dict, level: str, outdir: Path, seed_index: int, tube_radius: float,
               particles: int, fill_top: float, box: list[float], max_time: float, **extra) -> dict:
    """Render and run one characterisation scene in ``outdir``; return its final particles and run facts."""
    s = scene(config, level)
    outdir.mkdir(parents=True, exist_ok=True)
    geometry.write_stl(base_disk(tube_radius), outdir / "base.stl")
    text = render(template, s=s, contact=contact_model(s), seeds=test_seeds(config, s, seed_index),
                  box=[f"{v:.6g}" for v in box], skin=skin(s), thermo_every=THERMO_EVERY,
                  substrate_stl=input_path(outdir / "base.stl", outdir), tube_radius=tube_radius,
                  fill_radius=tube_radius - max(s.diameters) / 2, fill_z=(0.0, fill_top), particles=particles,
                  dump=DUMP, **rest_loop(s, max_time), **extra)
    name = template.removesuffix(".in.j2")
    (outdir / f"{name}.in").write_text(text)
    log = run(outdir / f"{name}.in", outdir / f"{name}.log")
    check_timestep(log, s)
    peak = check_kinetic_energy(log, squeeze_speed=squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio))
    if log["inserted"] != particles:
        raise LiggghtsError(f"{name}: inserted {log['inserted']} of {particles} particles "
                            "(the fill region is too small)")
    atoms = read_dump(outdir / DUMP).atoms
    return {"scene": s, "atoms": atoms, "run": {"wall_s": log["wall_s"], "cpu_s": log["cpu_s"],
                                                "steps": int(log["thermo"]["Step"].iloc[-1]), "particles": particles,
                                                "seed_index": seed_index, **peak}}


def _fill_top(particles: int, s, radius: float, fraction: float = INSERT_SOLID_FRACTION) -> float:
    """Height [m] of the insertion cylinder for ``particles`` in a tube of ``radius`` at solid ``fraction``."""
    volume = particles * number_mean_volume(s.diameters, s.mass_fractions)
    return volume / (fraction * pi * (radius - max(s.diameters) / 2) ** 2)


def repose_test(config: dict, level: str, outdir: str | Path, base_diameter_mm: float, seed_index: int = 0,
                max_time_s: float = 0.5) -> dict:
    """Run the angle-of-repose heap on a base of ``base_diameter_mm``; write ``repose.json``,
    the heap's dump and a side view into ``outdir``; return the measurement."""
    s, outdir = scene(config, level), Path(outdir)
    radius = base_diameter_mm * 1e-3 / 2
    cone = pi * radius**3 * tan(radians(HEAP_SIZING_ANGLE_DEG)) / 3
    particles = ceil(HEAP_EXCESS * SETTLED_SOLID_FRACTION * cone / number_mean_volume(s.diameters, s.mass_fractions))
    top = _fill_top(particles, s, radius)
    margin = radius + 1e-3
    box = [-margin, margin, -margin, margin, -0.5e-3, top + 1e-3]
    done = _run_scene("repose.in.j2", config, level, outdir, seed_index, radius, particles, top, box, max_time_s)
    atoms = done["atoms"]
    fit = heap_angle(atoms["x"].to_numpy(), atoms["y"].to_numpy(), atoms["z"].to_numpy(),
                     atoms["radius"].to_numpy(), radius, float(np.mean(s.diameters)))
    plot_heap(atoms, radius, fit, outdir / "repose.png")
    result = {"angle_of_repose_deg": fit["angle_deg"], "angle_se_deg": fit["angle_se_deg"],
              "heap_height_mm": fit["height_m"] * 1e3, "base_diameter_mm": base_diameter_mm,
              "particles_on_base": fit["particles_on_base"], **done["run"]}
    write_json(result, outdir / "repose.json")
    return result


def heap_angle(x, y, z, radius, base_radius: float, bin_width: float, sectors: int = SECTORS,
               fit_range: tuple = FIT_RANGE) -> dict:
    """Angle of repose [deg] of a heap on a round base centred on the z axis, from its surface profile.

    The surface is the highest particle top (``z + radius``) in each cell of ``bin_width`` in
    distance from the axis by ``sectors`` azimuthal sectors; a straight line through the cells
    between ``fit_range`` x ``base_radius`` gives the angle (least squares over all sectors), the
    sectors' own slopes its standard error. Particles off the base (fallen) are left out.
    """
    x, y, z, radius = (np.asarray(a, float) for a in (x, y, z, radius))
    r = np.hypot(x, y)
    on = (r < base_radius) & (z > -radius)
    n_bins = int(ceil(base_radius / bin_width))
    ring = np.minimum((r[on] / bin_width).astype(int), n_bins - 1)
    sector = np.minimum(((np.arctan2(y[on], x[on]) + pi) / (2 * pi) * sectors).astype(int), sectors - 1)
    top = np.full(n_bins * sectors, -np.inf)
    np.maximum.at(top, ring * sectors + sector, (z + radius)[on])
    centre = np.repeat((np.arange(n_bins) + 0.5) * bin_width, sectors)
    cell_sector = np.tile(np.arange(sectors), n_bins)
    use = np.isfinite(top) & (centre >= fit_range[0] * base_radius) & (centre <= fit_range[1] * base_radius)
    if use.sum() < 3:
        raise LiggghtsError(f"the heap's surface has {int(use.sum())} cells in its fit range: no heap on the base")
    slope, intercept = np.polyfit(centre[use], top[use], 1)
    # per-sector slopes from grouped sums (closed-form least squares)
    w = np.bincount(cell_sector[use], minlength=sectors)
    sx, sy = (np.bincount(cell_sector[use], a[use], sectors) for a in (centre, top))
    sxx, sxy = (np.bincount(cell_sector[use], a[use], sectors) for a in (centre**2, centre * top))
    ok = (w >= 2) & (w * sxx - sx**2 > 0)
    slopes = (w[ok] * sxy[ok] - sx[ok] * sy[ok]) / (w[ok] * sxx[ok] - sx[ok] ** 2)
    angles = np.degrees(np.arctan(-slopes))
    return {"angle_deg": float(np.degrees(np.arctan(-slope))), "slope": float(slope), "intercept_m": float(intercept),
            "angle_se_deg": float(np.std(angles, ddof=1) / np.sqrt(ok.sum())) if ok.sum() > 1 else float("nan"),
            "height_m": float(top[np.isfinite(top)].max()), "particles_on_base": int(on.sum())}


def large_heap_angle(base_diameters_mm, angles_deg) -> dict:
    """Angle of repose [deg] of a heap too large for its apex and toe to matter, from heaps on
    several bases: the intercept ``a`` of the least-squares line ``angle = a + b / D`` (D the base's
    diameter [mm], ``b`` [deg mm]; docs/calibration.md: How big the tests must be).

    ``angles_deg`` has one entry per size in ``base_diameters_mm`` (or shape (n_sizes, n) for n
    series at once). With one size, ``a`` is that heap's angle and ``b`` is nan. With two, the
    line passes through both and a single run's seed sd s becomes
    ``s sqrt(D1^2 + D2^2) / (D2 - D1)`` in ``a`` (3.1 s for 5 and 8 mm).
    """
    d = np.asarray(base_diameters_mm, float)
    angles = np.asarray(angles_deg, float)
    if d.size == 1:
        return {"angle_deg": angles[0], "size_slope_deg_mm": np.full(angles.shape[1:], np.nan)}
    if np.unique(d).size < 2:
        raise ValueError(f"heaps on bases {d.tolist()} mm: the angle's size trend needs two different bases")
    slope, intercept = np.polyfit(1.0 / d, angles, 1)
    return {"angle_deg": intercept, "size_slope_deg_mm": slope}


def repose_over_sizes(results: list[dict]) -> dict:
    """The angle of repose of one calibration run from its heaps on one or more bases (each a
    :func:`repose_test` result): :func:`large_heap_angle` of them, the heaps' own angles by base,
    their summed cost."""
    d = [r["base_diameter_mm"] for r in results]
    angles = [r["angle_of_repose_deg"] for r in results]
    fit, extrapolated = large_heap_angle(d, angles), len(set(d)) > 1
    return {"angle_of_repose_deg": float(fit["angle_deg"]),   # no slope of one base: null, not JSON-invalid NaN
            "size_slope_deg_mm": float(fit["size_slope_deg_mm"]) if extrapolated else None,
            "extrapolated": extrapolated, "base_diameters_mm": d, "angles_deg": angles,
            **{k: float(sum(r[k] for r in results)) for k in ("wall_s", "cpu_s")},
            "particles": int(sum(r["particles"] for r in results))}


def plot_heap(atoms, base_radius: float, fit: dict, path: Path) -> None:
    """Side view of the heap (distance from the axis against height) with its fitted surface line."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    r = np.hypot(atoms["x"].to_numpy(), atoms["y"].to_numpy()) * 1e3
    fig, ax = plt.subplots(figsize=(5, 3), dpi=120)
    ax.scatter(np.copysign(r, atoms["x"].to_numpy()), atoms["z"].to_numpy() * 1e3, s=2, c="0.4", lw=0)
    line = np.array(FIT_RANGE) * base_radius
    for side in (-1, 1):
        ax.plot(side * line * 1e3, (fit["intercept_m"] + fit["slope"] * line) * 1e3, "r-", lw=2)
    ax.axvspan(-base_radius * 1e3, base_radius * 1e3, ymax=0.02, color="k")
    ax.set(xlabel="distance from the axis (mm), signed by x", ylabel="z (mm)", aspect="equal",
           title=f"angle of repose {fit['angle_deg']:.1f} deg (fit, red)", ylim=(-0.3, None))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def bulk_density_test(config: dict, level: str, outdir: str | Path, cup_diameter_mm: float, cup_height_mm: float,
                      seed_index: int = 0, max_time_s: float = 0.5) -> dict:
    """Fill a cup of ``cup_diameter_mm`` x ``cup_height_mm`` by a loose rain, strike it off and
    weigh it; write ``bulk_density.json``, the dump and a side view into ``outdir``."""
    s, outdir = scene(config, level), Path(outdir)
    radius, rim = cup_diameter_mm * 1e-3 / 2, cup_height_mm * 1e-3
    particles = ceil(CUP_EXCESS * SETTLED_SOLID_FRACTION * pi * radius**2 * rim
                     / number_mean_volume(s.diameters, s.mass_fractions))
    top = _fill_top(particles, s, radius, CUP_INSERT_SOLID_FRACTION)
    margin = radius + 0.5e-3
    box = [-margin, margin, -margin, margin, -0.5e-3, top + 1e-3]
    done = _run_scene("bulk_density.in.j2", config, level, outdir, seed_index, radius, particles, top, box,
                      max_time_s, rim=rim)
    atoms = done["atoms"]
    measured = cup_density(atoms["x"].to_numpy(), atoms["y"].to_numpy(), atoms["z"].to_numpy(),
                           atoms["radius"].to_numpy(), radius, rim, s.density, max(s.diameters))
    if measured["cup_kg_m3"] <= 0.5 * SETTLED_SOLID_FRACTION * s.density:
        raise LiggghtsError(f"the cup holds {measured['cup_kg_m3']:.0f} kg/m^3: it was not filled to its rim")
    plot_cup(atoms, radius, rim, measured, outdir / "bulk_density.png")
    result = {"bulk_density_kg_m3": measured["core_kg_m3"], **measured, "cup_diameter_mm": cup_diameter_mm,
              "cup_height_mm": cup_height_mm, **done["run"]}
    write_json(result, outdir / "bulk_density.json")
    return result


def cup_density(x, y, z, radius, cup_radius: float, rim: float, density: float, margin: float) -> dict:
    """Bulk density [kg/m^3] of a struck-off cup: ``cup_kg_m3``, the particles left (centres below the rim)
    over the cup's volume, wall layers included; ``core_kg_m3``, the particles whose centres lie more
    than ``margin`` [m] from its wall, bottom and rim over that core's volume: the wall-free value a
    large laboratory cup measures."""
    x, y, z, radius = (np.asarray(a, float) for a in (x, y, z, radius))
    mass = density * 4 / 3 * pi * radius**3
    inside = (z < rim) & (np.hypot(x, y) < cup_radius)
    core = inside & (np.hypot(x, y) < cup_radius - margin) & (z > margin) & (z < rim - margin)
    core_volume = pi * (cup_radius - margin) ** 2 * (rim - 2 * margin)
    return {"cup_kg_m3": float(mass[inside].sum() / (pi * cup_radius**2 * rim)),
            "core_kg_m3": float(mass[core].sum() / core_volume), "particles_in_cup": int(inside.sum()),
            "particles_in_core": int(core.sum())}


def plot_cup(atoms, cup_radius: float, rim: float, measured: dict, path: Path) -> None:
    """Side view of the struck-off cup: its wall, rim and the core the density is taken in."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(4, 4), dpi=120)
    ax.scatter(atoms["x"].to_numpy() * 1e3, atoms["z"].to_numpy() * 1e3, s=2, c="0.4", lw=0)
    R, H = cup_radius * 1e3, rim * 1e3
    ax.plot([-R, -R, R, R], [H, 0, 0, H], "k-", lw=2)
    ax.set(xlabel="x (mm)", ylabel="z (mm)", aspect="equal",
           title=f"bulk density {measured['core_kg_m3']:.0f} kg/m^3 (core)\n{measured['cup_kg_m3']:.0f} (whole cup)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
