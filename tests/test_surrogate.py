"""The surrogate of section 2.3: split, accuracy, scores, convergence, persistence."""

import json
import runpy
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pytest
import sklearn
from conftest import synthetic_dataset, synthetic_metrics
from sklearn.exceptions import ConvergenceWarning

from analysis.columns import METRICS
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, point_folds, read_split, split_runs, split_table, targets_of
from analysis.surrogate.network import deviation_from_paper, fit_surrogate, make_surrogate
from analysis.surrogate.network import test_r_spread as r_spread  # not a test of pytest's
from analysis.surrogate.persistence import load_surrogate, save_surrogate
from analysis.surrogate.predict import hybrid_indices, predict_grid
from analysis.surrogate.scores import R_TARGET, regression_scores
from analysis.surrogate.selection import cross_validate_models, write_model_choice


def test_split_is_35_10_seeded_and_reproducible(dataset):
    train, test = split_runs(dataset, 10, 0)
    assert (len(train), len(test)) == (35, 10)
    assert sorted(np.r_[train, test]) == list(range(45))
    again = split_runs(dataset, 10, 0)
    assert np.array_equal(train, again[0]) and np.array_equal(test, again[1])
    assert not np.array_equal(test, split_runs(dataset, 10, 1)[1])


@pytest.mark.parametrize("n_test", [0, 45, 50])
def test_split_rejects_impossible_test_size(dataset, n_test):
    with pytest.raises(ValueError, match=f"n_test={n_test}"):
        split_runs(dataset, n_test, 0)


def test_surrogate_reaches_the_papers_accuracy(fitted):
    _, scores = fitted
    assert scores["fit"]["converged"]
    assert scores["split"]["n_train"] == 35 and scores["split"]["n_test"] == 10
    for metric in METRICS:
        assert scores["test"][metric]["R"] >= R_TARGET, metric
        assert scores["train"][metric]["R"] >= R_TARGET, metric
        assert scores["test"][metric]["MAPE_pct"] < 5.0, metric
        assert scores["cv"][metric]["R2"] > 0.9, metric
    assert scores["warnings"] == []


def _hand_scores(y, p):
    """Pearson R, R^2 and MAPE (%) of one metric, written out: the oracle of `regression_scores`."""
    dy, dp = y - y.mean(), p - p.mean()
    return {"R": np.sum(dy * dp) / np.sqrt(np.sum(dy**2) * np.sum(dp**2)),
            "R2": 1 - np.sum((y - p) ** 2) / np.sum(dy**2),
            "MAPE_pct": 100 * np.mean(np.abs(p - y) / np.abs(y))}


def test_scores_values_recomputed_by_hand_and_json(fitted, dataset):
    """scores.json's train and test scores are the fitted network's on its split's runs (R, R^2
    and MAPE recomputed here from its predictions), on known fits R is 1 or -1 and R^2 what it
    must be, and the split and input range are the dataset's."""
    model, scores = fitted
    train, test = split_runs(dataset, 10, 0)
    assert scores["split"]["seed"] == 0
    assert scores["split"]["train"] == train.tolist() and scores["split"]["test"] == test.tolist()
    X, Y = inputs_of(dataset), dataset[list(METRICS)].to_numpy(float)
    for part, rows in (("train", train), ("test", test)):
        pred = model.predict(X[rows])
        for j, m in enumerate(METRICS):
            hand = _hand_scores(Y[rows, j], pred[:, j])
            got = scores[part][m]
            assert got["n_nonzero"] == len(rows), (part, m)
            for key, value in hand.items():
                assert got[key] == pytest.approx(value, rel=1e-9), (part, m, key)
    for m in METRICS:                                # the pooled out-of-fold predictions: no better than the fit
        assert scores["cv"][m]["n_nonzero"] == 45
        assert scores["cv"][m]["R2"] <= scores["train"][m]["R2"] + 1e-9
    # known fits: perfect, scaled and shifted (R 1, R^2 by hand), reversed (R -1)
    y = Y
    perfect = regression_scores(y, y)
    assert all(s["R"] == pytest.approx(1) and s["R2"] == pytest.approx(1) and s["MAPE_pct"] == 0
               for s in perfect.values())
    scaled = regression_scores(y, 1.1 * y)
    for j, s in enumerate(scaled.values()):
        d = y[:, j] - y[:, j].mean()
        assert s["R"] == pytest.approx(1)
        assert s["R2"] == pytest.approx(1 - np.sum((0.1 * y[:, j]) ** 2) / np.sum(d**2))
        assert s["MAPE_pct"] == pytest.approx(10)
    reversed_ = regression_scores(y, 2 * y.mean(axis=0) - y)
    assert all(s["R"] == pytest.approx(-1) for s in reversed_.values())
    assert scores["input_range"] == {"U_mm_s": [dataset["U_mm_s"].min(), dataset["U_mm_s"].max()],
                                     "omega_rad_s": [dataset["omega_rad_s"].min(), dataset["omega_rad_s"].max()]}
    assert scores["cv_settings"]["folds"] == 5
    assert scores["params"]["n_init"] == 3
    json.dumps(scores, allow_nan=False)          # strictly valid JSON


