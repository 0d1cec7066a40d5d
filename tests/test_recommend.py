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


@pytest.fixture(scope="module")
def model_file(known, tmp_path_factory):
    path = tmp_path_factory.mktemp("surrogate") / "model.joblib"
    save_surrogate(known[0], path, known[1])
    return path


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
