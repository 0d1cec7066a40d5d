"""Tests of analysis.metrics.profilometer against hand-derived answers.

Sphere caps. A sphere of radius r resting on the plane z = b has its top at
b + r + s(rho) over the disc rho < r, with s = sqrt(r^2 - rho^2), and the
integral of s^k over the disc is 2 pi r^(k+2) / (k+2); the expected means
and roughnesses below follow from these integrals in closed form.

Sampling tolerances. The profilometer averages f over the n x n probes
(X_i, Y_j), X and Y independent and uniform over the region. The variance of
this two-sample U-statistic (Hoeffding decomposition) is at most
Var_x(E_y f)/n + Var_y(E_x f)/n + Var(f)/n^2. The tests evaluate the exact
f (or the linearised influence function of R_q) on a fine midpoint grid to
get these marginal variances, and allow K of the resulting standard errors.
"""

import gzip
import json
import math
import re
import resource
import signal
import subprocess
import sys
from math import comb, pi
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh

import analysis.metrics.profilometer as lm
from analysis.io import error_line
from analysis.metrics.dump import read_dump, write_dump
from analysis.metrics.profilometer import layer_top, periodic_images, probe_lines, substrate_height
from analysis.metrics.spread_layer import (
    layer_porosity,
    layer_roughness,
    powder_mass,
    spread_layer_metrics,
    spread_throughput,
    to_report_units,
)

K = 4.0  # tolerance in standard errors
RHO = 4430.0  # Ti-6Al-4V [kg/m3]
U = 0.05  # [m/s]
REPO = Path(__file__).resolve().parents[1]


def disc_integral(k, r):
    """Integral of (r^2 - rho^2)^(k/2) over the disc of radius r [m^(k+2)]."""
    return 2 * pi * r ** (k + 2) / (k + 2)


def resting_sphere_moments(r, cell_area):
    """Mean and RMS roughness of h - b over a cell holding one sphere resting on a plane.

    Over the disc h - b = r + s; elsewhere 0. E[h - b] = (pi r^3 + 2/3 pi r^3)/A
    and E[(h - b)^2] = (pi r^4 + 4/3 pi r^4 + 1/2 pi r^4)/A, from `disc_integral`.
    """
    m1, m2 = (sum(comb(k, j) * r ** (k - j) * disc_integral(j, r) for j in range(k + 1)) / cell_area for k in (1, 2))
    return m1, math.sqrt(m2 - m1**2)


def resting_sphere_top(px, py, xc, yc, r):
    """Exact h - b at points (px, py) for a sphere of radius r resting at (xc, yc)."""
    d2 = (px - xc) ** 2 + (py - yc) ** 2
    return np.where(d2 < r * r, r + np.sqrt(np.abs(r * r - d2)), 0.0)


def midpoints(x0, x1, y0, y1, m=800):
    """Midpoint grid (m x m) over a rectangle, for quadrature of the marginals."""
    x = x0 + (np.arange(m) + 0.5) * (x1 - x0) / m
    y = y0 + (np.arange(m) + 0.5) * (y1 - y0) / m
    return np.meshgrid(x, y, indexing="ij")


def probe_se(f, n):
    """Standard error of the mean of f over n x n random-line probes (f on a midpoint grid)."""
    return math.sqrt(f.mean(axis=1).var() / n + f.mean(axis=0).var() / n + f.var() / n**2)


def tolerances(f, mean, r_q, n):
    """K-SE tolerances on the probe estimates of mean(h) and R_q, f = exact h on a grid."""
    tol_mean = K * probe_se(f, n)
    psi = ((f - mean) ** 2 - r_q**2) / (2 * r_q)  # influence function of R_q
    return tol_mean, K * probe_se(psi, n) + tol_mean**2 / (2 * r_q)


def spheres(x, y, z, r):
    """An atoms table from centre coordinates and radii [m]."""
    x, y, z, r = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (x, y, z, r)))
    return pd.DataFrame({"id": np.arange(1, x.size + 1), "x": x.ravel(), "y": y.ravel(), "z": z.ravel(),
                         "radius": r.ravel()})


def lattice(r, a, cells, z0=0.0):
    """Square lattice of spheres (radius r, spacing a) resting on z = z0, over [0, cells*a]^2."""
    c = (np.arange(cells) + 0.5) * a
    x, y = np.meshgrid(c, c, indexing="ij")
    return spheres(x, y, z0 + r, r)