def test_fits_at_once_are_the_fits_one_at_a_time(fit_params):
    """fit_surrogate's split and fold fits in 2 processes: the same scores, and the out-of-fold scores
    those of scikit-learn's cross_val_predict over the same folds; test_r_spread takes the split whose
    scores it is given (fit_surrogate's own: the same fit) instead of refitting it."""
    from sklearn.model_selection import cross_val_predict

    data = synthetic_dataset(2, noise=0.05)
    params = {**fit_params, "hidden_units": 20, "n_init": 2}
    _, one = fit_surrogate(data, params)
    _, two = fit_surrogate(data, params, n_jobs=2)
    for part in ("train", "test", "cv"):
        assert one[part] == two[part], part
    X, Y = inputs_of(data), targets_of(data)
    reference = cross_val_predict(make_surrogate(params), X, Y, cv=point_folds(data, params["cv_folds"], 0))
    by_sklearn = regression_scores(Y, reference)      # the same predictions, summed in another memory order
    for m in METRICS:
        assert two["cv"][m] == pytest.approx(by_sklearn[m], rel=1e-12), m
    refitted = r_spread(data, params, 3, n_jobs=2)
    reused = r_spread(data, params, 3, known={0: one["test"]})
    assert refitted == reused and refitted["mass_g"]["R"][0] == one["test"]["mass_g"]["R"]
    made_up = {m: {**one["test"][m], "R": 0.5} for m in METRICS}
    assert r_spread(data, params, 3, known={0: made_up})["mass_g"]["R"] == [0.5, *refitted["mass_g"]["R"][1:]]


def test_papers_literal_adam_setting_does_not_converge(dataset, fit_params):
    """Why the default deviates: adam at learning rate 1e-4 in 200 epochs."""
    literal = {**fit_params, "solver": "adam", "learning_rate_init": 1e-4, "max_iter": 200}
    with pytest.warns(ConvergenceWarning, match="did not converge"):
        _, scores = fit_surrogate(dataset, literal)
    assert scores["fit"]["converged"] is False
    assert scores["fit"]["n_iter"] == 200
    assert "Maximum iterations (200) reached" in scores["fit"]["convergence_warnings"][0]
    assert scores["cv_settings"]["converged"] is False
    assert min(s["R"] for s in scores["test"].values()) < R_TARGET
    assert any("roughness_um" in w and "under-fits" in w for w in scores["warnings"])
    assert "as the paper's Table 2" in scores["deviation_from_paper"]


def test_default_deviation_is_stated(fit_params):
    text = deviation_from_paper(fit_params)
    assert "solver='lbfgs'" in text and "adam" in text and "does not converge" in text


def test_regression_scores_mape_skips_zero_truth():
    y_true = np.repeat([[0.0], [2.0], [4.0]], 4, axis=1)
    y_pred = np.repeat([[1.0], [3.0], [4.0]], 4, axis=1)
    scores = regression_scores(y_true, y_pred)
    for values in scores.values():
        assert values["MAPE_pct"] == pytest.approx(25.0)   # (1/2 + 0/4) / 2
        assert values["n_nonzero"] == 2
        assert values["R"] == pytest.approx(np.corrcoef([0, 2, 4], [1, 3, 4])[0, 1])
    constant = regression_scores(y_true, np.ones_like(y_true))
    assert constant["mass_g"]["R"] is None                    # undefined, not NaN


def test_a_single_test_run_has_mape_but_no_r(dataset, fit_params):
    """n_test 1: R and R^2 are undefined on one run and say so (None), not a crash."""
    _, scores = fit_surrogate(dataset, {**fit_params, "n_test": 1, "n_init": 1})
    assert scores["split"]["n_test"] == 1
    for values in scores["test"].values():
        assert values["R"] is None and values["R2"] is None
        assert values["MAPE_pct"] < 10.0
    json.dumps(scores, allow_nan=False)


