"""Calibrated prediction intervals (analysis.surrogate.intervals): their coverage of new noisy runs
on synthetic data whose truth and noise are known, the choice that bars under-covering models, and
the recommendation, grid and maps that use them."""

import numpy as np
import pandas as pd
import pytest
from conftest import synthetic_dataset, synthetic_metrics

from analysis.surrogate.candidates import GPSurrogate, make_candidate
from analysis.surrogate.data import inputs_of, split_runs, targets_of
from analysis.surrogate.intervals import (
    CalibratedSurrogate,
    calibrated_from_predictions,
    check_confidence,
    conformal_quantile,
    interval_score,
    relative_noise,
    with_products,
)
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.recommend import main, recommend
from analysis.surrogate.selection import choose_model, cross_validate_models, model_choice_markdown
from analysis.viz.process_map import process_map_figure
from analysis.viz.surfaces import interval_figure

NOISE = 0.05          # relative std of the synthetic runs' noise
CONFIDENCE = 0.9


# --- the pieces, by hand ---------------------------------------------------------------------

def test_conformal_quantile_is_the_finite_sample_rank():
    scores = np.arange(1.0, 20.0)[:, None]            # 19 runs, scores 1..19
    assert conformal_quantile(scores, 0.9)[0] == 18.0   # ceil(0.9 x 20) = 18th smallest
    assert conformal_quantile(scores, 0.5)[0] == 10.0   # ceil(0.5 x 20) = 10th
    assert np.isinf(conformal_quantile(scores[:8], 0.9)[0])   # ceil(0.9 x 9) = 9 > 8 runs: no finite bound
    # two repeats of the same 19 runs pooled: the same quantile
    assert conformal_quantile(np.r_[scores, scores], 0.9, n_runs=19)[0] == 18.0


@pytest.mark.parametrize("bad", [0, 1, 1.5, -0.1, float("nan"), "abc"])
def test_confidence_outside_0_1_is_refused_by_value(bad):
    with pytest.raises(ValueError, match="confidence must be") as err:
        check_confidence(bad)
    assert str(bad) in str(err.value)


def test_interval_score_by_hand():
    # width 2; a miss 1 below costs 2/0.1 x 1 = 20 more; inside costs the width only
    assert interval_score([0.0, 2.0, 5.0], [1.0, 1.0, 1.0], [3.0, 3.0, 3.0], 0.9) == pytest.approx([22, 2, 42])


def test_products_and_their_first_order_std():
    mean = np.array([[2.0, 3.0, 4.0, 5.0]])        # M_s, Q_s, R_q, Phi
    std = np.array([[0.2, 0.3, 0.4, 0.5]])
    m6, s6 = with_products(mean, std)
    assert m6[0, 4:] == pytest.approx([3 * 2, 4 * 5])
    assert s6[0, 4:] == pytest.approx([np.hypot(0.3 * 2, 3 * 0.2), np.hypot(0.4 * 5, 4 * 0.5)])


def test_relative_noise_from_replicates_and_from_the_gp():
    reps = pd.concat([synthetic_dataset(s, noise=0.03).assign(replicate=s) for s in range(4)], ignore_index=True)
    rho, source = relative_noise(reps)
    assert "replicates" in source and rho[:4] == pytest.approx(0.03, rel=0.15)
    rho, source = relative_noise(synthetic_dataset(3, noise=NOISE))
    assert "Gaussian process" in source and ((rho[:4] > 0.6 * NOISE) & (rho[:4] < 1.6 * NOISE)).all(), rho


# --- coverage on synthetic data with known noise ----------------------------------------------

@pytest.fixture(scope="module")
def calibrated(fit_params):
    """Each candidate fitted on 45 noisy runs (5 % noise), calibrated on its grouped 5-fold x 2
    held-out predictions; and 2,000 new noisy runs at random off-grid speeds with the truth there."""
    df = synthetic_dataset(3, noise=NOISE)
    params = {**fit_params, "models": ["mlp", "gp", "trees"], "hidden_units": 50, "mlp_members": 2,
              "n_init": 1, "max_iter": 1000, "cv_repeats": 2, "cv_loo": False, "gp_restarts": 0,
              "tree_count": 100, "confidence": CONFIDENCE}
    table, held_out = cross_validate_models(df, params, return_predictions=True)
    rho, source = relative_noise(df)
    models = {}
    for name in params["models"]:
        model = make_candidate(name, params).fit(inputs_of(df), targets_of(df))
        mine = held_out[(held_out.model == name) & (held_out.scheme == "kfold")]
        models[name] = calibrated_from_predictions(model, mine, df, rho, CONFIDENCE, source)
    rng = np.random.default_rng(11)
    X = np.c_[rng.uniform(40, 100, 2000), rng.uniform(-20, 20, 2000)]
    truth = np.column_stack(list(synthetic_metrics(X[:, 0], X[:, 1]).values()))
    runs = truth * (1 + NOISE * rng.standard_normal(truth.shape))
    return models, table, X, with_products(truth), with_products(runs)


