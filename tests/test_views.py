"""VTK export and top-view picture of a tiny hand-written dump."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import pyvista
from PIL import Image

from analysis.viz.views import render_top_view, write_vtk

# 7 particles in m: six in a 1 mm x 0.6 mm sampling region, one far outside.
DUMP = """\
ITEM: TIMESTEP
5000
ITEM: NUMBER OF ATOMS
7
ITEM: BOX BOUNDS pp pp ff
-0.001 0.003
0.0 0.0006
-0.0005 0.001
ITEM: ATOMS id type x y z radius vx vy vz 
1 1 0.0001 0.0001 0.00005 5e-05 0.01 0 0
2 1 0.0003 0.0002 0.00006 6e-05 0 0.02 0
3 1 0.0005 0.0003 0.00007 7.5e-05 0 0 -0.03
4 1 0.0007 0.0004 0.00008 0.0001 0.1 0 0
5 1 0.0009 0.0005 0.00009 0.000125 0 0 0
6 1 0.0006 0.0001 0.00005 8e-05 0 0 0
7 1 0.0025 0.0003 0.00005 0.000125 0 0 0
"""
REGION = (0.0, 0.001, 0.0, 0.0006)          # xmin, xmax, ymin, ymax [m]


@pytest.fixture
def frame(tmp_path):
    """The dump read by analysis.metrics.dump.read_dump."""
    read_dump = pytest.importorskip("analysis.metrics.dump").read_dump
    path = tmp_path / "final.dump"
    path.write_text(DUMP)
    return read_dump(path)


def test_write_vtk_has_every_particle_with_its_data(frame, tmp_path):
    path = write_vtk(frame, tmp_path / "final.vtp")
    cloud = pyvista.read(path)
    assert cloud.n_points == 7 and cloud.n_verts == 7
    assert np.allclose(cloud.points[3], [0.0007, 0.0004, 0.00008])
    assert np.allclose(cloud["diameter_um"], [100, 120, 150, 200, 250, 160, 250])
    assert np.allclose(cloud["radius_m"][0], 5e-5)
    assert cloud["velocity_m_s"].shape == (7, 3)
    assert np.allclose(cloud["velocity_m_s"][2], [0, 0, -0.03])
    assert np.allclose(cloud.field_data["box_m"], [-0.001, 0.003, 0, 0.0006, -0.0005, 0.001])
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".vtp"] == ["final.vtp"]


def test_write_vtk_wants_vtp(frame, tmp_path):
    with pytest.raises(ValueError, match=".vtp"):
        write_vtk(frame, tmp_path / "final.vtk")


def test_top_view_png_shows_the_region(frame, tmp_path):
    path = render_top_view(frame, REGION, tmp_path / "top.png", long_side_px=600)
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    assert path.stat().st_size > 5_000
    assert image.shape == (360, 600 + 220, 3)          # region 1 x 0.6 mm at 600 px/mm + bar
    region = image[:, :600]
    coloured = np.abs(region - region.mean(axis=2, keepdims=True)).sum(axis=2) > 30
    assert 0.2 < coloured.mean() < 0.9                   # spheres on a white background
    # The largest particle (250 um, id 5) is yellow at the top of viridis.
    x, y = 0.0009 * 600 / 0.001, (0.0006 - 0.0005) * 600 / 0.001
    r, g, b = image[int(y), int(x)]
    assert r > 150 and g > 150 and b < 120


def test_top_view_of_an_empty_region_is_refused(frame, tmp_path):
    with pytest.raises(ValueError, match="no particle"):
        render_top_view(frame, (0.01, 0.02, 0.0, 0.0006), tmp_path / "top.png")


def test_top_view_without_the_dump_reader(tmp_path):
    """A bare frame (atoms DataFrame and box) is enough; region as ((x), (y))."""
    atoms = pd.DataFrame({"x": [0.2e-3, 0.6e-3], "y": [0.3e-3, 0.3e-3], "z": [0.0, 0.0],
                          "radius": [1e-4, 1e-4]})
    bare = SimpleNamespace(atoms=atoms, box=np.array([[0, 1e-3], [0, 6e-4], [0, 1e-3]]))
    path = render_top_view(bare, ((0, 1e-3), (0, 6e-4)), tmp_path / "top.png",
                           long_side_px=400)
    assert Image.open(path).size == (400 + 220, 300)
    write_vtk(bare, tmp_path / "bare.vtp")
    assert pyvista.read(tmp_path / "bare.vtp").n_points == 2