def test_fit_rejects_missing_values(dataset, fit_params):
    broken = dataset.copy()
    broken.loc[7, "porosity_pct"] = np.nan
    with pytest.raises(ValueError, match=r"rows \[7\]"):
        fit_surrogate(broken, fit_params)


def test_save_load_roundtrip(fitted, dataset, tmp_path):
    model, scores = fitted
    path = tmp_path / "model.joblib"
    save_surrogate(model, path, scores)
    loaded, meta = load_surrogate(path)
    X = inputs_of(dataset)
    assert np.array_equal(loaded.predict(X), model.predict(X))
    assert meta["sklearn_version"] == sklearn.__version__
    assert meta["metrics"]["roughness_um"] == {"symbol": "R_q", "unit": "um"}
    assert meta["split"]["test"] == scores["split"]["test"]
    assert list(tmp_path.iterdir()) == [path]                 # no temporary left


def test_load_warns_when_sklearn_version_differs(fitted, tmp_path, monkeypatch):
    path = tmp_path / "model.joblib"
    monkeypatch.setattr(sklearn, "__version__", "0.0.1")
    save_surrogate(fitted[0], path, fitted[1])
    monkeypatch.undo()
    with pytest.warns(UserWarning, match=rf"scikit-learn 0\.0\.1 .*{sklearn.__version__}"):
        load_surrogate(path)


def test_load_rejects_a_foreign_file(tmp_path):
    path = tmp_path / "other.joblib"
    joblib.dump({"model": None}, path)
    with pytest.raises(ValueError, match="not a spreadmap surrogate"):
        load_surrogate(path)


def test_predict_grid_covers_the_range_with_indices(fitted):
    """The grid is the model's prediction at every (U, omega) of the linspace grid, and its hybrid
    indices are Figure 10's products, computed here by hand from the grid's own predicted metrics
    and, within the fit's error, from the synthetic truth at those speeds."""
    model = fitted[0]
    grid = predict_grid(model, (40, 100), (-20, 20), 5)
    assert len(grid) == 25
    assert list(grid.columns) == ["U_mm_s", "omega_rad_s", *METRICS,
                                  "throughput_index", "defect_index"]
    U, omega = (a.ravel() for a in np.meshgrid([40, 55, 70, 85, 100], [-20, -10, 0, 10, 20], indexing="ij"))
    assert np.array_equal(grid["U_mm_s"], U) and np.array_equal(grid["omega_rad_s"], omega)
    assert np.allclose(grid[list(METRICS)], model.predict(np.column_stack([U, omega])))
    M, Q, Rq, Phi = (grid[m].to_numpy() for m in ("mass_g", "throughput_mm2_s", "roughness_um", "porosity_pct"))
    assert np.allclose(grid["throughput_index"], Q / Q.max() * M / M.max())
    assert np.allclose(grid["defect_index"], Rq / Rq.max() * np.maximum(Phi, 0) / Phi.max())
    true = synthetic_metrics(U, omega)
    assert np.allclose(grid["throughput_index"], true["throughput_mm2_s"] / true["throughput_mm2_s"].max()
                       * true["mass_g"] / true["mass_g"].max(), atol=0.05)
    assert np.allclose(grid["defect_index"], true["roughness_um"] / true["roughness_um"].max()
                       * true["porosity_pct"] / true["porosity_pct"].max(), atol=0.05)


def test_split_table_roundtrip(dataset, tmp_path):
    train, test = split_runs(dataset, 10, 3)
    path = tmp_path / "split.csv"
    split_table(dataset, train, test).to_csv(path, index=False)
    back = read_split(path, dataset)
    assert np.array_equal(back[0], train) and np.array_equal(back[1], test)
    with pytest.raises(ValueError, match="does not match"):
        read_split(path, dataset.iloc[::-1])