def _coverage(model, X, y, kind="run", confidence=None):
    _, lo, hi = model.predict_interval(X, confidence, kind)
    return ((y >= lo) & (y <= hi)).mean(axis=0)


@pytest.mark.parametrize("name, upper", [("gp", 0.95), ("mlp", 0.95), ("trees", 0.98)])
def test_single_run_intervals_cover_new_runs_at_the_nominal_rate(calibrated, name, upper):
    """90 % of new runs inside, within a few percent, for every candidate. The trees' are
    conservative: their Q_s interval covers 99-100 % (over 6 seeds, 5 % noise: 91-96 %
    pooled), since a held-out edge point is predicted flat by the fold's trees."""
    models, _, X, _, runs = calibrated
    cover = _coverage(models[name], X, runs)
    assert 0.87 <= cover[:4].mean() <= upper, cover
    assert (cover >= 0.8).all(), cover                   # no metric, nor index product, far below


def test_the_coverage_test_can_fail(calibrated):
    """The same test fails intervals that are not calibrated: the mlp ensemble's own
    std band (1.645 x the networks' spread) and a calibration at a lower level."""
    models, _, X, _, runs = calibrated
    mlp = models["mlp"]
    mean, std = mlp.model.predict(X, return_std=True)
    own = (np.abs(runs[:, :4] - mean) <= 1.645 * std).mean()
    assert own < 0.7, own
    assert _coverage(mlp, X, runs, confidence=0.6)[:4].mean() < 0.75


def test_mean_intervals_are_narrower_and_the_gps_covers_the_truth(calibrated):
    """The mean's interval (calibrated std of the mean, same multiplier) lies inside the run's.
    It cannot be conformal (the mean is never observed): measured here, the GP's covers the
    truth at 80-100 % per quantity, the mlp's only ~65 % (docs/uncertainty.md)."""
    models, _, X, truth, _ = calibrated
    for model in models.values():
        mean, lo, hi = model.predict_interval(X[:50], kind="run")
        _, mlo, mhi = model.predict_interval(X[:50], kind="mean")
        assert (lo <= mlo).all() and (mlo <= mean).all() and (mean <= mhi).all() and (mhi <= hi).all()
    assert _coverage(models["gp"], X, truth, kind="mean")[:4].mean() >= 0.8


def test_cross_fitted_coverage_in_the_table_is_near_nominal(calibrated):
    _, table, *_ = calibrated
    kfold = table[table.scheme == "kfold"].groupby("model")
    assert kfold["coverage_pct"].mean().between(85, 97).all(), kfold["coverage_pct"].mean()
    # the mlp ensemble's own std band is over-confident; calibrated, it is not
    assert kfold["std_coverage_pct"].mean()["mlp"] < 70


def test_an_under_covering_model_is_flagged_and_passed_over(calibrated):
    _, table, *_ = calibrated
    table = table.copy()
    best = choose_model(table, ["mlp", "gp", "trees"], 85)[0]
    table.loc[(table.model == best) & (table.metric == "roughness_um") & (table.scheme == "kfold"),
              "coverage_pct"] = 70.0
    chosen = choose_model(table, ["mlp", "gp", "trees"], 85)[0]
    assert chosen != best
    text = model_choice_markdown(table, chosen, None, "smoke", CONFIDENCE, 85)
    assert "under-covers R_q" in text and f"**{chosen}**" in text
    # when every candidate under-covers, the best R^2 is taken and the table says so
    table["coverage_pct"] = 50.0
    assert choose_model(table, ["mlp", "gp", "trees"], 85)[0] == best
    assert "every candidate under-covers" in model_choice_markdown(table, best, None, None, CONFIDENCE, 85)


# --- the recommendation, grid and maps use the calibrated interval -----------------------------

def monotone(U, omega):
    """As tests/test_recommend.py: under porosity <= P the best U is (P - 20)/0.2 at omega -20."""
    U, omega = np.asarray(U, float), np.asarray(omega, float)
    return {"mass_g": 0.01 + 1e-4 * U, "throughput_mm2_s": 10 + 0.3 * U - 0.1 * omega,
            "roughness_um": 40 + 0.05 * omega**2, "porosity_pct": 20 + 0.2 * U}


@pytest.fixture(scope="module")
def monotone_model(tmp_path_factory):
    """A GP on the monotone metrics with 2 % noise, calibrated by hand: run intervals +-q sigma."""
    df = synthetic_dataset(1, noise=0.02, metrics=monotone)
    gp = GPSurrogate().fit(inputs_of(df), targets_of(df))
    rho = np.full(6, 0.02)
    scores = np.abs(np.random.default_rng(0).standard_normal((45, 6)))     # |N(0, 1)|: q ~ 1.7
    model = CalibratedSurrogate(gp, np.ones(6), rho, scores, 45, CONFIDENCE, "by hand")
    meta = {"input_range": {"U_mm_s": [40.0, 100.0], "omega_rad_s": [-20.0, 20.0]}}
    path = tmp_path_factory.mktemp("gp") / "model.joblib"
    save_surrogate(model, path, meta)
    return model, meta, path


