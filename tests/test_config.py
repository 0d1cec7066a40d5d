"""config.yaml: the shipped file is valid, and each bad value stops with its key and value."""
import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from analysis.config.errors import ConfigError
from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.config.reading import coerce_cli_values
from analysis.physics import feed_length, liggghts_seeds, psd_classes, rayleigh_time, roller_motion

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def base():
    return yaml.safe_load((ROOT / "config.yaml").read_text())


def with_value(config, dotted, value):
    config = copy.deepcopy(config)
    *path, last = dotted.split(".")
    node = config
    for key in path:
        node = node[key]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return config


def test_shipped_config_is_valid_and_has_the_papers_design(base):
    config = load_config(ROOT / "config.yaml")
    assert config["sweep"]["U_mm_s"] == [40, 55, 70, 85, 100]
    assert sorted(config["sweep"]["omega_rad_s"]) == [-20, -15, -10, -5, 0, 5, 10, 15, 20]
    assert {"smoke", "default", "paper"} <= set(config["fidelity"])
    paper = scene(config, "paper")
    assert paper.strip_width == pytest.approx(0.070)          # 70 mm roller
    x0, x1, y0, y1 = paper.sampling_region
    assert (x1 - x0, y1 - y0) == pytest.approx((0.025, 0.025))  # 25 x 25 mm
    assert paper.roller_radius == pytest.approx(0.015)


@pytest.mark.parametrize("dotted, value, words", [
    ("sweep.U_mm_s", [40, -55], "-55"),
    ("psd.min_diameter_um", 300, "psd.min_diameter_um"),
    ("roller.gap_um", 80, "roller.gap_um"),
    ("material.density_kg_m3", -4430, "material.density_kg_m3"),
    ("material.poisson_ratio", 0.7, "material.poisson_ratio"),
    ("substrate.mesh", "no/such/substrate.stl", "substrate.mesh"),
    ("material.restitution", float("nan"), "material.restitution"),
    ("sweep.U_mm_s", [float("inf"), 40, 70], "sweep.U_mm_s[0]"),
    ("sweep.U_mm_s", [float("nan"), 40, 70], "sweep.U_mm_s[0]"),
    ("fidelity.default.heap_length_mm", float("-inf"), "fidelity.default.heap_length_mm"),
    ("surrogate.alpha", float("inf"), "surrogate.alpha"),
    ("psd.max_diameter_um", 1241.0, "no particles"),                      # found by tests/test_fuzz.py
    ("level", "huge", "level"),
    ("timestep.rayleigh_fraction", 0.6, "timestep.rayleigh_fraction"),
    ("material.colour", "grey", "colour"),
    ("roller.diameter_mm", KeyError, "diameter_mm"),
    ("surrogate.n_test", 44, "surrogate.n_test"),
    ("surrogate.confidence", 1.5, "surrogate.confidence"),
    ("surrogate.confidence", 0, "surrogate.confidence"),
    ("fidelity.default.feed_pile_mg_per_mm", 500, "feed_pile_mg_per_mm"),   # does not fit ahead of the roller
    ("fidelity.default.feed_pile_mg_per_mm", -3, "feed_pile_mg_per_mm"),
    ("maps.operating_window.min_coverage_pct", 150, "maps.operating_window.min_coverage_pct"),
    ("maps.operating_window.max_void_fraction_pct", -2, "maps.operating_window.max_void_fraction_pct"),
    ("substrate.peak_cap_fraction_of_gap", 1.2, "peak_cap_fraction_of_gap"),
    ("fidelity.default.run_out_max_mm", 1.5, "run_out_max_mm (1.5 mm)"),  # before the earliest stop (2 mm)
    ("layer_laid.checks", 0, "layer_laid.checks"),
    ("fidelity.default.freeze_lag_mm", 3.0, "still in the roller's nip"),  # under 4.06 mm: the roller's nip
    ("fidelity.default.freeze_lag_mm", -1, "freeze_lag_mm"),
])
def test_bad_value_names_key_and_value(base, dotted, value, words):
    with pytest.raises(ConfigError) as err:
        load_config(with_value(base, dotted, value), base_dir=ROOT)
    assert words in str(err.value)
    if value not in (KeyError,) and not isinstance(value, list):
        assert repr(value) in str(err.value) or str(value) in str(err.value)