def test_fit_surrogate_script(tmp_path, fit_params, fake_snakemake):
    """The rule keeps the paper network's scores and saves the model chosen by
    cross-validation (here a GP, from a model_choice.csv naming it)."""
    data = synthetic_dataset(0, noise=0.01)
    data.to_csv(tmp_path / "dataset.csv", index=False)
    params = {**fit_params, "grid_points": 11, "models": ["gp"],
              "cv_repeats": 1, "cv_loo": False, "test_splits": 3}
    table, held_out = cross_validate_models(data, params, return_predictions=True)
    write_model_choice(table, "gp", tmp_path / "choice.csv", tmp_path / "choice.md",
                       predictions=held_out, predictions_path=tmp_path / "cv.csv")
    out = {name: str(tmp_path / "surrogate" / file) for name, file in
           (("model", "model.joblib"), ("scores", "scores.json"), ("split", "split.csv"),
            ("grid", "grid.csv"))}
    smk = fake_snakemake({"dataset": str(tmp_path / "dataset.csv"),
                          "choice": str(tmp_path / "choice.csv"),
                          "predictions": str(tmp_path / "cv.csv")}, out,
                         {"surrogate": params, "grid_points": 11})
    runpy.run_path(str(smk.scriptdir / "fit_surrogate.py"), init_globals={"snakemake": smk})

    scores = json.loads(Path(out["scores"]).read_text())
    assert min(s["R"] for s in scores["test"].values()) >= R_TARGET       # the paper's network
    spread = scores["test_spread"]                 # ... and its test R over seeded splits, the first the same
    assert spread["n_splits"] == 3 and spread["seeds"] == [0, 1, 2]
    for m in METRICS:
        assert spread[m]["R"][0] == pytest.approx(scores["test"][m]["R"])
        assert spread[m]["R_min"] <= spread[m]["R_mean"] <= spread[m]["R_max"] and spread[m]["R_sd"] >= 0
    assert scores["model"]["name"] == "gp" and scores["model"]["n_train"] == 35
    assert min(s["R"] for s in scores["model"]["test"].values()) >= R_TARGET
    assert set(scores["model"]["cv"]["kfold"]) == set(METRICS)
    split = pd.read_csv(out["split"])
    assert split["set"].value_counts().to_dict() == {"train": 35, "test": 10}
    grid = pd.read_csv(out["grid"])
    assert len(grid) == 121 and grid["throughput_index"].max() == pytest.approx(1.0)
    assert (grid[[f"{m}_std" for m in METRICS]] > 0).all().all()
    for q in (*METRICS, "throughput_index", "defect_index"):      # calibrated intervals around the mean
        assert (grid[f"{q}_lo"] < grid[f"{q}_mean_lo"]).all() and (grid[f"{q}_mean_lo"] <= grid[q]).all()
        assert (grid[q] <= grid[f"{q}_mean_hi"]).all() and (grid[f"{q}_mean_hi"] < grid[f"{q}_hi"]).all()
    model, meta = load_surrogate(out["model"])
    assert isinstance(model.model, GPSurrogate) and meta["model"]["name"] == "gp"
    assert meta["model"]["intervals"]["confidence"] == params["confidence"]
    assert "cross-conformal" in meta["model"]["intervals"]["method"]
    assert meta["split"]["test"] == split.index[split["set"] == "test"].tolist()
    log = (tmp_path / "rule.log").read_text()
    assert "converged" in log and "chosen by cross-validation: gp" in log and "over 3 seeded 10-point" in log


def test_hybrid_indices_against_hand_computed_values():
    """Figure 10's indices for three settings worked by hand: throughput index
    Q_s/max(Q_s) * M_s/max(M_s), defect index R_q/max(R_q) * Phi/max(Phi)."""
    frame = pd.DataFrame({"mass_g": [0.010, 0.020, 0.005], "throughput_mm2_s": [20.0, 10.0, 40.0],
                          "roughness_um": [80.0, 100.0, 120.0], "porosity_pct": [60.0, 30.0, 45.0]})
    throughput, defect = hybrid_indices(frame)
    # maxima: M_s 0.020, Q_s 40, R_q 120, Phi 60
    assert throughput == pytest.approx([0.5 * 0.5, 0.25 * 1.0, 1.0 * 0.25])
    assert defect == pytest.approx([(80 / 120) * 1.0, (100 / 120) * 0.5, 1.0 * 0.75])
    # against the maxima of a whole map instead of this frame's
    maxima = {"mass_g": 0.04, "throughput_mm2_s": 80.0, "roughness_um": 160.0, "porosity_pct": 90.0}
    throughput, defect = hybrid_indices(frame.iloc[:1], maxima)
    assert throughput == pytest.approx([0.25 * 0.25]) and defect == pytest.approx([0.5 * (60 / 90)])
    with pytest.raises(ValueError, match="non-positive maximum: mass_g"):
        hybrid_indices(frame, {**maxima, "mass_g": 0.0})