def test_the_upper_end_of_the_run_interval_meets_the_limit(monotone_model):
    model, meta = monotone_model[:2]
    loose = recommend(model, meta, 34.0, n=101, confidence=0.5)
    safe = recommend(model, meta, 34.0, n=101)
    assert safe["confidence"] == CONFIDENCE and loose["confidence"] == 0.5 and safe["meets_confidence"]
    assert safe["porosity_pct_hi"] <= 34.0 < safe["porosity_pct_hi"] + 0.3      # at the limit, grid step 0.12 %
    assert safe["U_mm_s"] < loose["U_mm_s"] < 70.0                               # backs off from the limit
    # the interval reflects the run-to-run noise (2 % of ~33 % porosity): q x 0.66 % at least
    assert safe["porosity_pct_hi"] - safe["porosity_pct"] > 1.5 * 0.02 * safe["porosity_pct"]
    assert safe["n_feasible"] < loose["n_feasible"] < loose["n_feasible_mean"]


def test_cli_prints_the_interval_it_used(monotone_model, capsys):
    path = monotone_model[2]
    assert main(["--max-porosity", "34", "--grid-points", "101", "--model", str(path)]) == 0
    out = capsys.readouterr().out
    assert "upper end of the 90 % single-run interval within each limit" in out
    assert "Phi = 3" in out and "(a run: " in out
    assert main(["--max-porosity", "28.3", "--confidence", "0.97", "--grid-points", "101",
                 "--model", str(path)]) == 1
    out = capsys.readouterr().out
    assert "at none does the 97 % single-run interval stay within the limits" in out
    assert "lower --confidence" in out


@pytest.mark.parametrize("value", ["1.5", "0", "-0.2", "nan"])
def test_bad_confidence_exits_2_naming_it(monotone_model, capsys, value):
    with pytest.raises(SystemExit) as exit_:
        main(["--max-porosity", "34", "--confidence", value, "--model", str(monotone_model[2])])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and value in err


def test_margin_is_gone_with_a_clear_error(monotone_model, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--max-porosity", "34", "--margin", "1", "--model", str(monotone_model[2])])
    assert exit_.value.code == 2 and "--margin" in capsys.readouterr().err


def test_maps_draw_the_calibrated_interval_with_its_level(monotone_model, tmp_path):
    model = monotone_model[0]
    df = synthetic_dataset(1, noise=0.02, metrics=monotone)
    split = split_runs(df, 10, 0)
    interval_figure(model, df, split, "porosity_pct", n=11).savefig(tmp_path / "phi.svg")
    process_map_figure(model, df, split, n=21).savefig(tmp_path / "map.svg")
    assert "90 % of new DEM runs" in (tmp_path / "phi.svg").read_text()
    svg = (tmp_path / "map.svg").read_text()
    assert "90 % single-run interval" in svg and "cross-conformal" in svg


def test_the_adaptive_designs_gp_is_saved_calibrated(tmp_path, fit_params):
    from types import SimpleNamespace

    from analysis.surrogate.adaptive import write_result
    from analysis.surrogate.persistence import load_surrogate
    data = synthetic_dataset(2, noise=NOISE).iloc[::3].reset_index(drop=True)        # 15 runs
    result = SimpleNamespace(design=data[["U_mm_s", "omega_rad_s"]], rounds=pd.DataFrame({"round": [0]}),
                             data=data, stop="budget",
                             model=GPSurrogate(n_restarts=0).fit(inputs_of(data), targets_of(data)))
    write_result(result, tmp_path, "smoke", surrogate_params={**fit_params, "cv_repeats": 1})
    model, meta = load_surrogate(tmp_path / "model.joblib")
    assert meta["model"]["intervals"]["n_calibration_runs"] == 15
    assert recommend(model, meta, 60.0, n=21)["confidence"] == fit_params["confidence"]


def test_too_few_runs_for_the_level_is_said_not_drawn(monotone_model, tmp_path, capsys):
    gp, meta = monotone_model[0].model, monotone_model[1]
    few = CalibratedSurrogate(gp, np.ones(6), np.full(6, 0.02), np.ones((6, 6)), 6, CONFIDENCE)
    assert few.runs_needed() == 9 and not few.is_finite() and few.is_finite(0.85)
    with pytest.raises(ValueError, match="needs at least 9 calibration runs for a finite interval; this model has 6"):
        recommend(few, meta, 34.0, n=21)
    df = synthetic_dataset(1, noise=0.02, metrics=monotone)
    split = split_runs(df, 10, 0)
    interval_figure(few, df, split, "porosity_pct", n=11).savefig(tmp_path / "phi.svg")
    process_map_figure(few, df, split, n=21).savefig(tmp_path / "map.svg")
    assert "at least 9 needed" in (tmp_path / "phi.svg").read_text()
    assert "No interval crosses" in (tmp_path / "map.svg").read_text()