def polydisperse(n, region, seed, margin=300e-6):
    """Random overlapping polydisperse spheres, some centred outside region."""
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = region
    r = rng.uniform(50e-6, 125e-6, n)
    return spheres(rng.uniform(xmin - margin, xmax + margin, n), rng.uniform(ymin - margin, ymax + margin, n),
                   rng.uniform(0, 400e-6, n), r)


def brute_force_top(atoms, xs, ys, base):
    """h at every probe by checking every sphere (small inputs only)."""
    px, py = np.meshgrid(xs, ys, indexing="ij")
    d2 = (px[..., None] - atoms.x.values) ** 2 + (py[..., None] - atoms.y.values) ** 2
    cap = np.where(d2 <= atoms.radius.values**2, atoms.z.values + np.sqrt(np.abs(atoms.radius.values**2 - d2)),
                   -np.inf)
    return np.maximum(base, cap.max(axis=-1))


# ---------------------------------------------------------------- building blocks


def test_probe_lines_are_sorted_uniform_and_seeded():
    region = (1e-3, 3e-3, -2e-3, 0.0)
    xs, ys = probe_lines(region, 5000, seed=4)
    assert xs.shape == ys.shape == (5000,)
    assert np.all(np.diff(xs) >= 0) and np.all(np.diff(ys) >= 0)
    assert 1e-3 <= xs.min() and xs.max() <= 3e-3 and -2e-3 <= ys.min() and ys.max() <= 0.0
    # mean of U(a, b): sd (b - a)/sqrt(12 n)
    assert abs(xs.mean() - 2e-3) < K * 2e-3 / math.sqrt(12 * 5000)
    np.testing.assert_array_equal(xs, probe_lines(region, 5000, seed=4)[0])
    assert not np.array_equal(xs, probe_lines(region, 5000, seed=5)[0])


def test_layer_top_matches_brute_force_and_is_chunk_independent(monkeypatch):
    region = (0.0, 1e-3, 0.0, 1e-3)
    atoms = polydisperse(300, region, seed=1)
    xs, ys = probe_lines(region, 80, seed=2)
    base = np.full((80, 80), 1e-4)
    expected = brute_force_top(atoms, xs, ys, base)
    got = layer_top(atoms[["x", "y", "z"]].to_numpy(), atoms.radius.to_numpy(), xs, ys, base)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)
    monkeypatch.setattr(lm, "MAX_PAIRS", 50)  # many small chunks
    chunked = layer_top(atoms[["x", "y", "z"]].to_numpy(), atoms.radius.to_numpy(), xs, ys, base)
    np.testing.assert_array_equal(chunked, got)


def test_small_formulas():
    d = np.array([100e-6, 200e-6])
    assert powder_mass(d, RHO) == pytest.approx(pi * RHO / 6 * (1e-12 + 8e-12), rel=1e-14)
    assert spread_throughput(0.1, 50e-6) == pytest.approx(5e-6)
    assert layer_roughness([1.0, 3.0, 1.0, 3.0]) == pytest.approx(1.0)
    assert layer_porosity(RHO * 2e-9, RHO, 1e-3, 1e-3, 1e-3) == pytest.approx(50.0)
    assert math.isnan(layer_porosity(0.0, RHO, 1e-3, 1e-3, 0.0))


# ---------------------------------------------------------------- analytic layers


def test_empty_region_over_flat_substrate():
    region = (0.0, 2e-3, 0.0, 2e-3)
    far = spheres([10e-3, -5e-3], [1e-3, 1e-3], [1e-4, 1e-4], [1e-4, 1e-4])  # nowhere near the region
    m = spread_layer_metrics(far, region, U, RHO, substrate=0.25e-3, n_lines=200)
    assert m["M_s"] == 0.0 and m["n_particles"] == 0
    assert m["b_avg"] == m["h_avg"] == pytest.approx(0.25e-3, rel=1e-14)
    assert m["thk_avg"] == 0.0 and m["Q_s"] == 0.0 and m["R_q"] == 0.0
    assert m["coverage"] == 0.0 and m["n_probes"] == 200**2
    assert math.isnan(m["Phi"]) and math.isnan(m["packing_fraction"])
    report = to_report_units(m)
    assert report["porosity_pct"] is None and report["b_avg_um"] == pytest.approx(250.0)
    json.dumps(report, allow_nan=False)  # strict JSON


