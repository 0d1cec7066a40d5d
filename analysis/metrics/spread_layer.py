"""The paper's spread-layer metrics (section 2.1, eqs. 1-7) of one DEM frame, from the heights
its virtual profilometer probes (:mod:`analysis.metrics.profilometer`): the mean substrate and
layer-top heights and the layer's thickness (eqs. 1-3), the powder mass M_s (eq. 4), the
spread throughput Q_s (eq. 5), the roughness R_q (eq. 6) and the porosity Phi (eq. 7).

Units are SI throughout (m, kg, s); :func:`to_report_units` converts to mm, um, g and mm/s.
"""

from __future__ import annotations

import math

import numpy as np

from analysis.metrics.profilometer import layer_top, periodic_images, probe_lines, substrate_height

__all__ = [
    "powder_mass",
    "spread_throughput",
    "layer_roughness",
    "layer_porosity",
    "spread_layer_metrics",
    "to_report_units",
    "check_inputs",
]


def powder_mass(diameters, density):
    """Mass of powder in the sampling region, eq. (4).

    Parameters
    ----------
    diameters : array_like
        Diameters ``phi_k`` of the particles centred in the region [m].
    density : float
        Material density ``rho`` [kg/m^3].

    Returns
    -------
    float
        ``M_s = pi * rho / 6 * sum(phi_k**3)`` [kg].
    """
    return math.pi * density / 6.0 * float(np.sum(np.asarray(diameters, dtype=float) ** 3))


def spread_throughput(speed, thk_avg):
    """Spread throughput, eq. (5).

    Parameters
    ----------
    speed : float
        Translation speed ``U`` of the spreader [m/s].
    thk_avg : float
        Average spread layer thickness, eq. (3) [m].

    Returns
    -------
    float
        ``Q_s = U * thk_avg``, volume spread per unit time and spreader
        width [m^2/s].
    """
    return speed * thk_avg


def layer_roughness(h):
    """Roughness of the spread layer, eq. (6).

    Parameters
    ----------
    h : array_like
        Layer-top heights ``h_j`` at the probes [m].

    Returns
    -------
    float
        ``R_q``, the RMS of ``h`` about its mean ``h_avg`` [m].
    """
    dev = np.asarray(h, dtype=float) - np.ravel(h)[0]  # shifted: a flat layer gives exactly 0
    return float(np.sqrt(np.mean((dev - dev.mean()) ** 2)))


def layer_porosity(mass, density, length_x, length_y, roughness):
    """Porosity of the spread layer, eq. (7).

    Parameters
    ----------
    mass : float
        Powder mass ``M_s`` in the region [kg].
    density : float
        Material density ``rho`` [kg/m^3].
    length_x, length_y : float
        Sides ``L_x``, ``L_y`` of the sampling region [m].
    roughness : float
        ``R_q`` [m]; the paper takes ``4 R_q`` as the layer's thickness.

    Returns
    -------
    float
        ``Phi = (1 - M_s / (rho L_x L_y 4 R_q)) * 100`` [%]; NaN when
        ``R_q = 0`` (the layer cuboid has no volume).
    """
    cuboid = density * length_x * length_y * 4.0 * roughness
    return (1.0 - mass / cuboid) * 100.0 if cuboid > 0 else math.nan


