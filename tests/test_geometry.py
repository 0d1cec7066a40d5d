"""Generated geometry: the substrate's roughness and the roller's shape."""
import numpy as np
import pytest
import yaml

from analysis.config.errors import ConfigError
from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.dem import geometry
from analysis.dem.simulate import make_geometry
from analysis.physics import polygon_circumradius
from tests.test_config import ROOT


@pytest.fixture(scope="module")
def meshes(config, tmp_path_factory):
    out = tmp_path_factory.mktemp("meshes")
    summary = make_geometry(config, "default", out)
    return out, summary


def _stl_height_grid(path):
    """The heights of a height-field STL on its node grid, read with numpy alone: x, y and
    z[i, j] [m] from the ASCII file's ``vertex`` lines (a node is repeated in each of its triangles)."""
    v = np.asarray([line.split()[1:] for line in path.read_text().splitlines()
                    if line.lstrip().startswith("vertex")], float)
    x, ix = np.unique(np.round(v[:, 0], 12), return_inverse=True)
    y, iy = np.unique(np.round(v[:, 1], 12), return_inverse=True)
    z = np.full((len(x), len(y)), np.nan)
    z[ix, iy] = v[:, 2]
    assert not np.isnan(z).any()                               # a full grid of nodes
    return x, y, z


def _surface_moments(x, z, x_range, m=8):
    """(mean height, Sq) [m] of the piecewise-linear surface over the grid's cells inside
    ``x_range``, by quadrature: its heights at m x m points of each cell, interpolated in the
    cell's triangle (nodes (i, j), (i+1, j), (i+1, j+1) below the diagonal, (i, j), (i+1, j+1),
    (i, j+1) above it), not by the closed form of `geometry.substrate_rms`."""
    i = np.flatnonzero((x >= x_range[0]) & (x <= x_range[1]))[:-1]
    za, zb, zc, zd = z[i, :-1], z[i + 1, :-1], z[i + 1, 1:], z[i, 1:]
    t = (np.arange(m) + 0.5) / m
    heights = np.asarray([za + u * (zb - za) + v * (zc - zb) if u >= v else za + v * (zd - za) + u * (zc - zd)
                          for u in t for v in t])
    return heights.mean(), np.sqrt(np.mean((heights - heights.mean()) ** 2))


def test_substrate_sq_and_correlation_length_measured_from_the_stl(config, meshes):
    """The sampling region has the target Sq, and the rough part around it (the region, half a mm
    before it and the level's ``rough_past_mm`` past it) is one field with the target correlation
    length, measured from the written STL's vertices with numpy alone (the generator scales with
    `geometry.substrate_rms`: not used here); the rest of the rough part is the same field, its Sq as it falls."""
    out, summary = meshes
    s = scene(config, "default")
    target = config["substrate"]["sq_um"] * 1e-6
    x, y, z = _stl_height_grid(out / "substrate.stl")
    region_mean, region_sq = _surface_moments(x, z, s.sampling_region[:2])
    assert region_sq == pytest.approx(target, rel=0.02)
    mean, sq = _surface_moments(x, z, s.rough_x)
    # The field is scaled so that the region has the target; the rough part (4 mm, 3 of them the
    # region's) falls where its field does: 0.94-1.04 of the target over seeds 7-12.
    assert sq == pytest.approx(target, rel=0.1)
    assert abs(mean) < 0.2 * target                            # mean plane at z = 0
    assert summary["substrate_sq_m"] == pytest.approx(region_sq, rel=0.01)
    assert summary["substrate_mean_m"] == pytest.approx(region_mean, abs=0.01 * target)
    assert summary["substrate_peak_m"] == pytest.approx(z.max())
    assert z.max() - region_mean == pytest.approx(s.substrate["peak_cap"], rel=1e-3)   # capped under the gap
    # The field's autocorrelation is exp(-r^2 / lc^2): at a lag of lc along the travel the rough
    # nodes' normalised autocovariance is 1/e, so lc = lag / sqrt(-ln C(lag)). Over the default's
    # 4 x 1.2 mm (about 50 correlation areas) this estimate scatters by about 10 % between seeds.
    lc = config["substrate"]["correlation_length_um"] * 1e-6
    rough_x = x[(x >= s.rough_x[0]) & (x <= s.rough_x[1])]
    h = z[(x >= s.rough_x[0]) & (x <= s.rough_x[1]), :-1]      # the last column repeats the first
    h = h - h.mean()
    spacing = np.diff(rough_x).mean()
    lag = int(round(lc / spacing))
    c = np.mean(h[:-lag] * h[lag:]) / np.mean(h**2)
    assert lag * spacing / np.sqrt(-np.log(c)) == pytest.approx(lc, rel=0.15)


