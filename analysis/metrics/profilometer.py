"""Spread-layer metrics from a DEM frame with a virtual profilometer.

Implements section 2.1 (eqs. 1-7, Figure 3) of the spreading process-maps
paper: heights are probed at the intersections of ``n_lines`` random lines
parallel to y and ``n_lines`` random lines parallel to x over the sampling
region. At each probe, ``b`` is the height of the substrate (the previously
fused layer) and ``h`` the top of the spread layer, i.e. the highest of
``b`` and every particle surface above the probe (``h = b`` where no
particle lies, the paper's h_3 = b_3).

Units are SI throughout (m, kg, s); ``to_report_units`` and the command line
convert to mm, um, g and mm/s. Run ``python -m analysis.metrics.profilometer -h``
for the command line.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from analysis.dem.geometry import units_slip
from analysis.io import USER_ERRORS, error_line, write_text
from analysis.metrics.dump import read_dump

__all__ = [
    "probe_lines",
    "substrate_height",
    "layer_top",
    "periodic_images",
    "powder_mass",
    "spread_throughput",
    "layer_roughness",
    "layer_porosity",
    "spread_layer_metrics",
    "to_report_units",
    "main",
]


#: Number of (object, probe) pairs handled at once: bounds the working memory
#: (about 100 bytes a pair) without slowing the NumPy loops.
MAX_PAIRS = 1 << 18


def probe_lines(region, n_lines=1000, seed=0):
    """Positions of the profilometer's random lines over the sampling region.

    Parameters
    ----------
    region : tuple of float
        Sampling region ``(xmin, xmax, ymin, ymax)`` [m].
    n_lines : int, optional
        Number of lines in each direction; the probes are the
        ``n_lines**2`` intersections.
    seed : int, optional
        Seed of the random generator (``numpy.random.default_rng``).

    Returns
    -------
    xs, ys : numpy.ndarray, shape (n_lines,)
        Sorted, uniformly random x positions of the lines parallel to y and
        y positions of the lines parallel to x [m]. Probe ``(i, j)`` is at
        ``(xs[i], ys[j])``.
    """
    xmin, xmax, ymin, ymax = region
    rng = np.random.default_rng(seed)
    return np.sort(rng.uniform(xmin, xmax, n_lines)), np.sort(rng.uniform(ymin, ymax, n_lines))


def substrate_height(substrate, xs, ys):
    """Substrate heights ``b`` at the probes of a line grid.

    Parameters
    ----------
    substrate : None, float, str, os.PathLike or trimesh.Trimesh
        ``None``: flat plane z = 0; a float: flat plane at that height [m];
        a path to an STL file (coordinates in m) or a ``trimesh.Trimesh``:
        the surface's highest point above each probe (so a closed solid
        gives its top face).
    xs, ys : numpy.ndarray
        Sorted line positions [m] (see `probe_lines`).

    Returns
    -------
    numpy.ndarray, shape (len(xs), len(ys))
        ``b[i, j]``, the substrate height at ``(xs[i], ys[j])`` [m].

    Raises
    ------
    ValueError
        If the mesh leaves some probes uncovered or cannot be read.
    """
    shape = (len(xs), len(ys))
    if substrate is None or isinstance(substrate, (int, float)):
        return np.full(shape, float(substrate or 0.0))
    mesh = _load_mesh(substrate)
    b = _mesh_top(np.asarray(mesh.triangles, dtype=float), xs, ys)
    uncovered = np.count_nonzero(np.isneginf(b))
    if uncovered:
        raise ValueError(f"substrate {substrate}: mesh leaves {uncovered} of {b.size} probes of the region uncovered")
    return b


def layer_top(centres, radii, xs, ys, base):
    """Top of the spread layer ``h`` at the probes of a line grid.

    ``h`` is the highest of the substrate ``base`` and every sphere top
    ``z_k + sqrt(r_k**2 - d**2)`` over the probe (d: horizontal distance
    from probe to centre k). Particles centred outside the grid's region
    count where their caps reach over it.

    Parameters
    ----------
    centres : numpy.ndarray, shape (N, 3)
        Particle centres [m].
    radii : numpy.ndarray, shape (N,)
        Particle radii [m].
    xs, ys : numpy.ndarray
        Sorted line positions [m] (see `probe_lines`).
    base : numpy.ndarray, shape (len(xs), len(ys))
        Substrate heights ``b`` [m] (see `substrate_height`).

    Returns
    -------
    numpy.ndarray, shape (len(xs), len(ys))
        ``h[i, j]`` at ``(xs[i], ys[j])`` [m].
    """
    x, y, z = np.asarray(centres, dtype=float).reshape(-1, 3).T
    r = np.asarray(radii, dtype=float)
    h = np.array(base, dtype=float, order="C")
    ix0, ix1 = _covered(xs, x - r, x + r)
    iy0, iy1 = _covered(ys, y - r, y + r)
    for part in _chunks((ix1 - ix0) * (iy1 - iy0), MAX_PAIRS):
        # x-lines crossing each sphere, then the y-lines within its chord there
        k, ix = _expand_ranges(ix0[part], ix1[part])
        k += part.start
        chord2 = np.maximum(r[k] ** 2 - (xs[ix] - x[k]) ** 2, 0.0)
        chord = np.sqrt(chord2)
        row, iy = _expand_ranges(*_covered(ys, y[k] - chord, y[k] + chord))
        k, ix = k[row], ix[row]
        top = z[k] + np.sqrt(np.maximum(chord2[row] - (ys[iy] - y[k]) ** 2, 0.0))
        np.maximum.at(h.reshape(-1), ix * len(ys) + iy, top)
    return h


def periodic_images(centres, radii, box, periodic):
    """The particles plus their periodic images that reach into the box.

    A sphere within one diameter of a periodic boundary also stands, shifted
    by the period, just beyond the opposite boundary: its cap raises the
    surface there. Only heights use the images; mass counts each particle once.

    Parameters
    ----------
    centres : numpy.ndarray, shape (N, 3)
        Particle centres [m].
    radii : numpy.ndarray, shape (N,)
        Particle radii [m].
    box : array_like, shape (3, 2)
        Box bounds ``[[xlo, xhi], [ylo, yhi], [zlo, zhi]]`` [m].
    periodic : sequence of 3 bool
        Which axes are periodic.

    Returns
    -------
    centres, radii : numpy.ndarray
        The originals first, then the images.
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    radii = np.asarray(radii, dtype=float)
    box = np.asarray(box, dtype=float).reshape(3, 2)
    for axis in np.flatnonzero(np.asarray(periodic, dtype=bool)[:2]):  # x, y: z never matters for heights
        lo, hi = box[axis]
        period = hi - lo
        near_lo = centres[:, axis] < lo + 2 * radii
        near_hi = centres[:, axis] > hi - 2 * radii
        shifted = [centres[near_lo].copy(), centres[near_hi].copy()]
        shifted[0][:, axis] += period
        shifted[1][:, axis] -= period
        centres = np.concatenate([centres, *shifted])
        radii = np.concatenate([radii, radii[near_lo], radii[near_hi]])
    return centres, radii


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
        Substrate below the layer, see `substrate_height` (default: the
        plane z = 0).
    n_lines : int, optional
        Profilometer lines in each direction (``n_lines**2`` probes).
    seed : int, optional
        Seed for the line positions.
    box, periodic : optional
        Box bounds [m] and periodic axes (see `periodic_images`); default
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
    region = _check_inputs(region, speed, density, n_lines, getattr(atoms_or_frame, "box", None))
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


