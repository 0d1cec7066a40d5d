"""Deposit profiles and the steady-state start, on layers whose areal mass is known by hand."""
import numpy as np
import pandas as pd
import pytest

from analysis.metrics.deposit import deposit_profile, profile_runs, steady_state_start

RHO = 4430.0


def test_lattice_layer_has_its_hand_computed_areal_mass():
    """A square lattice (spacing a) of spheres of radius r: areal mass rho (4/3 pi r^3) / a^2."""
    r, a, width = 50e-6, 125e-6, 1.0e-3
    c = (np.arange(40) + 0.5) * a  # x over 0..5 mm
    x, y = np.meshgrid(c, (np.arange(8) + 0.5) * a, indexing="ij")
    atoms = pd.DataFrame({"x": x.ravel(), "y": y.ravel(), "radius": r})
    profile = deposit_profile(atoms, RHO, width, (0.0, 5e-3), bin_length=0.5e-3)
    assert len(profile) == 10
    np.testing.assert_allclose(profile["x_mm"], np.arange(0.25, 5.0, 0.5))
    expected = RHO * 4 / 3 * np.pi * r**3 / a**2  # kg/m^2 = mg/mm^2
    np.testing.assert_allclose(profile["areal_mass_mg_mm2"], expected, rtol=1e-12)


def synthetic(start_mm, level, noise, replicates=3, seed=0):
    """Profiles that ramp up linearly until ``start_mm`` and are flat (plus noise) after."""
    rng = np.random.default_rng(seed)
    x = np.arange(0.25, 16.0, 0.5)
    mean = np.where(x < start_mm, level * x / start_mm, level)
    return pd.concat([pd.DataFrame({"x_mm": x, "replicate": k,
                                    "areal_mass_mg_mm2": mean + rng.normal(0, noise, x.size)})
                      for k in range(replicates)], ignore_index=True)


@pytest.mark.parametrize("start", [4.0, 8.0])
def test_steady_state_starts_where_the_ramp_ends(start):
    found = steady_state_start(synthetic(start, 0.2, 0.004), plateau_mm=(12.0, 16.0))
    assert start - 1.0 <= found <= start + 0.5


def test_profile_runs_pick_the_middle_speed_and_nearest_omegas():
    grid = [(U, w) for U in (40, 70, 100) for w in (-20, -10, 0, 10, 20)]
    assert profile_runs(grid, 2) == [(70, -10, 0), (70, -10, 1), (70, 0, 0), (70, 0, 1), (70, 10, 0), (70, 10, 1)]
    assert profile_runs([(55, -3), (55, 4), (85, 0)], 1) == [(85, 0, 0)]  # an off-grid design: the upper middle U