def test_substrate_covers_the_box_and_is_seamless_across_the_periodic_strip(config, meshes):
    out, _ = meshes
    s = scene(config, "default")
    v = geometry.load_stl(out / "substrate.stl").vertices
    assert v[:, 0].min() <= s.box[0] and v[:, 0].max() >= s.box[1]
    assert v[:, 1].min() == pytest.approx(0) and v[:, 1].max() == pytest.approx(s.strip_width)
    edge0, edge1 = v[np.isclose(v[:, 1], 0)], v[np.isclose(v[:, 1], s.strip_width)]
    z0 = dict(zip(np.round(edge0[:, 0], 9), edge0[:, 2]))
    z1 = dict(zip(np.round(edge1[:, 0], 9), edge1[:, 2]))
    assert z0.keys() == z1.keys() and all(z0[k] == pytest.approx(z1[k]) for k in z0)


def test_random_field_is_gaussian_with_a_gaussian_autocorrelation_of_its_length():
    """What the rescaling to the target RMS does not force: the heights' distribution is Gaussian
    (skewness 0, kurtosis 3, 68.3 % within one sd) and their autocorrelation is exp(-r^2 / lc^2)
    along both axes (at lc / 2, lc and 2 lc: 0.779, 0.368, 0.018). 256 x 256 nodes at lc / 6
    hold about 1800 correlation areas: the estimates scatter by about 0.03 between seeds."""
    lc, spacing = 300e-6, 50e-6
    z = geometry.gaussian_random_field(256, 256, spacing, lc, 79e-6, seed=3)
    h = (z - z.mean()) / z.std()
    assert abs(np.mean(h**3)) < 0.2
    assert np.mean(h**4) == pytest.approx(3.0, abs=0.3)
    assert np.mean(np.abs(h) < 1) == pytest.approx(0.683, abs=0.02)
    for axis in (0, 1):
        for r in (lc / 2, lc, 2 * lc):
            lag = int(round(r / spacing))
            c = np.mean(h * np.roll(h, lag, axis=axis))            # the field is periodic
            assert c == pytest.approx(np.exp(-(lag * spacing / lc) ** 2), abs=0.06), (axis, r)


def test_roller_is_a_watertight_cylinder_of_the_papers_size():
    r = geometry.roller(0.030, 0.070, 180)
    assert r.is_watertight and r.is_winding_consistent and r.volume > 0
    lo, hi = r.bounds
    assert hi[1] - lo[1] == pytest.approx(0.070)                   # length along y
    assert hi[0] - lo[0] == pytest.approx(0.030, rel=1e-3)         # diameter
    assert hi[2] - lo[2] == pytest.approx(0.030, rel=1e-3)
    assert r.volume == pytest.approx(np.pi * 0.015**2 * 0.070, rel=1e-3)
    lateral = np.abs(r.face_normals[:, 1]) < 0.5
    radial = r.triangles_center[lateral][:, [0, 2]]
    assert np.all(np.sum(radial * r.face_normals[lateral][:, [0, 2]], 1) > 0)   # outward


def test_roller_shell_has_no_end_caps(config, meshes):
    out, _ = meshes
    shell = geometry.load_stl(out / "roller_shell.stl")
    assert not shell.is_watertight
    assert np.allclose(np.abs(shell.face_normals[:, 1]), 0, atol=1e-9)
    assert np.allclose(np.hypot(shell.vertices[:, 0], shell.vertices[:, 2]),
                       polygon_circumradius(0.015, config["roller"]["facets_around"]))


def _bottom_depth_over_a_turn(mesh, turns=7200):
    """The lowest point's depth below the axis at each of ``turns`` angles of a turn, from the
    vertices alone (a polygon's lowest point is a vertex)."""
    angle = np.linspace(0.0, 2 * np.pi, turns, endpoint=False)
    x, z = mesh.vertices[:, 0], mesh.vertices[:, 2]
    # the mesh turned by `angle` about y: a vertex at (x, z) goes to z' = z cos a - x sin a
    return np.max(-(z[None, :] * np.cos(angle)[:, None] - x[None, :] * np.sin(angle)[:, None]), axis=1)