def main(argv=None):
    """Command line: print (and optionally save) the metrics of a dump frame.

    Returns
    -------
    int
        Exit status: 0 on success, 2 on a bad argument or input file.
    """
    args = _parser().parse_args(argv)
    args.region_text = [f"{v:g}" for v in args.region]
    try:
        for path in (args.dump, args.substrate):
            if path is not None and not Path(path).is_file():
                raise ValueError(f"file not found: {path}")
        if args.json and not Path(args.json).resolve().parent.is_dir():
            raise ValueError(f"--json {args.json}: folder does not exist")
        frame = read_dump(args.dump, timestep=args.timestep)
        # check in the units given, so that messages quote the user's numbers
        _check_inputs(args.region, args.speed, args.density, args.lines, frame.box * 1e3, unit="mm")
        region = tuple(v * 1e-3 for v in args.region)
        _check_units(frame, region, args)
        substrate = args.substrate if args.substrate is not None else args.substrate_height * 1e-3
        try:
            if args.substrate is not None:
                substrate = _load_mesh(substrate)
                slip = units_slip(substrate, np.ptp(frame.box[:2], axis=1), float(np.ptp(frame.box[2])))
                if slip:
                    raise ValueError(f"substrate {args.substrate} {slip} (the dump's box): in millimetres? "
                                     "--substrate is in metres")
            metrics = spread_layer_metrics(frame, region, args.speed * 1e-3, args.density, substrate=substrate,
                                           n_lines=args.lines, seed=args.seed)
        except ValueError as err:
            raise ValueError(f"{args.dump}: {err}") from None
        if metrics["n_particles"] == 0:
            raise ValueError(f"{args.dump}: no particle is centred in the region {' '.join(args.region_text)} mm "
                             f"(of {len(frame.atoms)} in the dump): no layer to measure")
        text = json.dumps(to_report_units(metrics), indent=2)
        if args.json:
            write_text(text + "\n", args.json)
    except USER_ERRORS as err:
        print(f"layer_metrics: error: {error_line(err)}", file=sys.stderr)
        return 2
    print(text)
    return 0


