"""Scene geometry: the rough substrate and the roller, as STL meshes in metres, and where the
roller stands over the substrate (its gap as built, its start behind the heap).

Axes: x along the roller's travel, y along the roller's axis (the periodic
strip), z up; the substrate's mean plane is z = 0.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import meshio
import numpy as np
import trimesh

from analysis.io import write_bytes
from analysis.physics import polygon_bottom_range, polygon_circumradius

if TYPE_CHECKING:
    from analysis.config.fidelity import Scene


def gaussian_random_field(nx: int, ny: int, spacing: float, correlation_length: float,
                          rms: float, seed: int) -> np.ndarray:
    """Heights [m] of a zero-mean Gaussian random field on an ``nx`` x ``ny`` grid.

    Gaussian autocorrelation ``exp(-r^2 / lc^2)``, synthesised by filtering white
    noise in Fourier space; periodic in both directions. Rescaled so that the
    nodal RMS height equals ``rms`` exactly.
    """
    rng = np.random.default_rng(seed)
    kx = 2 * np.pi * np.fft.fftfreq(nx, d=spacing)
    ky = 2 * np.pi * np.fft.fftfreq(ny, d=spacing)
    k2 = kx[:, None] ** 2 + ky[None, :] ** 2
    amplitude = np.exp(-k2 * correlation_length**2 / 8)  # sqrt of the Gaussian spectrum
    field = np.fft.ifft2(np.fft.fft2(rng.standard_normal((nx, ny))) * amplitude).real
    field -= field.mean()
    return field * (rms / field.std()) if rms > 0 else np.zeros_like(field)


def height_field_mesh(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> trimesh.Trimesh:
    """Triangulate heights ``z[i, j]`` at ``(x[i], y[j])``; normals point up (+z)."""
    nx, ny = z.shape
    xx, yy = np.meshgrid(x, y, indexing="ij")
    vertices = np.column_stack([xx.ravel(), yy.ravel(), z.ravel()])
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return trimesh.Trimesh(vertices, faces, process=False)


def rough_substrate(x_range: tuple, width: float, spacing: float, correlation_length: float,
                    rms: float, seed: int, rough_x: tuple | None = None, taper: float = 0.0,
                    flat_spacing: float | None = None, peak_cap: float | None = None,
                    rms_x: tuple | None = None) -> trimesh.Trimesh:
    """A substrate over ``x_range`` x ``[0, width]`` [m], periodic across y.

    Rough (a Gaussian random field over ``rough_x``, default all of
    ``x_range``, scaled so that the mesh's own area-weighted RMS height over
    ``rms_x``, default ``rough_x``, is ``rms``: the sampling region's, so that
    the layer is measured on the Sq asked for) around where the layer is
    measured; outside, it ramps
    to the flat mean plane over ``taper`` [m] (a cosine window) and continues
    flat on a coarse grid of ``flat_spacing`` [m]: LIGGGHTS pays per triangle
    per step, and the heap's path needs no roughness.

    ``peak_cap`` [m] clips the rare highest nodes (a big field's extremes
    pass 4 Sq: the paper level's 25 x 70 mm reaches 4.5 Sq, through the
    roller's gap) that far above the mean plane over ``rms_x`` (the datum the
    roller's gap is set from; z = 0 without ``rms_x``), after the clip; the
    field is scaled so that the clipped surface has the RMS asked for (a cap at
    2.3 Sq clips 1 % of a Gaussian field's nodes and would lower its Sq 1.2 %).

    The node spacing across y is adjusted so that a whole number of cells fits
    the strip; the row at y = width repeats the row at y = 0, so the surface
    is seamless through the periodic boundary.
    """
    rough_x = x_range if rough_x is None else rough_x
    r0, r1 = max(x_range[0], rough_x[0] - taper), min(x_range[1], rough_x[1] + taper)
    nx = int(np.ceil((r1 - r0) / spacing)) + 1
    x_rough = r0 + spacing * np.arange(nx)
    ny = max(int(round(width / spacing)), 2)
    field = gaussian_random_field(nx, ny, spacing, correlation_length, rms, seed)
    ramp = np.clip(np.minimum(x_rough - r0, x_rough[-1] - x_rough) / taper, 0, 1) if taper > 0 else 1.0
    field *= (0.5 - 0.5 * np.cos(np.pi * ramp))[:, None] if taper > 0 else 1.0
    flat_spacing = flat_spacing or 10 * spacing
    before = np.linspace(x_range[0], r0, max(int(np.ceil((r0 - x_range[0]) / flat_spacing)), 1) + 1)[:-1]
    after = np.linspace(x_rough[-1], max(x_range[1], x_rough[-1]),
                        max(int(np.ceil((x_range[1] - x_rough[-1]) / flat_spacing)), 1) + 1)[1:]
    x = np.concatenate([before, x_rough, after])
    z = np.zeros((len(x), ny))
    z[len(before):len(before) + nx] = field
    z = np.concatenate([z, z[:, :1]], axis=1)
    mesh = height_field_mesh(x, np.linspace(0.0, width, ny + 1), z)
    # Scale (linear facets lower the RMS below the nodes': calibrate the mesh itself) and clip,
    # together: the clip lowers the Sq and the mean plane it is measured from, so the scale and
    # the datum are iterated to their fixed point (each pass shrinks the error by the clipped share).
    raw, scale, datum = mesh.vertices[:, 2].copy(), 1.0, 0.0
    for _ in range(4 if peak_cap is not None else 1):
        mesh.vertices[:, 2] = scale * raw if peak_cap is None else np.minimum(scale * raw, datum + peak_cap)
        mean, sq = substrate_rms(mesh, rough_x if rms_x is None else rms_x)
        scale, datum = (scale * rms / sq if rms > 0 else scale), (0.0 if rms_x is None else mean)
    mesh.vertices[:, 2] = scale * raw if peak_cap is None else np.minimum(scale * raw, datum + peak_cap)
    return mesh


def substrate_rms(mesh: trimesh.Trimesh, x_range: tuple | None = None) -> tuple[float, float]:
    """(mean height, Sq) [m] of a height-field mesh, area-weighted over its
    triangles (those with centres inside ``x_range`` [m], if given).

    Uses the exact mean and mean square of a linear function over each triangle.
    """
    z = mesh.vertices[mesh.faces][:, :, 2]
    area = mesh.area_faces * np.abs(mesh.face_normals[:, 2])  # projected area
    if x_range is not None:
        cx = mesh.triangles_center[:, 0]
        area = area * ((cx >= x_range[0]) & (cx <= x_range[1]))
    mean = np.sum(area * z.mean(1)) / area.sum()
    zc = z - mean
    mean_square = (np.sum(zc**2, 1) + zc[:, 0] * zc[:, 1] + zc[:, 1] * zc[:, 2] + zc[:, 0] * zc[:, 2]) / 6
    return float(mean), float(np.sqrt(np.sum(area * mean_square) / area.sum()))


def roller(diameter: float, length: float, facets: int, capped: bool = True) -> trimesh.Trimesh:
    """The roller: a ``facets``-gon prism of mean diameter ``diameter`` and ``length`` [m],
    axis along y from y=0 to y=length, centred on x = z = 0, normals outward.

    Its circumradius is :func:`analysis.physics.polygon_circumradius` (the bottom's mean over a turn is
    ``diameter / 2`` below the axis), and it is turned so that its bottom is at that mean
    as built: a still roller (omega = 0) sees the gap as set, a turning one swings about it
    by :func:`analysis.physics.polygon_bottom_range`.

    ``capped=False`` gives the lateral surface alone: in a periodic strip the
    roller is endless, and end caps on the periodic boundary would be walls.
    """
    rc = polygon_circumradius(diameter / 2, facets)
    cylinder = trimesh.creation.cylinder(radius=rc, height=length, sections=facets)
    cylinder.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # z -> y
    # the vertex nearest the bottom (-z) at the angle whose depth is the mean one
    rim = cylinder.vertices[np.isclose(np.hypot(cylinder.vertices[:, 0], cylinder.vertices[:, 2]), rc)]
    depth = -rim[:, 2]
    nearest = rim[np.argmax(depth)]
    now = np.arctan2(nearest[0], -nearest[2])  # its angle from straight down, about +y towards +x
    want = np.arccos(np.clip(diameter / 2 / rc, -1.0, 1.0))
    cylinder.apply_transform(trimesh.transformations.rotation_matrix(now - want, [0, 1, 0]))
    cylinder.apply_translation([0.0, length / 2, 0.0])
    if capped:
        cylinder.fix_normals()
        return cylinder
    radial = np.hypot(cylinder.vertices[:, 0], cylinder.vertices[:, 2])
    lateral = np.all(np.isclose(radial[cylinder.faces], rc), axis=1)
    shell = cylinder.submesh([np.flatnonzero(lateral)], append=True)
    return shell


def roller_bottom_depth(mesh: trimesh.Trimesh) -> float:
    """Depth [m] of a roller mesh's lowest point below its axis (z = 0), as built."""
    return float(-mesh.vertices[:, 2].min())


def write_stl(mesh: trimesh.Trimesh, path: str | Path) -> Path:
    """Write an ASCII STL atomically (:func:`analysis.io.atomic_path`)."""
    return write_bytes(trimesh.exchange.stl.export_stl_ascii(mesh).encode(), path)


def load_stl(path: str | Path) -> trimesh.Trimesh:
    """An STL as written by :func:`write_stl` (or LIGGGHTS' mesh input), vertices in m."""
    return trimesh.load_mesh(str(path), file_type="stl", process=False)


def load_surface(path: str | Path) -> trimesh.Trimesh:
    """A user's surface mesh in any format meshio reads (STL, PLY, OBJ, VTK, VTU, ...), in m.

    Only its triangles are kept (a profilometer scan exported as a triangulated
    surface); quads are split in two. An STL is read by trimesh (meshio 5.3
    misreads some ASCII STLs). Raises ``ValueError`` naming the file if it
    cannot be read (empty, truncated, not a mesh), holds no triangle or quad, or has a
    vertex that is not a finite number.
    """
    if Path(path).suffix.lower() == ".stl":
        try:
            mesh = load_stl(path)
        except Exception as err:
            raise ValueError(f"cannot read the surface mesh {str(path)!r}: {err}") from None
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise ValueError(f"the surface mesh {str(path)!r} holds no triangles (an empty, truncated or "
                             "unreadable STL)")
        return _finite(mesh, path)
    try:
        mesh = meshio.read(str(path))
    except Exception as err:  # meshio raises its own ReadError, and OS and format errors
        raise ValueError(f"cannot read the surface mesh {str(path)!r}: {err}") from None
    faces = [block.data for block in mesh.cells if block.type == "triangle"]
    faces += [quad[:, [0, 1, 2, 0, 2, 3]].reshape(-1, 3) for quad in
              (block.data for block in mesh.cells if block.type == "quad")]
    if not faces:
        raise ValueError(f"the surface mesh {str(path)!r} holds no triangles or quads "
                         f"(cells: {', '.join(b.type for b in mesh.cells) or 'none'})")
    return _finite(trimesh.Trimesh(np.asarray(mesh.points, float)[:, :3], np.concatenate(faces), process=False), path)


#: A mesh whose extent is this many times what it should cover, or whose heights span more than
#: the box is high, is in the wrong units (mm or um for m: 1000 x, 1e6 x).
UNITS_FACTOR = 30


def units_slip(mesh: trimesh.Trimesh, extent, height: float) -> str | None:
    """What says that ``mesh`` is not in metres: its x-y extent over ``UNITS_FACTOR`` x ``extent``
    (x, y [m], what it covers) or its heights spanning more than ``height`` [m]; None if nothing."""
    span = mesh.bounds[1] - mesh.bounds[0]
    ratio = float(np.max(span[:2] / np.asarray(extent, float)))
    if ratio > UNITS_FACTOR:
        return f"spans {span[0]:.4g} x {span[1]:.4g} m, {ratio:.0f} x the {extent[0]:.4g} x {extent[1]:.4g} m it covers"
    if span[2] > height:
        return f"has heights spanning {span[2]:.4g} m, more than the {height:.4g} m box is high"
    return None


def _finite(mesh: trimesh.Trimesh, path) -> trimesh.Trimesh:
    """``mesh`` if every vertex of its triangles is finite; else a ValueError naming the file and one vertex."""
    used = mesh.vertices[np.unique(mesh.faces)]
    bad = ~np.isfinite(used).all(axis=1)
    if bad.any():
        raise ValueError(f"the surface mesh {str(path)!r} has {bad.sum()} vertices that are not finite numbers "
                         f"(e.g. {used[bad][0].tolist()})")
    return mesh


def roller_gap(s: Scene, substrate, roller) -> dict:
    """Where the roller's axis goes so that its gap is the one set, and the gap as built.

    The gap is measured from the substrate's mean plane under the sampling region (not the
    whole field's), to the roller's bottom averaged over a turn (:func:`roller`:
    the polygon's mean bottom is ``R`` below its axis, and a still roller stands at that
    mean). Returns the axis height ``axis_z_m`` [m], the datum ``substrate_mean_region_m``,
    the polygon's ``circumradius_m``, and in um the ``effective_gap_um`` (mean over a turn,
    measured on the mesh as built) with its swing ``gap_min_um`` .. ``gap_max_um``.
    """
    datum = substrate_rms(substrate, s.sampling_region[:2])[0]
    axis_z = datum + s.roller_gap + s.roller_radius
    mesh = roller
    near, far = polygon_bottom_range(s.roller_radius, s.roller_facets)
    turns = np.linspace(0.0, 2 * np.pi, 3600, endpoint=False)
    xz = mesh.vertices[:, [0, 2]]
    depth = np.max(-(np.sin(turns)[:, None] * xz[:, 0] + np.cos(turns)[:, None] * xz[:, 1]), axis=1)
    return {"axis_z_m": axis_z, "substrate_mean_region_m": datum, "circumradius_m": far,
            "effective_gap_um": (axis_z - depth.mean() - datum) * 1e6,
            "gap_still_um": (axis_z - roller_bottom_depth(mesh) - datum) * 1e6,
            "gap_min_um": (axis_z - far - datum) * 1e6, "gap_max_um": (axis_z - near - datum) * 1e6}


def roller_start(atoms, s: Scene, clearance: float | None = None, axis_z: float | None = None) -> float:
    """x [m] of the roller axis just behind the settled heap (no particle touched).

    For each particle, the axis at height ``axis_z`` (default ``gap + R``) must stay
    ``R + r + clearance`` away; the start is the smallest such x over all particles.
    """
    clearance = 0.2 * min(s.diameters) if clearance is None else clearance
    zc = s.roller_gap + s.roller_radius if axis_z is None else axis_z
    reach = s.roller_radius + atoms["radius"].to_numpy() + clearance
    dz = np.minimum(np.abs(atoms["z"].to_numpy() - zc), reach)
    return float(np.min(atoms["x"].to_numpy() - np.sqrt(reach**2 - dz**2)))