def test_one_sphere_resting_on_a_raised_plane():
    r, z0, n = 100e-6, 0.4e-3, 1000
    region = (-120e-6, 140e-6, -130e-6, 110e-6)  # disc inside, sphere off-centre
    area = 260e-6 * 240e-6
    m = spread_layer_metrics(spheres(0, 0, z0 + r, r), region, U, RHO, substrate=z0, n_lines=n, seed=1)
    thk, r_q = resting_sphere_moments(r, area)
    assert thk == pytest.approx(5 / 3 * pi * r**3 / area)
    f = resting_sphere_top(*midpoints(*region), 0, 0, r)
    tol_mean, tol_rq = tolerances(f, thk, r_q, n)
    p = pi * r**2 / area
    assert m["M_s"] == pytest.approx(pi * RHO * (2 * r) ** 3 / 6, rel=1e-14)
    assert m["n_particles"] == 1
    assert m["b_avg"] == pytest.approx(z0, rel=1e-15)
    assert m["thk_avg"] == pytest.approx(thk, abs=tol_mean)
    assert m["h_avg"] - m["b_avg"] == pytest.approx(m["thk_avg"], rel=1e-12)
    assert m["R_q"] == pytest.approx(r_q, abs=tol_rq)
    assert m["coverage"] == pytest.approx(p, abs=K * probe_se((f > 0).astype(float), n))
    assert m["Q_s"] == pytest.approx(U * m["thk_avg"], rel=1e-15)


def test_cap_of_a_particle_centred_outside_counts_for_h_not_mass():
    r, n = 100e-6, 1000
    region = (0.0, 400e-6, 0.0, 400e-6)
    # centred r/2 beyond x = 400 um: a circular segment of its disc lies inside
    m = spread_layer_metrics(spheres(400e-6 + r / 2, 200e-6, r, r), region, U, RHO, n_lines=n)
    segment = r**2 * math.acos(0.5) - (r / 2) * math.sqrt(r**2 - (r / 2) ** 2)
    p = segment / 400e-6**2
    covered = resting_sphere_top(*midpoints(*region), 400e-6 + r / 2, 200e-6, r) > 0
    assert m["M_s"] == 0.0 and m["n_particles"] == 0
    assert m["coverage"] == pytest.approx(p, abs=K * probe_se(covered.astype(float), n))
    assert m["h_avg"] > 0


def lattice_cell(r, a):
    """Exact h - b over one lattice cell (periodic, so its marginals are the region's)."""
    return resting_sphere_top(*midpoints(0, a, 0, a), a / 2, a / 2, r)


@pytest.mark.parametrize("r, a", [(50e-6, 125e-6), (60e-6, 120e-6)])  # gaps, and touching spheres
def test_lattice_monolayer_mean_and_roughness_converge(r, a):
    cells = 8
    region = (0.0, cells * a, 0.0, cells * a)
    atoms = lattice(r, a, cells)
    thk, r_q = resting_sphere_moments(r, a * a)
    errors = {}
    for n in (100, 1000):
        tol_mean, tol_rq = tolerances(lattice_cell(r, a), thk, r_q, n)
        err = []
        for seed in range(6):
            m = spread_layer_metrics(atoms, region, U, RHO, n_lines=n, seed=seed)
            assert m["thk_avg"] == pytest.approx(thk, abs=tol_mean)
            assert m["R_q"] == pytest.approx(r_q, abs=tol_rq)
            err.append(m["thk_avg"] - thk)
        errors[n] = math.sqrt(np.mean(np.square(err)))
    # error ~ 1/sqrt(n): expect a factor sqrt(10) ~ 3.2 between 100 and 1000 lines
    assert errors[1000] < errors[100] / 2


