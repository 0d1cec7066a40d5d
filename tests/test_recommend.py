"""The operator's question, on a surrogate whose answer is known."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import synthetic_dataset

from analysis.surrogate.network import fit_surrogate
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.recommend import main, recommend

ROOT = Path(__file__).resolve().parents[1]


def monotone_metrics(U, omega):
    """Throughput rises with U and falls with omega; porosity rises with U only;
    roughness is least at omega = 0.  So under porosity <= P the best U is
    (P - 20)/0.2 mm/s, at omega = -20 rad/s, or at omega = -sqrt((R - 40)/0.05)
    under roughness <= R as well."""
    U, omega = np.asarray(U, float), np.asarray(omega, float)
    return {"mass_g": 0.01 + 1e-4 * U,
            "throughput_mm2_s": 10 + 0.3 * U - 0.1 * omega,
            "roughness_um": 40 + 0.05 * omega**2,
            "porosity_pct": 20 + 0.2 * U}


@pytest.fixture(scope="module")
def known(fit_params):
    """(model, scores) fitted on the monotone dataset; scores serve as meta."""
    model, scores = fit_surrogate(synthetic_dataset(0, metrics=monotone_metrics), fit_params)
    return model, scores


def saved(model_and_scores, tmp_path_factory, folder):
    """The model saved with its scores as ``<folder>/model.joblib``, as the surrogate rule writes it."""
    path = tmp_path_factory.mktemp(folder) / "model.joblib"
    save_surrogate(model_and_scores[0], path, model_and_scores[1])
    return path


@pytest.fixture(scope="module")
def model_file(known, tmp_path_factory):
    return saved(known, tmp_path_factory, "surrogate")


def test_best_is_the_largest_U_within_the_porosity_limit(known):
    found = recommend(*known, max_porosity_pct=34.0)
    assert found["U_mm_s"] == pytest.approx(70.0, abs=1.0)       # grid step 0.3 mm/s
    assert found["omega_rad_s"] == pytest.approx(-20.0, abs=0.5)
    assert found["porosity_pct"] <= 34.0
    assert found["throughput_mm2_s"] == pytest.approx(10 + 0.3 * 70 + 2, abs=0.5)
    assert found["n_grid"] == 201 * 201 and 0 < found["n_feasible"] < found["n_grid"]


def test_roughness_limit_moves_omega(known):
    found = recommend(*known, max_porosity_pct=34.0, max_roughness_um=45.0, n=161)
    assert found["U_mm_s"] == pytest.approx(70.0, abs=1.0)
    assert found["omega_rad_s"] == pytest.approx(-10.0, abs=0.75)   # 0.05 omega^2 <= 5
    assert found["roughness_um"] <= 45.0


def test_no_speeds_meet_an_impossible_limit(known):
    assert recommend(*known, max_porosity_pct=5.0) is None


@pytest.mark.parametrize("porosity, roughness", [(-1.0, None), (30.0, -2.0), (float("nan"), None)])
def test_bad_limits_are_refused(known, porosity, roughness):
    with pytest.raises(ValueError, match="non-negative"):
        recommend(*known, max_porosity_pct=porosity, max_roughness_um=roughness)


def test_cli_prints_the_recommendation(model_file, capsys):
    assert main(["--max-porosity", "34", "--model", str(model_file)]) == 0
    out = capsys.readouterr().out
    U = float(re.search(r"U\s+= ([\d.]+) mm/s", out).group(1))
    assert U == pytest.approx(70.0, abs=1.0)
    assert "omega = -20" in out and "Phi = " in out and "Q_s = " in out


def test_cli_says_when_nothing_qualifies(model_file, capsys):
    assert main(["--max-porosity", "5", "--model", str(model_file)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("No speeds in U 40..100 mm/s, omega -20..20 rad/s")
    lowest = float(re.search(r"lowest predicted porosity there is ([\d.]+) %", out).group(1))
    assert lowest == pytest.approx(28.0, abs=0.05)      # 20 + 0.2 * 40, as fitted


@pytest.mark.parametrize("argv, named", [
    (["--max-porosity", "-3"], "-3"),
    (["--max-porosity", "30", "--max-roughness", "-0.5"], "-0.5"),
    (["--max-porosity", "abc"], "abc"),
    (["--max-porosity", "30", "--grid-points", "1"], "1"),
    (["--max-porosity", "30", "--confidence", "1.2"], "1.2"),
])
def test_cli_bad_input_exits_2_with_one_line(model_file, capsys, argv, named):
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--model", str(model_file)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and named in err


def test_cli_missing_model_exits_2(tmp_path, capsys):
    missing = tmp_path / "nowhere" / "model.joblib"
    with pytest.raises(SystemExit) as exit_:
        main(["--max-porosity", "30", "--model", str(missing)])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(missing) in err


def test_runs_as_a_module(model_file):
    done = subprocess.run([sys.executable, "-m", "analysis.surrogate.recommend", "--max-porosity", "34",
                           "--model", str(model_file)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "Highest predicted throughput with porosity <= 34 %" in done.stdout


# --- limits on the void fraction and the coverage ------------------------------------------------

class LinearStructure:
    """Exact layer-structure metrics: void fraction 10 + 0.3 U (%), coverage 60 + 2 omega (%)."""

    def predict(self, X):
        X = np.asarray(X, float)
        return np.column_stack([10 + 0.3 * X[:, 0], 60 + 2 * X[:, 1]])


@pytest.fixture(scope="module")
def layered(known):
    """The monotone network with the exact structure metrics stacked beside it; the scores as meta."""
    from analysis.columns import METRICS, STRUCTURE_METRICS
    from analysis.surrogate.intervals import SurrogateStack
    return SurrogateStack([known[0], LinearStructure()], [list(METRICS), list(STRUCTURE_METRICS)]), known[1]


@pytest.fixture(scope="module")
def layered_file(layered, tmp_path_factory):
    return saved(layered, tmp_path_factory, "layered")


def test_a_void_fraction_limit_caps_U(layered):
    found = recommend(*layered, max_void_fraction_pct=31.0)         # 10 + 0.3 U <= 31: U <= 70
    assert found["U_mm_s"] == pytest.approx(70.0, abs=0.01) and found["void_fraction_pct"] <= 31.0
    assert found["omega_rad_s"] == pytest.approx(-20.0, abs=0.5)
    assert found["limits"] == {"max_void_fraction_pct": 31.0}
    assert found["metrics"][4:] == ["void_fraction_pct", "coverage_pct"]


def test_a_coverage_limit_excludes_the_best_unlimited_setting(layered):
    free = recommend(*layered, max_porosity_pct=1e9)
    assert (free["U_mm_s"], free["omega_rad_s"]) == pytest.approx((100.0, -20.0), abs=1.0)   # coverage 20 % there
    found = recommend(*layered, min_coverage_pct=80.0)              # 60 + 2 omega >= 80: omega >= 10
    assert found["omega_rad_s"] == pytest.approx(10.0, abs=0.01) and found["coverage_pct"] >= 80.0
    assert found["U_mm_s"] == pytest.approx(100.0, abs=1.0)
    both = recommend(*layered, max_void_fraction_pct=31.0, min_coverage_pct=80.0)
    assert (both["U_mm_s"], both["omega_rad_s"]) == pytest.approx((70.0, 10.0), abs=0.01)
    assert recommend(*layered, max_void_fraction_pct=21.0) is None  # 10 + 0.3 x 40 = 22 % at the least


@pytest.mark.parametrize("limits, named", [
    ({"min_coverage_pct": 150.0}, "--min-coverage must be a share from 0 to 100 %, got 150"),
    ({"max_void_fraction_pct": -1.0}, "--max-void-fraction must be a non-negative number, got -1"),
    ({"max_void_fraction_pct": float("nan")}, "--max-void-fraction must be a non-negative number, got nan"),
])
def test_bad_structure_limits_are_refused_by_value(layered, limits, named):
    with pytest.raises(ValueError, match=re.escape(named)):
        recommend(*layered, **limits)


def test_a_model_without_the_structure_metrics_refuses_their_limits(known):
    with pytest.raises(ValueError, match="--min-coverage: this model does not predict the coverage"):
        recommend(*known, max_porosity_pct=40.0, min_coverage_pct=50.0)


def test_cli_limits_the_void_fraction_and_the_coverage(layered_file, capsys):
    assert main(["--max-void-fraction", "31", "--min-coverage", "80", "--model", str(layered_file)]) == 0
    out = capsys.readouterr().out
    assert "Highest predicted throughput with void fraction <= 31 % and coverage >= 80 %" in out
    assert re.search(r"U\s+= 70\.0 mm/s", out) and "omega = 10.00 rad/s" in out
    void = float(re.search(r"eps = ([\d.]+) % \(void fraction", out).group(1))
    cover = float(re.search(r"  C = ([\d.]+) % \(coverage", out).group(1))
    assert void == pytest.approx(31.0, abs=0.01) and cover == pytest.approx(80.0, abs=0.01)
    assert main(["--max-void-fraction", "21", "--model", str(layered_file)]) == 1
    out = capsys.readouterr().out
    assert "the lowest predicted void fraction there is 22 %" in out


@pytest.mark.parametrize("argv, named", [
    (["--min-coverage", "150"], "150"),
    (["--max-void-fraction", "-5"], "-5"),
    (["--max-void-fraction", "lots"], "lots"),
    ([], "give at least one limit: --max-porosity, --max-roughness, --max-void-fraction, --min-coverage"),
])
def test_cli_bad_structure_limits_exit_2_naming_them(layered_file, capsys, argv, named):
    with pytest.raises(SystemExit) as exit_:
        main([*argv, "--model", str(layered_file)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and named in err


def test_cli_refuses_a_structure_limit_on_an_old_model(model_file, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--max-void-fraction", "30", "--model", str(model_file)])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--max-void-fraction" in err and "refit it" in err