def test_bad_value_stops_snakemake_before_any_job(tmp_path):
    """A dry run with a bad --config value exits non-zero, names the value, makes nothing."""
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "-d", str(tmp_path),
                           "-s", str(ROOT / "Snakefile"), "--configfile", str(ROOT / "config.yaml"),
                           "--config", "sweep={U_mm_s: [40, -5]}"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode != 0
    assert "-5" in proc.stdout + proc.stderr
    assert not (tmp_path / "results").exists()


def test_cli_values_are_coerced():
    assert coerce_cli_values({"sweep": {"U_mm_s": ["40", "70.5"], "x": "null"}}) == \
        {"sweep": {"U_mm_s": [40, 70.5], "x": None}}


def test_psd_classes_keep_mass_and_range():
    d, w = psd_classes(175.0, 25.0, 100.0, 250.0, 5)
    assert w.sum() == pytest.approx(1.0)
    assert d.min() > 100 and d.max() < 250 and list(d) == sorted(d)
    # symmetric number PDF about the middle class: by mass, the big classes weigh more
    assert w[3] > w[1] and w[4] > w[0]


def test_rayleigh_time_matches_liggghts_formula():
    # pi r sqrt(rho/G)/(0.1631 nu + 0.8766), G = E / 2(1+nu)
    r, rho, E, nu = 50e-6, 4430.0, 5e6, 0.3
    G = E / 2.6
    assert rayleigh_time(r, rho, E, nu) == pytest.approx(3.141592653589793 * r * (rho / G) ** 0.5 / 0.92553)


def test_seeds_are_distinct_primes_above_10000():
    seeds = liggghts_seeds(3, 12)
    assert len(set(seeds)) == 12 and min(seeds) > 10000
    assert all(all(s % k for k in range(2, int(s**0.5) + 1)) for s in seeds)
    assert set(seeds).isdisjoint(liggghts_seeds(4, 12))


@pytest.mark.parametrize("U, omega, bottom", [(40, -5, -35.0), (100, -5, 25.0), (70, 0, 70.0), (40, 20, 340.0)])
def test_roller_sign_convention_matches_the_paper(U, omega, bottom):
    """Bottom point at U + omega R (paper: -35 mm/s at U=40, +25 mm/s at U=100 for omega=-5)."""
    m = roller_motion(U * 1e-3, omega, 0.015)
    assert m["bottom_speed"] * 1e3 == pytest.approx(bottom)
    if omega:
        # a right-handed rotation about `axis` moves the bottom point (0,0,-R) by omega_vec x r
        wy = m["rotate"]["axis"][1] * 2 * 3.141592653589793 / m["rotate"]["period"]
        assert (U * 1e-3 - wy * 0.015) * 1e3 == pytest.approx(bottom)
    else:
        assert m["rotate"] is None


def test_feed_zone_holds_twice_the_pile_in_the_wedge_ahead_of_the_roller():
    """The wedge between the bed and a roller of radius R at gap g, from the axis to L
    ahead, has the area g L + R^2 asin(L/R)/2 - L sqrt(R^2 - L^2)/2 + ... (integral of
    g + R - sqrt(R^2 - x^2)); the zone holds FEED_ZONE_ROOM x the pile's bulk volume."""
    from math import asin, sqrt

    from analysis.physics import FEED_ZONE_ROOM, PILE_SOLID_FRACTION
    R, g, rho = 0.015, 3e-4, 4430.0
    for pile in (5e-3, 20e-3, 40e-3):                       # kg per m of width (mg/mm)
        L = feed_length(pile, rho, R, g)
        wedge = (g + R) * L - (L * sqrt(R**2 - L**2) + R**2 * asin(L / R)) / 2
        assert wedge == pytest.approx(FEED_ZONE_ROOM * pile / (rho * PILE_SOLID_FRACTION), rel=1e-4)
    assert feed_length(40e-3, rho, R, g) > feed_length(20e-3, rho, R, g)
    with pytest.raises(ValueError, match="does not fit"):
        feed_length(0.2, rho, R, g)