def test_lattice_mass_porosity_and_packing_fraction():
    r, a, cells, n, z0 = 50e-6, 125e-6, 8, 1000, -0.1e-3
    region = (0.0, cells * a, 0.0, cells * a)
    m = spread_layer_metrics(lattice(r, a, cells, z0), region, U, RHO, substrate=z0, n_lines=n, seed=3)
    thk, r_q = resting_sphere_moments(r, a * a)
    f = lattice_cell(r, a)
    tol_mean, tol_rq = tolerances(f, thk, r_q, n)
    m_s = cells**2 * pi * RHO * (2 * r) ** 3 / 6
    assert m["M_s"] == pytest.approx(m_s, rel=1e-12)
    assert m["n_particles"] == cells**2
    # eq. 7 with the lattice's M_s and R_q: Phi = 1 - (pi d^3/6) / (a^2 4 R_q)
    phi = (1 - (pi * (2 * r) ** 3 / 6) / (a * a * 4 * r_q)) * 100
    assert m["Phi"] == pytest.approx(phi, abs=(100 - phi) * tol_rq / (r_q - tol_rq))
    assert m["Phi"] == pytest.approx(layer_porosity(m["M_s"], RHO, cells * a, cells * a, m["R_q"]), rel=1e-14)
    packing = (4 / 3 * pi * r**3) / (a * a * thk)
    assert m["packing_fraction"] == pytest.approx(packing, abs=packing * tol_mean / (thk - tol_mean))
    p = pi * r**2 / a**2
    assert m["coverage"] == pytest.approx(p, abs=K * probe_se((f > 0).astype(float), n))


def test_lattice_across_a_periodic_boundary_measures_as_one_inside(tmp_path):
    """A monolayer wrapped through the periodic y boundary (a quarter of a cell shifted, so
    a row of spheres straddles y = 0 = W) measures like the same lattice away from it: the
    images of the straddling spheres raise the surface at both edges. Without the images
    the layer comes out thinner than the lattice's exact value."""
    r, a, cells, n = 50e-6, 125e-6, 8, 1000
    width = cells * a
    box = [[0.0, width], [0.0, width], [0.0, 1e-3]]
    region = (0.0, width, 0.0, width)
    wrapped = lattice(r, a, cells)
    wrapped["y"] = (wrapped["y"] + 0.75 * a) % width  # the row at 7.5 a moves to 0.25 a: it straddles y = 0
    path = tmp_path / "wrapped.dump"
    write_dump(path, wrapped, box, periodic=(False, True, False))
    frame = read_dump(path)
    assert frame.periodic == (False, True, False)
    thk, r_q = resting_sphere_moments(r, a * a)
    tol_mean, tol_rq = tolerances(lattice_cell(r, a), thk, r_q, n)
    phi = (1 - (pi * (2 * r) ** 3 / 6) / (a * a * 4 * r_q)) * 100
    for seed in range(3):
        inside = spread_layer_metrics(lattice(r, a, cells), region, U, RHO, n_lines=n, seed=seed)
        across = spread_layer_metrics(frame, region, U, RHO, n_lines=n, seed=seed)
        for m in (inside, across):
            assert m["thk_avg"] == pytest.approx(thk, abs=tol_mean)
            assert m["R_q"] == pytest.approx(r_q, abs=tol_rq)
            assert m["Phi"] == pytest.approx(phi, abs=(100 - phi) * tol_rq / (r_q - tol_rq))
        assert across["M_s"] == pytest.approx(inside["M_s"], rel=1e-12)  # mass: each sphere once
        assert across["n_particles"] == cells**2
    # Without the images, heights differ exactly where the straddling row's caps reach
    # across y = W, and there the surface is the image sphere's cap (centre y = W + a/4)
    xs, ys = probe_lines(region, n, 0)
    centres, radii = wrapped[["x", "y", "z"]].to_numpy(), wrapped["radius"].to_numpy()
    h_on = layer_top(*periodic_images(centres, radii, box, (False, True, False)), xs, ys, np.zeros((n, n)))
    h_off = layer_top(centres, radii, xs, ys, np.zeros((n, n)))
    changed = np.argwhere(h_on != h_off)
    assert len(changed) > 0 and np.all(ys[changed[:, 1]] > width - (r - 0.25 * a))
    px, py = xs[changed[:, 0]], ys[changed[:, 1]]
    cx = (np.floor(px / a) + 0.5) * a
    d2 = (px - cx) ** 2 + (py - width - 0.25 * a) ** 2
    np.testing.assert_allclose(h_on[changed[:, 0], changed[:, 1]], r + np.sqrt(r**2 - d2), rtol=1e-12)