def spread_layer_metrics(atoms_or_frame, region, speed, density, substrate=None, n_lines=1000, seed=0,
                         box=None, periodic=None):
    """Spread-layer properties of one frame, eqs. (1)-(7) of the paper.

    Parameters
    ----------
    atoms_or_frame : pandas.DataFrame or analysis.metrics.dump.Frame
        Particles with columns ``x, y, z, radius`` [m]. A Frame's box is
        checked to contain the region.
    region : tuple of float
        Sampling region ``(xmin, xmax, ymin, ymax)`` [m].
    speed : float
        Spreader translation speed ``U`` [m/s], >= 0.
    density : float
        Particle material density ``rho`` [kg/m^3], > 0.
    substrate : None, float, str, os.PathLike or trimesh.Trimesh, optional
        Substrate below the layer, see
        :func:`analysis.metrics.profilometer.substrate_height` (default: the
        plane z = 0).
    n_lines : int, optional
        Profilometer lines in each direction (``n_lines**2`` probes).
    seed : int, optional
        Seed for the line positions.
    box, periodic : optional
        Box bounds [m] and periodic axes (see :func:`analysis.metrics.profilometer.periodic_images`); default
        those of a Frame (its dump's ``BOX BOUNDS`` header), none for a
        DataFrame. Spheres across a periodic boundary raise the heights.

    Returns
    -------
    dict
        Paper quantities: ``b_avg``, ``h_avg``, ``thk_avg`` [m] (eqs. 1-3),
        ``M_s`` [kg] (eq. 4), ``Q_s`` [m^2/s] (eq. 5), ``R_q`` [m] (eq. 6),
        ``Phi`` [%] (eq. 7). Extras: ``coverage`` (share of probes with
        powder above the substrate, h > b), ``packing_fraction`` (solid
        volume of the particles centred in the region over
        ``L_x L_y thk_avg``; NaN if thk_avg = 0), ``n_particles`` (particles
        centred in the region), ``n_probes``.

    Raises
    ------
    ValueError
        On an empty or inverted region, a region outside the frame's box, a
        negative or non-finite speed, a non-positive density, fewer than one
        line, missing columns, a radius that is not positive or exceeds the box,
        or a substrate mesh not covering the region.
    """
    atoms = getattr(atoms_or_frame, "atoms", atoms_or_frame)
    region = check_inputs(region, speed, density, n_lines, getattr(atoms_or_frame, "box", None))
    missing = {"x", "y", "z", "radius"} - set(atoms.columns)
    if missing:
        raise ValueError(f"atoms lack column(s) {sorted(missing)}")
    centres = atoms[["x", "y", "z"]].to_numpy(dtype=float)
    radii = atoms["radius"].to_numpy(dtype=float)

    box = getattr(atoms_or_frame, "box", None) if box is None else box
    extent = np.inf if box is None else float(np.ptp(np.asarray(box, dtype=float), axis=1).max())
    wrong = ~((radii > 0) & (radii <= extent))
    if wrong.any():
        raise ValueError(f"{wrong.sum()} particle radii are not positive or exceed the box "
                         f"(e.g. {float(radii[wrong][0])!r} m against a box of {extent:.4g} m)")
    if box is not None:  # LIGGGHTS keeps atoms in the box (periodic ones within a skin of it)
        lo, hi = np.asarray(box, dtype=float).T
        away = ((centres < lo - extent) | (centres > hi + extent)).any(axis=1)
        if away.any():
            raise ValueError(f"{away.sum()} particles lie far outside the box (e.g. at "
                             f"{centres[away][0].tolist()} m; box {np.asarray(box).tolist()} m)")
    periodic = getattr(atoms_or_frame, "periodic", (False, False, False)) if periodic is None else periodic
    if any(periodic) and box is None:
        raise ValueError(f"periodic axes {tuple(periodic)} need the box bounds (box=...)")
    xs, ys = probe_lines(region, n_lines, seed)
    b = substrate_height(substrate, xs, ys)
    h = layer_top(*(periodic_images(centres, radii, box, periodic) if any(periodic) else (centres, radii)),
                  xs, ys, b)

    xmin, xmax, ymin, ymax = region
    length_x, length_y = xmax - xmin, ymax - ymin
    x, y = centres[:, 0], centres[:, 1]
    inside = (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)
    m_s = powder_mass(2.0 * radii[inside], density)
    b_avg, h_avg = float(b.mean()), float(h.mean())
    thk_avg = h_avg - b_avg
    r_q = layer_roughness(h)
    solid = m_s / density
    return {
        "b_avg": b_avg,
        "h_avg": h_avg,
        "thk_avg": thk_avg,
        "M_s": m_s,
        "Q_s": spread_throughput(speed, thk_avg),
        "R_q": r_q,
        "Phi": layer_porosity(m_s, density, length_x, length_y, r_q),
        "coverage": float(np.mean(h > b)),
        "packing_fraction": solid / (length_x * length_y * thk_avg) if thk_avg > 0 else math.nan,
        "n_particles": int(np.count_nonzero(inside)),
        "n_probes": int(h.size),
    }


def to_report_units(metrics):
    """Convert `spread_layer_metrics` output to the report's units.

    Parameters
    ----------
    metrics : dict
        Output of `spread_layer_metrics` (SI).

    Returns
    -------
    dict
        ``mass_g`` [g], ``throughput_mm2_s`` [mm^2/s], ``roughness_um`` [um],
        ``porosity_pct`` [%], ``thickness_um`` [um], ``coverage`` [-],
        ``packing_fraction`` [-], ``n_particles``, ``b_avg_um`` [um],
        ``h_avg_um`` [um], ``n_probes``. Undefined values (NaN) are None,
        so the dict serialises to strict JSON.
    """
    scaled = {
        "mass_g": metrics["M_s"] * 1e3,
        "throughput_mm2_s": metrics["Q_s"] * 1e6,
        "roughness_um": metrics["R_q"] * 1e6,
        "porosity_pct": metrics["Phi"],
        "thickness_um": metrics["thk_avg"] * 1e6,
        "coverage": metrics["coverage"],
        "packing_fraction": metrics["packing_fraction"],
        "b_avg_um": metrics["b_avg"] * 1e6,
        "h_avg_um": metrics["h_avg"] * 1e6,
    }
    report = {k: (None if math.isnan(v) else float(v)) for k, v in scaled.items()}
    report.update(n_particles=metrics["n_particles"], n_probes=metrics["n_probes"])
    return report


def check_inputs(region, speed, density, n_lines, box, unit="m"):
    """Validate the analysis inputs; return the region as floats.

    Lengths are in ``unit`` (speed in ``unit``/s), which only labels the
    messages.
    """
    xmin, xmax, ymin, ymax = (float(v) for v in region)
    if not (xmin < xmax and ymin < ymax):
        raise ValueError(f"region {xmin:g} {xmax:g} {ymin:g} {ymax:g} {unit} has zero or negative area "
                         "(need XMIN < XMAX and YMIN < YMAX)")
    if not (math.isfinite(speed) and speed >= 0):
        raise ValueError(f"speed {speed:g} {unit}/s must be finite and >= 0")
    if not (math.isfinite(density) and density > 0):
        raise ValueError(f"density {density:g} kg/m3 must be finite and > 0")
    if n_lines < 1:
        raise ValueError(f"lines {n_lines} must be >= 1")
    if box is not None:
        (bx0, bx1), (by0, by1) = np.asarray(box, dtype=float)[:2]
        tol = 1e-9 * max(abs(bx0), abs(bx1), abs(by0), abs(by1))
        if xmin < bx0 - tol or xmax > bx1 + tol or ymin < by0 - tol or ymax > by1 + tol:
            raise ValueError(f"region {xmin:g} {xmax:g} {ymin:g} {ymax:g} {unit} lies outside the dump's box "
                             f"x [{bx0:g}, {bx1:g}], y [{by0:g}, {by1:g}] {unit}")
    return xmin, xmax, ymin, ymax