@pytest.mark.parametrize("facets", [12, 90])
def test_roller_polygon_keeps_the_mean_gap_over_a_turn_and_at_rest(facets):
    """A polygon's bottom swings between its inradius and circumradius as it turns; the roller's
    polygon is sized so that the bottom's mean over a turn is the roller's radius, and built turned
    so that a still roller's bottom is there too (the gap as set, whatever omega)."""
    R = 0.015
    shell = geometry.roller(2 * R, 0.001, facets, capped=False)
    depth = _bottom_depth_over_a_turn(shell)
    assert depth.mean() == pytest.approx(R, rel=1e-6)
    assert depth[0] == pytest.approx(R, rel=1e-9)                        # as built: the still roller
    half = np.pi / facets                                                 # the swing, by hand
    rc = R * half / np.sin(half)
    assert depth.max() == pytest.approx(rc, rel=1e-5)                    # (sampled angles: within 1e-5)
    assert depth.min() == pytest.approx(rc * np.cos(half), rel=1e-4)


def test_gap_is_set_from_the_sampling_regions_mean_plane(config):
    """Over a tilted bed (z = a + b x) the region's mean plane is not the field's: the roller's
    axis stands gap + R above the mean height under the sampling region, a + b x_mid."""
    from analysis.dem.geometry import roller_gap
    s = scene(config, "smoke")
    a, b = 20e-6, 4e-3
    x = np.linspace(s.box[0], s.box[1], 401)
    y = np.linspace(0.0, s.strip_width, 5)
    bed = geometry.height_field_mesh(x, y, a + b * np.repeat(x[:, None], len(y), axis=1))
    shell = geometry.roller(2 * s.roller_radius, s.strip_width, s.roller_facets, capped=False)
    gap = roller_gap(s, bed, shell)
    x_mid = np.mean(s.sampling_region[:2])
    field_mean = a + b * np.mean(s.box[:2])
    assert abs(field_mean - (a + b * x_mid)) > 2e-6                     # the two datums differ here
    assert gap["substrate_mean_region_m"] == pytest.approx(a + b * x_mid, abs=0.5e-6)
    assert gap["axis_z_m"] == pytest.approx(a + b * x_mid + s.roller_gap + s.roller_radius, abs=0.5e-6)
    assert gap["effective_gap_um"] == pytest.approx(s.roller_gap * 1e6, abs=0.01)
    assert gap["gap_min_um"] < gap["effective_gap_um"] < gap["gap_max_um"]


def test_users_stl_replaces_the_generated_substrate(config, tmp_path):
    s = scene(config, "smoke")
    x = np.arange(s.box[0], s.box[1] + 2e-5, 2e-5)
    y = np.linspace(0, s.strip_width, 11)
    z = 40e-6 * np.sin(2 * np.pi * x / 1e-3)[:, None] * np.ones(len(y))
    geometry.write_stl(geometry.height_field_mesh(x, y, z), tmp_path / "mine.stl")
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"]["mesh"] = str(tmp_path / "mine.stl")
    summary = make_geometry(load_config(mine), "smoke", tmp_path / "out")
    assert summary["substrate_sq_m"] == pytest.approx(40e-6 / np.sqrt(2), rel=0.02)


def test_users_stl_too_small_for_the_bed_is_refused(config, tmp_path):
    flat = geometry.height_field_mesh(np.linspace(0, 1e-3, 3), np.linspace(0, 1e-3, 3), np.zeros((3, 3)))
    geometry.write_stl(flat, tmp_path / "small.stl")
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"]["mesh"] = str(tmp_path / "small.stl")
    with pytest.raises(ConfigError, match="substrate.mesh"):
        make_geometry(load_config(mine), "smoke", tmp_path / "out")


def test_users_substrate_reaching_the_roller_is_refused(config, tmp_path):
    """A user's surface with a peak 1.2 gaps above its mean plane under the sampling region."""
    s = scene(config, "smoke")
    x, y = np.linspace(*s.substrate_x, 60), np.linspace(0.0, s.strip_width, 5)
    z = np.zeros((len(x), len(y)))
    z[np.argmin(np.abs(x - np.mean(s.sampling_region[:2]))), 2] = 1.2 * s.roller_gap
    geometry.write_stl(geometry.height_field_mesh(x, y, z), tmp_path / "peak.stl")
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"]["mesh"] = str(tmp_path / "peak.stl")
    with pytest.raises(ConfigError, match="roller.gap_um"):
        make_geometry(load_config(mine), "smoke", tmp_path / "out")


@pytest.mark.parametrize("key, value", [("peak_cap_fraction_of_gap", 0.5), ("sq_um", 200)])
def test_peak_cap_under_two_sq_is_refused_by_name(key, value):
    """0.5 x 300 um is 1.9 Sq at 79 um; 0.6 x 300 um is 0.9 Sq at 200 um: each clips more
    than a Gaussian surface's 2.3 % above 2 Sq."""
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"][key] = value
    with pytest.raises(ConfigError, match="substrate.peak_cap_fraction_of_gap"):
        load_config(mine)