def test_periodic_images_leave_a_region_away_from_the_boundary_unchanged():
    r, a, cells = 50e-6, 125e-6, 8
    width = cells * a
    atoms = lattice(r, a, cells)
    atoms["y"] = (atoms["y"] + 0.75 * a) % width
    box = [[0.0, width], [0.0, width], [0.0, 1e-3]]
    region = (0.0, width, 2 * a, width - 2 * a)  # a full diameter clear of y = 0 and y = W
    on = spread_layer_metrics(atoms, region, U, RHO, n_lines=300, seed=1, box=box, periodic=(False, True, False))
    off = spread_layer_metrics(atoms, region, U, RHO, n_lines=300, seed=1)
    assert on == off
    centres, radii = periodic_images(atoms[["x", "y", "z"]].to_numpy(), atoms["radius"].to_numpy(), box,
                                     (False, True, False))
    assert len(radii) == cells**2 + 2 * cells  # the straddling row (near both edges) imaged once each way
    with pytest.raises(ValueError, match="box"):
        spread_layer_metrics(atoms, region, U, RHO, n_lines=10, periodic=(False, True, False))


# ---------------------------------------------------------------- mesh substrates


def heightfield_stl(path, f, x, y, bottom=None, file_type="stl"):
    """Write the surface z = f(x, y) on grid x, y [m] as an STL (binary or "stl_ascii"); optional flat bottom."""
    gx, gy = np.meshgrid(x, y, indexing="ij")
    verts = np.column_stack([gx.ravel(), gy.ravel(), f(gx, gy).ravel()])
    idx = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    if bottom is not None:  # same grid at z = bottom, facing down
        verts = np.vstack([verts, np.column_stack([verts[:, :2], np.full(len(verts), bottom)])])
        faces = np.vstack([faces, faces[:, ::-1] + gx.size])
    trimesh.Trimesh(verts, faces, process=False).export(path, file_type=file_type)
    return path


def test_sinusoidal_substrate_without_powder(tmp_path):
    amp, wavelength, z0, n = 40e-6, 0.5e-3, 1e-3, 1000
    region = (0.0, 4 * wavelength, 0.0, 1e-3)  # four full periods in x
    dx = wavelength / 64
    x = np.arange(-2 * dx, region[1] + 3 * dx, dx)
    y = np.linspace(-0.1e-3, 1.1e-3, 13)

    def surface(px, py):
        return z0 + amp * np.sin(2 * pi * px / wavelength)

    stl = heightfield_stl(tmp_path / "sine.stl", surface, x, y, bottom=0.0)
    xs, ys = probe_lines(region, n, seed=0)
    b = substrate_height(str(stl), xs, ys)
    # linear interpolation error <= max|f''| dx^2 / 8, plus float32 STL rounding
    interp = amp * (2 * pi / wavelength) ** 2 * dx**2 / 8 + 1e-10
    exact = surface(xs, 0)[:, None]
    assert np.max(np.abs(b - exact)) <= interp

    m = spread_layer_metrics(pd.DataFrame(columns=["x", "y", "z", "radius"], dtype=float), region, U, RHO,
                             substrate=stl, n_lines=n, seed=0)
    assert m["M_s"] == 0.0 and m["thk_avg"] == 0.0 and m["coverage"] == 0.0 and m["Phi"] == 100.0
    # the same probes on the exact surface: only interpolation error
    assert m["R_q"] == pytest.approx(np.std(np.broadcast_to(exact, b.shape)), abs=2 * interp)
    # the analytic RMS amplitude/sqrt(2), within the sampling error
    f = surface(midpoints(*region)[0], 0) - z0
    tol_mean, tol_rq = tolerances(f, 0.0, amp / math.sqrt(2), n)
    assert m["R_q"] == pytest.approx(amp / math.sqrt(2), abs=tol_rq)
    assert m["b_avg"] == pytest.approx(z0, abs=tol_mean)


def test_tilted_plane_mesh_is_exact_and_walls_are_ignored():
    region = (0.0, 1e-3, 0.0, 1e-3)
    plane = lambda px, py: 1e-4 + 0.1 * px - 0.2 * py  # noqa: E731
    corners = np.array([[-1e-3, -1e-3], [2e-3, -1e-3], [2e-3, 2e-3], [-1e-3, 2e-3]])
    verts = np.column_stack([corners, plane(*corners.T)])
    wall = [[0.5e-3, -1e-3, -1.0], [0.5e-3, 2e-3, -1.0], [0.5e-3, 0.5e-3, 1.0]]  # vertical, rising above
    mesh = trimesh.Trimesh(np.vstack([verts, wall]), [[0, 1, 2], [0, 2, 3], [4, 5, 6]], process=False)
    xs, ys = probe_lines(region, 300, seed=5)
    b = substrate_height(mesh, xs, ys)
    np.testing.assert_allclose(b, plane(xs[:, None], ys[None, :]), rtol=0, atol=1e-15)