def _check_units(frame, region, args):
    """A ValueError if ``--region`` [mm] looks like metres: narrower than the dump's median particle."""
    if "radius" not in frame.atoms or frame.atoms.empty:
        return
    typical = 2 * float(frame.atoms["radius"].median())
    width = min(region[1] - region[0], region[3] - region[2])
    if width < typical:
        raise ValueError(f"region {' '.join(args.region_text)} mm is {width * 1e3:.3g} mm across, less than the "
                         f"dump's median particle diameter ({typical * 1e3:.3g} mm): in metres? --region takes mm")


def _check_inputs(region, speed, density, n_lines, box, unit="m"):
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


def _covered(lines, lo, hi):
    """Index range ``[start, stop)`` of the sorted ``lines`` within ``[lo, hi]``."""
    return np.searchsorted(lines, lo, "left"), np.searchsorted(lines, hi, "right")


def _expand_ranges(start, stop):
    """All (owner, index) pairs with ``start[owner] <= index < stop[owner]``.

    Parameters
    ----------
    start, stop : numpy.ndarray of int
        Per-owner index ranges (empty where ``stop <= start``).

    Returns
    -------
    owner, index : numpy.ndarray of int
        Owner of each pair (non-decreasing) and its index.
    """
    count = np.maximum(stop - start, 0)
    owner = np.repeat(np.arange(len(count)), count)
    offset = np.cumsum(count) - count
    return owner, np.arange(owner.size) + np.repeat(start - offset, count)


def _chunks(pairs, max_pairs):
    """Slices of consecutive objects holding about ``max_pairs`` pairs each.

    Parameters
    ----------
    pairs : numpy.ndarray of int
        Number of (object, probe) pairs of each object (an upper bound).
    max_pairs : int
        Target number of pairs per slice.

    Yields
    ------
    slice
        Consecutive objects, together at most ``max_pairs`` pairs plus
        those of one object.
    """
    group = np.cumsum(np.maximum(pairs, 0)) // max_pairs
    cuts = np.flatnonzero(np.diff(group)) + 1
    bounds = np.concatenate(([0], cuts, [len(pairs)]))
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b > a:
            yield slice(int(a), int(b))


