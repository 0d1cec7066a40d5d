"""The final state of a spreading run: VTK for ParaView and a top-view picture.

:func:`write_vtk` writes the particles as VTK XML polydata (``.vtp``) points
carrying their radius, diameter and velocity; :func:`render_top_view` renders
the sampling region seen from above with every particle drawn as a sphere
coloured by its diameter, as the paper's Figure 4.  Rendering is off-screen
(EGL unless ``VTK_DEFAULT_OPENGL_WINDOW`` says otherwise), so no display is
needed.

A frame is what :func:`analysis.metrics.dump.read_dump` returns: ``frame.atoms``, a
DataFrame with columns ``x, y, z, radius`` (m) and optionally ``id, type,
vx, vy, vz`` (m/s), and ``frame.box``, the (3, 2) box bounds in m.
"""

from __future__ import annotations

import os

import numpy as np

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
import pyvista  # noqa: E402  (after the render-window choice)
from vtkmodules.vtkCommonDataModel import vtkPlane  # noqa: E402

from analysis.io import atomic_path

pyvista.OFF_SCREEN = True


def particle_cloud(atoms):
    """Particles as pyvista point cloud.

    Parameters
    ----------
    atoms : pandas.DataFrame
        ``x, y, z, radius`` in m; ``id``, ``type`` and ``vx, vy, vz`` (m/s)
        are carried over when present.

    Returns
    -------
    pyvista.PolyData
        One vertex per particle; point data ``radius_m``, ``diameter_um`` and,
        when available, ``velocity_m_s`` (3-vector), ``speed_m_s``, ``id``,
        ``type``.
    """
    cloud = pyvista.PolyData(atoms[["x", "y", "z"]].to_numpy(float))
    radius = atoms["radius"].to_numpy(float)
    cloud.point_data["radius_m"] = radius
    cloud.point_data["diameter_um"] = 2e6 * radius
    if {"vx", "vy", "vz"} <= set(atoms.columns):
        velocity = atoms[["vx", "vy", "vz"]].to_numpy(float)
        cloud.point_data["velocity_m_s"] = velocity
        cloud.point_data["speed_m_s"] = np.linalg.norm(velocity, axis=1)
    for column in ("id", "type"):
        if column in atoms.columns:
            cloud.point_data[column] = atoms[column].to_numpy(np.int64)
    return cloud


def write_vtk(frame, path):
    """Write the frame's particles as VTK XML polydata for ParaView.

    Parameters
    ----------
    frame : analysis.metrics.dump.Frame
        Particles in m (see the module docstring).
    path : str or pathlib.Path
        Output ``.vtp`` file, written atomically.  Field data ``box_m`` holds
        the box bounds (xlo, xhi, ylo, yhi, zlo, zhi) in m.  In ParaView,
        show the points as "Point Gaussian" scaled by ``radius_m``, or apply
        a Glyph filter with sphere glyphs scaled by ``diameter_um``/1e6.

    Returns
    -------
    pathlib.Path
    """
    if not str(path).endswith(".vtp"):
        raise ValueError(f"VTK polydata goes to a .vtp file, not {path}")
    cloud = particle_cloud(frame.atoms)
    cloud.field_data["box_m"] = np.asarray(frame.box, float).ravel()
    with atomic_path(path) as tmp:
        cloud.save(tmp, binary=True)
    return path


def render_top_view(frame, region, path, clim=None, long_side_px=1600, sphere_resolution=12):
    """Render the sampling region from above, particles coloured by diameter.

    Parameters
    ----------
    frame : analysis.metrics.dump.Frame
        Particles in m.
    region : sequence of 4 float
        Sampling region ``(xmin, xmax, ymin, ymax)`` in m (also accepted as
        ``((xmin, xmax), (ymin, ymax))``).  Particles overlapping it are drawn,
        cut at its edges (clipping planes of the renderer).
    path : str or pathlib.Path
        Output PNG, written atomically.
    clim : (float, float), optional
        Colour range of the diameter in um; default: the range over the
        whole frame, so pictures of one run compare.
    long_side_px : int
        Image size along the region's longer side, px.
    sphere_resolution : int
        Facets around each sphere glyph.

    Returns
    -------
    pathlib.Path
    """
    x0, x1, y0, y1 = np.asarray(region, float).reshape(4)
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"empty sampling region {tuple(region)}")
    atoms = frame.atoms
    r = atoms["radius"].to_numpy(float)
    x, y = atoms["x"].to_numpy(float), atoms["y"].to_numpy(float)
    overlaps = (x + r > x0) & (x - r < x1) & (y + r > y0) & (y - r < y1)
    if not overlaps.any():
        raise ValueError(f"no particle in the sampling region x {x0}..{x1} m, y {y0}..{y1} m")
    if clim is None:
        clim = (2e6 * r.min(), 2e6 * r.max())
    if clim[1] <= clim[0]:       # one particle size: give the colour bar a span
        clim = (clim[0] - 1.0, clim[1] + 1.0)

    sphere = pyvista.Sphere(radius=1.0, theta_resolution=sphere_resolution,
                            phi_resolution=sphere_resolution)
    spheres = particle_cloud(atoms[overlaps]).glyph(geom=sphere, scale="radius_m", orient=False)

    # The region fills the left of the picture; the colour bar sits on the right.
    width, height = x1 - x0, y1 - y0
    scale = long_side_px / max(width, height)
    bar_px = 220
    window = (int(round(width * scale)) + bar_px, max(int(round(height * scale)), 300))
    plotter = pyvista.Plotter(off_screen=True, window_size=window)
    try:
        plotter.set_background("white")
        actor = plotter.add_mesh(
            spheres, scalars="diameter_um", cmap="viridis", clim=clim, smooth_shading=True,
            scalar_bar_args={"title": "Diameter\n(um)", "vertical": True, "color": "black",
                             "position_x": 1 - 0.85 * bar_px / window[0], "position_y": 0.08,
                             "height": 0.7, "width": 0.25 * bar_px / window[0],
                             "title_font_size": 18, "label_font_size": 16, "fmt": "%.0f"})
        for origin, normal in (((x0, 0, 0), (1, 0, 0)), ((x1, 0, 0), (-1, 0, 0)),
                               ((0, y0, 0), (0, 1, 0)), ((0, y1, 0), (0, -1, 0))):
            plane = vtkPlane()
            plane.SetOrigin(origin)
            plane.SetNormal(normal)
            actor.mapper.AddClippingPlane(plane)
        plotter.enable_parallel_projection()
        top = float(atoms["z"].max() + r.max())
        # Half the visible height; the visible width follows the window's aspect.
        half_h = 0.5 * window[1] / scale
        centre = (x0 + 0.5 * window[0] / scale, y0 + 0.5 * height, top)
        plotter.camera.focal_point = centre
        plotter.camera.position = (centre[0], centre[1], top + 10 * max(width, height))
        plotter.camera.up = (0.0, 1.0, 0.0)
        plotter.camera.parallel_scale = half_h
        plotter.reset_camera_clipping_range()
        with atomic_path(path) as tmp:
            plotter.screenshot(str(tmp))
    finally:
        plotter.close()
    return path