def test_mesh_not_covering_region_is_an_error():
    mesh = trimesh.Trimesh([[0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(ValueError, match="uncovered"):
        substrate_height(mesh, *probe_lines((0, 1e-3, 0, 1e-3), 50))


# ---------------------------------------------------------------- invariances and input checks


def test_atom_order_and_outside_particles():
    region = (0.0, 1.5e-3, 0.0, 1.5e-3)
    atoms = polydisperse(2000, region, seed=7)
    m = spread_layer_metrics(atoms, region, U, RHO, n_lines=300, seed=11)
    shuffled = spread_layer_metrics(atoms.sample(frac=1.0, random_state=3), region, U, RHO, n_lines=300, seed=11)
    assert shuffled == pytest.approx(m, rel=1e-12)  # sums over particles may round differently
    for key in ("b_avg", "h_avg", "R_q", "coverage", "n_particles"):  # from the probes: exactly equal
        assert shuffled[key] == m[key]
    far = spheres([5e-3, -4e-3, 0.7e-3], [0.7e-3, 0.7e-3, 9e-3], 100e-6, 120e-6)
    more = spread_layer_metrics(pd.concat([atoms, far]), region, U, RHO, n_lines=300, seed=11)
    assert more == pytest.approx(m, rel=1e-12)
    inside = atoms[atoms.x.between(0, 1.5e-3) & atoms.y.between(0, 1.5e-3)]
    assert m["n_particles"] == len(inside) < len(atoms)
    assert m["M_s"] == pytest.approx(pi * RHO / 6 * np.sum((2 * inside.radius) ** 3), rel=1e-12)


def test_frame_box_checked_and_bad_values_rejected(tmp_path):
    atoms = lattice(50e-6, 125e-6, 4)
    write_dump(tmp_path / "l.dump", atoms, [[0, 0.5e-3], [0, 0.5e-3], [0, 1e-3]])
    frame = read_dump(tmp_path / "l.dump")
    good = (0.0, 0.5e-3, 0.0, 0.5e-3)
    assert spread_layer_metrics(frame, good, U, RHO, n_lines=50)["n_particles"] == 16
    bad = [
        dict(region=(0.0, 0.6e-3, 0.0, 0.5e-3), match="outside the dump's box"),
        dict(region=(0.2e-3, 0.2e-3, 0.0, 0.5e-3), match="zero or negative area"),
        dict(region=(0.3e-3, 0.2e-3, 0.0, 0.5e-3), match="zero or negative area"),
        dict(speed=-1.0, match="speed -1"),
        dict(density=-5.0, match="density -5"),
        dict(density=0.0, match="density 0"),
    ]
    for case in bad:
        args = dict(region=good, speed=U, density=RHO) | case
        match = args.pop("match")
        with pytest.raises(ValueError, match=match):
            spread_layer_metrics(frame, args["region"], args["speed"], args["density"], n_lines=50)


# ---------------------------------------------------------------- command line


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "analysis.measure", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)


@pytest.fixture
def lattice_dump(tmp_path):
    """A 4 x 4 lattice (r = 50 um, a = 125 um) in a 0.5 mm box, as a gzipped dump."""
    path = tmp_path / "lattice.dump.gz"
    write_dump(path, lattice(50e-6, 125e-6, 4), [[0, 0.5e-3], [0, 0.5e-3], [0, 1e-3]], timestep=1000)
    return path


def test_cli_prints_and_writes_report(tmp_path, lattice_dump):
    out = tmp_path / "m.json"
    res = run_cli(lattice_dump, "--region", 0, 0.5, 0, 0.5, "--speed", 50, "--density", RHO, "--lines", 400,
                  "--seed", 2, "--json", out)
    assert res.returncode == 0, res.stderr
    printed = json.loads(res.stdout)
    assert json.loads(out.read_text()) == printed
    assert list(tmp_path.glob(".m.json*")) == []  # no temporary file left
    expected = to_report_units(spread_layer_metrics(read_dump(lattice_dump), (0, 0.5e-3, 0, 0.5e-3), 0.05, RHO,
                                                    n_lines=400, seed=2))
    assert printed == pytest.approx(expected, rel=1e-12)
    assert printed["mass_g"] == pytest.approx(16 * pi * RHO * 100e-6**3 / 6 * 1e3, rel=1e-12)
    assert printed["throughput_mm2_s"] == pytest.approx(50 * printed["thickness_um"] * 1e-3, rel=1e-12)
    assert printed["n_particles"] == 16 and printed["n_probes"] == 400**2
    for key in ("roughness_um", "porosity_pct", "coverage", "packing_fraction", "b_avg_um", "h_avg_um"):
        assert key in printed


def test_cli_substrate_options(tmp_path, lattice_dump):
    stl = heightfield_stl(tmp_path / "flat.stl", lambda px, py: np.full_like(px, 0.2e-3),
                          np.array([-1e-3, 1e-3]), np.array([-1e-3, 1e-3]), file_type="stl_ascii")
    common = [lattice_dump, "--region", 0, 0.5, 0, 0.5, "--speed", 50, "--density", RHO, "--lines", 100]
    for extra in (["--substrate", stl], ["--substrate-height", 0.2]):
        res = run_cli(*common, *extra)
        assert res.returncode == 0, res.stderr
        assert json.loads(res.stdout)["b_avg_um"] == pytest.approx(200.0, rel=1e-6)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"--region": ["0", "0.6", "0", "0.5"]}, "region 0 0.6 0 0.5 mm lies outside the dump's box"),
        ({"--region": ["0.3", "0.3", "0", "0.5"]}, "region 0.3 0.3 0 0.5 mm has zero or negative area"),
        ({"--speed": ["-20"]}, "speed -20 mm/s"),
        ({"--density": ["-4430"]}, "density -4430 kg/m3"),
        ({"dump": "missing.dump"}, "file not found: .*missing.dump"),
        ({"--substrate": ["nope.stl"]}, "file not found: .*nope.stl"),
        ({"dump": "broken"}, "broken.dump.*announces 16 atoms"),
    ],
)
def test_cli_bad_inputs_exit_2_and_write_nothing(tmp_path, lattice_dump, change, message):
    opts = {"--region": ["0", "0.5", "0", "0.5"], "--speed": ["50"], "--density": [str(RHO)]}
    dump = lattice_dump
    if change.get("dump") == "broken":
        dump = tmp_path / "broken.dump"
        dump.write_bytes(read_bytes_cut(lattice_dump))
    elif "dump" in change:
        dump = tmp_path / change["dump"]
    opts |= {k: v for k, v in change.items() if k != "dump"}
    out = tmp_path / "out.json"
    args = [dump, *[a for k, v in opts.items() for a in (k, *v)], "--json", out]
    res = run_cli(*args)
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("layer_metrics: error:")
    assert re.search(message, res.stderr), res.stderr
    assert res.stdout == ""
    assert list(tmp_path.glob("*.json")) == [] and list(tmp_path.glob(".out.json*")) == []