def _load_mesh(substrate):
    """A trimesh.Trimesh from a Trimesh or an STL path (coordinates in m)."""
    import trimesh

    if isinstance(substrate, trimesh.Trimesh):
        return substrate
    try:
        mesh = trimesh.load(substrate, force="mesh")
    except Exception as err:  # trimesh raises assorted types on bad files
        raise ValueError(f"substrate {substrate}: cannot read mesh ({err})") from err
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"substrate {substrate}: no triangles in the mesh")
    return mesh


def _mesh_top(triangles, xs, ys):
    """Highest point of a triangle soup above each grid probe (-inf: none).

    Rasterises every non-vertical triangle onto the probes inside its
    bounding box and interpolates z barycentrically there.

    Parameters
    ----------
    triangles : numpy.ndarray, shape (T, 3, 3)
        Triangle vertices [m].
    xs, ys : numpy.ndarray
        Sorted line positions [m].

    Returns
    -------
    numpy.ndarray, shape (len(xs), len(ys))
        Highest surface height over each probe [m], -inf where none.
    """
    top = np.full((len(xs), len(ys)), -np.inf)
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    extent = np.ptp(triangles[:, :, :2], axis=1).max(axis=1)
    flat = np.abs(det) > 1e-12 * extent**2  # drop vertical (wall) facets
    v0, e1, e2, det, tri = v0[flat], e1[flat], e2[flat], det[flat], triangles[flat]
    ix0, ix1 = _covered(xs, tri[:, :, 0].min(axis=1), tri[:, :, 0].max(axis=1))
    iy0, iy1 = _covered(ys, tri[:, :, 1].min(axis=1), tri[:, :, 1].max(axis=1))
    tol = 1e-9
    for part in _chunks((ix1 - ix0) * (iy1 - iy0), MAX_PAIRS):
        k, ix = _expand_ranges(ix0[part], ix1[part])
        k += part.start
        row, iy = _expand_ranges(iy0[k], iy1[k])
        k, ix = k[row], ix[row]
        px, py = xs[ix] - v0[k, 0], ys[iy] - v0[k, 1]
        l1 = (px * e2[k, 1] - py * e2[k, 0]) / det[k]
        l2 = (py * e1[k, 0] - px * e1[k, 1]) / det[k]
        inside = (l1 >= -tol) & (l2 >= -tol) & (l1 + l2 <= 1 + tol)
        z = v0[k, 2] + l1 * e1[k, 2] + l2 * e2[k, 2]
        np.maximum.at(top.reshape(-1), (ix * len(ys) + iy)[inside], z[inside])
    return top


def _parser():
    p = argparse.ArgumentParser(
        prog="python -m analysis.metrics.profilometer",
        description="Spread-layer metrics (mass, throughput, roughness, porosity) of a LIGGGHTS dump frame.",
    )
    p.add_argument("dump", help="LIGGGHTS dump custom file (SI, m), optionally gzipped")
    p.add_argument("--region", nargs=4, type=float, required=True, metavar=("XMIN", "XMAX", "YMIN", "YMAX"),
                   help="sampling region [mm]")
    p.add_argument("--speed", type=float, required=True, metavar="U", help="spreader translation speed [mm/s]")
    p.add_argument("--density", type=float, required=True, metavar="RHO", help="particle density [kg/m3]")
    sub = p.add_mutually_exclusive_group()
    sub.add_argument("--substrate", metavar="STL", help="substrate surface, STL in m (default: flat plane)")
    sub.add_argument("--substrate-height", type=float, default=0.0, metavar="Z",
                     help="height of a flat substrate plane [mm] (default 0)")
    p.add_argument("--lines", type=int, default=1000, help="profilometer lines per direction (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random line positions (default 0)")
    p.add_argument("--timestep", type=int, help="timestep of the frame (default: the last)")
    p.add_argument("--json", metavar="OUT", help="also write the JSON object to this file (atomically)")
    return p


if __name__ == "__main__":
    sys.exit(main())