def test_peak_cap_is_the_configs_fraction_of_the_gap_above_the_regions_mean_plane(tmp_path):
    """At 0.6 x the gap the default's first field (its highest node 193 um above the region's mean
    plane) is clipped 180 um above it (measured after the clip), its region's Sq the configured one."""
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"]["peak_cap_fraction_of_gap"] = 0.6
    summary = make_geometry(load_config(mine), "default", tmp_path / "a")
    assert summary["substrate_peak_m"] - summary["substrate_mean_m"] == pytest.approx(0.6 * 300e-6, rel=1e-3)
    assert summary["substrate_sq_m"] == pytest.approx(79e-6, rel=1e-3)


def test_paper_level_substrate_is_made_with_peaks_clipped_below_the_roller(config):
    """The paper's 25 x 70 mm rough field reaches 4.5 Sq, through the 300 um gap,
    unless its rare highest nodes are clipped; clipped, it is scaled to hold the region's Sq at 79 um."""
    s = scene(config, "paper")
    unclipped = geometry.rough_substrate(s.substrate_x, s.strip_width, 100e-6, 300e-6, 79e-6, 7,
                                         rough_x=s.rough_x, taper=0.5e-3)
    assert unclipped.vertices[:, 2].max() > s.roller_gap          # what the cap is for
    clipped = geometry.rough_substrate(s.substrate_x, s.strip_width, 100e-6, 300e-6, 79e-6, 7,
                                       rough_x=s.rough_x, taper=0.5e-3, peak_cap=s.substrate["peak_cap"])
    fraction = config["substrate"]["peak_cap_fraction_of_gap"]
    assert s.substrate["peak_cap"] == pytest.approx(fraction * s.roller_gap)
    assert clipped.vertices[:, 2].max() == pytest.approx(fraction * s.roller_gap)
    # a Gaussian field's share above 2.3 Sq (0.6 x 300 um over 79 um) is 1.1 %
    assert np.mean(clipped.vertices[:, 2] >= fraction * s.roller_gap) < 0.02
    assert geometry.substrate_rms(clipped, s.rough_x)[1] == pytest.approx(79e-6, rel=1e-3)


def _stl_triangles(path):
    """Triangles (n, 3, 3) [m] of an ASCII STL, read with numpy alone."""
    lines = [line.split()[1:] for line in path.read_text().splitlines() if line.lstrip().startswith("vertex")]
    return np.asarray(lines, float).reshape(-1, 3, 3)


def test_rough_field_has_its_sq_and_correlation_length_measured_from_the_stl(tmp_path):
    """Sq and the correlation length measured from the written STL, independently of the
    generator: Sq as the area-weighted RMS of the piecewise-linear surface (a linear
    triangle's mean z^2 is (sum z_i^2 + sum_{i<j} z_i z_j) / 6), and lc as the e-folding
    length of the heights' autocorrelation along x (Gaussian field: exp(-r^2/lc^2))."""
    lc, sq, spacing = 300e-6, 79e-6, 50e-6
    mesh = geometry.rough_substrate((0.0, 0.012), 0.012, spacing, lc, sq, seed=5)
    path = geometry.write_stl(mesh, tmp_path / "field.stl")
    tri = _stl_triangles(path)
    z = tri[:, :, 2]
    (ax, ay), (bx, by) = (tri[:, 1, :2] - tri[:, 0, :2]).T, (tri[:, 2, :2] - tri[:, 0, :2]).T
    area = 0.5 * np.abs(ax * by - ay * bx)
    mean_z2 = ((z ** 2).sum(1) + z[:, 0] * z[:, 1] + z[:, 1] * z[:, 2] + z[:, 0] * z[:, 2]) / 6
    mean_z = z.mean(1)
    assert np.sqrt(np.sum(area * mean_z2) / area.sum() - (np.sum(area * mean_z) / area.sum()) ** 2) == \
        pytest.approx(sq, rel=0.02)
    # the nodes' heights on their grid, from the vertices
    v = np.unique(tri.reshape(-1, 3).round(12), axis=0)
    xs, ys = np.unique(v[:, 0]), np.unique(v[:, 1])
    heights = np.full((len(xs), len(ys)), np.nan)
    heights[np.searchsorted(xs, v[:, 0]), np.searchsorted(ys, v[:, 1])] = v[:, 2]
    heights = heights[:, :-1] - heights[:, :-1].mean()       # the last row repeats the first (periodic)
    spectrum = np.abs(np.fft.fft(heights, axis=0)) ** 2
    acf = np.fft.ifft(spectrum, axis=0).real.mean(axis=1)
    acf /= acf[0]
    lag = np.arange(len(acf)) * spacing
    k = np.argmax(acf < np.exp(-1))
    e_fold = lag[k - 1] + (np.exp(-1) - acf[k - 1]) / (acf[k] - acf[k - 1]) * spacing
    assert e_fold == pytest.approx(lc, rel=0.1)


