"""The virtual profilometer of the spreading process-maps paper (section 2.1, Figure 3): heights
probed at the intersections of ``n_lines`` random lines parallel to y and ``n_lines`` random
lines parallel to x over the sampling region.  At each probe, ``b`` is the height of the
substrate (the previously fused layer, :func:`substrate_height`) and ``h`` the top of the spread
layer (:func:`layer_top`), i.e. the highest of ``b`` and every particle surface above the probe
(``h = b`` where no particle lies, the paper's h_3 = b_3).  The layer metrics computed from
these heights (eqs. 1-7) are :mod:`analysis.metrics.spread_layer`'s.

Units are SI throughout (m).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "probe_lines",
    "substrate_height",
    "layer_top",
    "periodic_images",
    "load_mesh",
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
    mesh = load_mesh(substrate)
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


def load_mesh(substrate):
    """A trimesh.Trimesh from a Trimesh or an STL path (coordinates in m); ValueError naming an
    unreadable or empty file."""
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