def _file_size_limit(limit_bytes):
    """A child process whose files cannot grow past ``limit_bytes`` (a full disk, as the OS reports it)."""
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # write() then fails with EFBIG instead of killing
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    return limit


@pytest.mark.parametrize("fault, cause", [("full", "File too large"), ("directory", "Is a directory")])
def test_cli_os_error_is_one_line_naming_the_file_and_keeps_the_old_output(tmp_path, lattice_dump, fault, cause):
    out = tmp_path / "m.json"
    if fault == "directory":
        out.mkdir()
    else:
        out.write_text("old")
    res = subprocess.run([sys.executable, "-m", "analysis.measure", str(lattice_dump), "--region",
                          "0", "0.5", "0", "0.5", "--speed", "50", "--density", str(RHO), "--lines", "50",
                          "--json", str(out)], cwd=REPO, capture_output=True, text=True, timeout=60,
                         preexec_fn=_file_size_limit(200) if fault == "full" else None)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr == f"layer_metrics: error: {out}: {cause}\n"
    assert fault == "directory" or out.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lattice.dump.gz", "m.json"]  # no temporary file


def test_error_line_names_the_file_and_the_cause():
    assert error_line(OSError(28, "No space left on device", "results/x.json")) == \
        "results/x.json: No space left on device"
    assert error_line(FileNotFoundError(2, "No such file or directory")) == "No such file or directory (errno 2)"
    assert error_line(ValueError("speed -20 mm/s must be positive")) == "speed -20 mm/s must be positive"


def read_bytes_cut(gz_path):
    """The decompressed dump minus its last two atom lines."""
    lines = gzip.decompress(gz_path.read_bytes()).splitlines(keepends=True)
    return b"".join(lines[:-2])