def test_users_surface_in_any_meshio_format_replaces_the_generated_substrate(config, tmp_path):
    """substrate.mesh may be a PLY or VTK as well as an STL (meshio reads it); the
    geometry step writes it as substrate.stl for LIGGGHTS, unchanged."""
    import meshio
    s = scene(config, "smoke")
    x = np.arange(s.box[0], s.box[1] + 2e-5, 2e-5)
    y = np.linspace(0, s.strip_width, 11)
    z = 40e-6 * np.sin(2 * np.pi * x / 1e-3)[:, None] * np.ones(len(y))
    field = geometry.height_field_mesh(x, y, z)
    for name in ("mine.ply", "mine.vtk"):
        meshio.write(tmp_path / name, meshio.Mesh(field.vertices, [("triangle", field.faces)]))
        mine = yaml.safe_load((ROOT / "config.yaml").read_text())
        mine["substrate"]["mesh"] = str(tmp_path / name)
        summary = make_geometry(load_config(mine), "smoke", tmp_path / name.replace(".", "_"))
        assert summary["substrate_sq_m"] == pytest.approx(40e-6 / np.sqrt(2), rel=0.02), name
        written = geometry.load_stl(tmp_path / name.replace(".", "_") / "substrate.stl")
        assert len(written.faces) == len(field.faces)
        assert np.allclose(written.vertices[written.faces], field.vertices[field.faces], atol=1e-9)


def test_a_surface_without_triangles_is_refused_by_key(config, tmp_path):
    import meshio
    meshio.write(tmp_path / "points.vtk", meshio.Mesh(np.random.default_rng(0).random((5, 3)),
                                                         [("vertex", np.arange(5)[:, None])]))
    mine = yaml.safe_load((ROOT / "config.yaml").read_text())
    mine["substrate"]["mesh"] = str(tmp_path / "points.vtk")
    with pytest.raises(ConfigError, match="substrate.mesh.*no triangles"):
        make_geometry(load_config(mine), "smoke", tmp_path / "out")


@pytest.mark.parametrize("case", ["out_is_a_file", "nan_in_config"])
def test_simulate_cli_reports_one_line_and_writes_nothing(tmp_path, case):
    """``spreadmap-simulate`` names the file and the OS's cause, or the bad key, in one line."""
    import subprocess
    import sys
    config = tmp_path / "config.yaml"
    text = (ROOT / "config.yaml").read_text()
    if case == "nan_in_config":
        text = text.replace("restitution: 0.6", "restitution: .nan")
    config.write_text(text)
    out = tmp_path / "meshes"
    if case == "out_is_a_file":
        out.write_text("not a folder")
    res = subprocess.run([sys.executable, "-m", "analysis.dem.simulate", "geometry", "--config", str(config),
                          "--level", "smoke", "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert res.returncode != 0 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("spreadmap-simulate: error: "), res.stderr
    assert (f"{out}: File exists" if case == "out_is_a_file" else "'material.restitution' = nan") in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.yaml", "meshes"][: 1 + (case == "out_is_a_file")]


def test_health_and_profilometer_see_one_substrate(tmp_path):
    """The health checks' substrate under scattered points (particle centres) is the
    profilometer's (the mesh's own triangles) within 2 um on a rough field (Sq 79 um)."""
    from analysis.dem.health import substrate_height_at
    from analysis.metrics.profilometer import probe_lines, substrate_height
    mesh = geometry.rough_substrate((-0.004, 0.012), 0.0012, 100e-6, 300e-6, 79e-6, seed=3, rough_x=(0.0, 0.008),
                                    taper=0.5e-3)
    path = geometry.write_stl(mesh, tmp_path / "substrate.stl")
    xs, ys = probe_lines((0.001, 0.007, 0.0, 0.0012), 200, seed=1)
    grid = substrate_height(str(path), xs, ys)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    assert np.abs(substrate_height_at(path)(X, Y) - grid).max() < 2e-6  # 22 um with a Delaunay of the vertices
    assert grid.std() > 50e-6  # a rough surface, not a trivially flat one
