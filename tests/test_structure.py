"""The layer-structure metrics beside eq. 7 (analysis/surrogate/structure.py): void fraction and coverage
derived from dataset.csv's columns, their calibration and stacking beside the four metrics' model, and
the surrogate rule fitting them without changing anything of the four."""

import json
import runpy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import layer_structure, structured_dataset, synthetic_dataset

from analysis.columns import METRICS, STRUCTURE_METRICS
from analysis.metrics.dataset import (
    coverage_pct,
    point_means,
    structure_problem,
    void_fraction_pct,
    with_structure_metrics,
)
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, split_runs, targets_of
from analysis.surrogate.intervals import (
    PRODUCTS,
    QUANTITIES,
    CalibratedStack,
    CalibratedSurrogate,
    SurrogateStack,
    conformal_quantile,
    metrics_of,
    relative_noise,
    share_scale,
    with_products,
)
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.selection import cross_validate_models, write_model_choice
from analysis.surrogate.structure import fit_structure, format_structure, stack_structure

STRUCTURE = list(STRUCTURE_METRICS)


class Constant:
    """A stand-in model: the same mean and std (one column each per metric) at every point."""

    def __init__(self, mean, std):
        self.mean, self.std = np.asarray(mean, float), np.asarray(std, float)

    def predict(self, X, return_std=False):
        n = len(np.atleast_2d(X))
        mean, std = np.tile(self.mean, (n, 1)), np.tile(self.std, (n, 1))
        return (mean, std) if return_std else mean


# --- the metrics, from dataset.csv's columns ------------------------------------------------------

def test_void_fraction_and_coverage_from_the_datasets_fractions():
    # the default map's run at U 40 mm/s, omega -15 rad/s: packing 0.6345 is 36.55 % void (its Phi: 4.0 %)
    assert void_fraction_pct(0.6345) == pytest.approx(36.55)
    assert void_fraction_pct([1.0, 0.0, np.nan])[:2].tolist() == [0.0, 100.0]
    assert np.isnan(void_fraction_pct([np.nan])[0])
    assert coverage_pct([0.9948, 0.4]) == pytest.approx([99.48, 40.0])
    df = pd.DataFrame({"U_mm_s": [40.0, 70.0], "packing_fraction": [0.6, 0.75], "coverage": [0.5, 1.0]})
    out = with_structure_metrics(df)
    assert out["void_fraction_pct"].tolist() == pytest.approx([40.0, 25.0])
    assert out["coverage_pct"].tolist() == pytest.approx([50.0, 100.0])
    assert "void_fraction_pct" not in df                                 # the caller's frame is not changed
    bare = synthetic_dataset(0)                                           # no fractions: left as it is
    assert list(with_structure_metrics(bare).columns) == list(bare.columns)


def test_structure_problem_says_what_is_missing():
    assert structure_problem(with_structure_metrics(synthetic_dataset(0))) == \
        "the dataset lacks packing_fraction, coverage"
    df = structured_dataset()
    assert structure_problem(with_structure_metrics(df)) is None
    df.loc[[3, 7], "packing_fraction"] = np.nan                           # empty layers: thk_avg = 0
    assert structure_problem(with_structure_metrics(df)) == \
        "runs [3, 7] have no finite packing fraction or coverage (an empty layer)"


def test_point_means_carry_the_structure_metrics_and_their_seed_spread():
    df = pd.DataFrame({"U_mm_s": [70.0, 70.0, 40.0], "omega_rad_s": [-15.0, -15.0, 0.0],
                       **{m: [1.0, 1.0, 1.0] for m in METRICS},
                       "packing_fraction": [0.60, 0.64, 0.70], "coverage": [0.99, 0.97, 0.50]})
    points, _ = point_means(with_structure_metrics(df))
    assert points["void_fraction_pct"].tolist() == pytest.approx([38.0, 30.0])
    assert points["void_fraction_pct_sd"].tolist() == pytest.approx([np.sqrt(8.0), 0.0])   # (40, 36): sd 2 sqrt 2
    assert points["coverage_pct"].tolist() == pytest.approx([98.0, 50.0])
    assert "void_fraction_pct" not in point_means(df)[0]                 # not derived: not there


# --- their calibration, beside the four ----------------------------------------------------------

def test_products_and_noise_of_metrics_without_products():
    mean, std = np.array([[30.0, 90.0]]), np.array([[1.0, 2.0]])
    assert with_products(mean, None, STRUCTURE, {}) == pytest.approx(mean)
    m, s = with_products(mean, std, STRUCTURE, {})
    assert m == pytest.approx(mean) and s == pytest.approx(std)
    # two replicates at each of two points: void 40/36 around 38 and 30/30; coverage 99/97 and 50/50
    df = pd.DataFrame({"U_mm_s": [70.0, 70.0, 40.0, 40.0], "omega_rad_s": [0.0] * 4,
                       "void_fraction_pct": [40.0, 36.0, 30.0, 30.0], "coverage_pct": [99.0, 97.0, 50.0, 50.0]})
    rho, source = relative_noise(df, metrics=STRUCTURE, products={})
    # sqrt(sum of squared relative deviations / (4 runs - 2 points))
    assert rho == pytest.approx([np.sqrt(2 * (2 / 38) ** 2 / 2), np.sqrt(2 * (1 / 98) ** 2 / 2)])
    assert "replicates" in source


def test_a_shares_noise_is_binomial_and_never_zero():
    assert share_scale([50.0, 80.0, 99.9, 100.0, -3.0]) == pytest.approx(
        [50.0, 40.0, np.sqrt(95 * 5), np.sqrt(95 * 5), np.sqrt(5 * 95)])          # clipped to 5..95 %
    # coverage replicates 99 / 97 around 98 (scale sqrt(95 x 5), clipped) and 50 / 50; void 40 / 36 and 30 / 30
    df = pd.DataFrame({"U_mm_s": [70.0, 70.0, 40.0, 40.0], "omega_rad_s": [0.0] * 4,
                       "void_fraction_pct": [40.0, 36.0, 30.0, 30.0], "coverage_pct": [99.0, 97.0, 50.0, 50.0]})
    rho, _ = relative_noise(df, metrics=STRUCTURE, products={}, shares=["coverage_pct"])
    assert rho == pytest.approx([np.sqrt(2 * (2 / 38) ** 2 / 2), np.sqrt(2 * (1 / np.sqrt(475)) ** 2 / 2)])
    model = CalibratedSurrogate(Constant([30.0, 99.0], [0.0, 0.0]), [1.0, 1.0], [0.1, 0.1],
                                np.ones((20, 2)), 20, 0.5, metrics=STRUCTURE, shares=["coverage_pct"])
    _, run, _ = model.half_widths(np.zeros((1, 2)))
    assert run[0] == pytest.approx([0.1 * 30.0, 0.1 * np.sqrt(95 * 5)])    # q = 1: rho x value, rho x share scale
    assert model.summary()["binomial_noise"].keys() == {"coverage_pct"}


def test_a_structure_surrogate_calibrates_its_own_two_quantities():
    scores = np.array([[0.5, 1.0], [1.0, 2.0], [1.5, 3.0], [2.0, 4.0]] * 5)      # 20 held-out runs
    model = CalibratedSurrogate(Constant([30.0, 90.0], [1.0, 2.0]), [2.0, 1.0], [0.1, 0.0], scores, 20,
                                0.5, "by hand", STRUCTURE)
    assert model.quantities == tuple(STRUCTURE) and model.products == {}
    q = conformal_quantile(scores, 0.5, 20)
    assert q == pytest.approx([1.5, 3.0])                   # ceil(0.5 x 21) = 11th of 20: 1.5 and 3.0
    mean, lo, hi = model.predict_interval(np.array([[70.0, 0.0]]))
    # void: q hypot(c s, rho mu) = 1.5 hypot(2 x 1, 0.1 x 30) = 1.5 sqrt(13); coverage: 3 x hypot(2, 0) = 6
    assert (hi - mean)[0] == pytest.approx([1.5 * np.sqrt(13.0), 6.0])
    assert (mean - lo)[0] == pytest.approx([1.5 * np.sqrt(13.0), 6.0])
    assert model.predict(np.zeros((1, 2)), return_std=True)[1][0] == pytest.approx([2.0, 2.0])   # c s
    summary = model.summary()
    assert summary["std_inflation"] == {"void_fraction_pct": 2.0, "coverage_pct": 1.0}


def test_a_model_saved_before_the_structure_metrics_keeps_the_four_and_their_products():
    old = CalibratedSurrogate(Constant([1.0] * 4, [0.1] * 4), np.ones(6), np.zeros(6), np.ones((20, 6)), 20)
    assert "metrics" not in vars(old) and "products" not in vars(old)     # an old pickle's attributes
    assert old.metrics == tuple(METRICS) and old.products == PRODUCTS and old.quantities == QUANTITIES
    assert metrics_of(old) == tuple(METRICS) and metrics_of(object()) == tuple(METRICS)


def test_a_stack_answers_as_its_parts_side_by_side():
    four = CalibratedSurrogate(Constant([0.01, 20.0, 80.0, 50.0], [0.001, 1.0, 2.0, 3.0]), np.ones(6),
                               np.full(6, 0.05), np.ones((20, 6)), 20, 0.9)
    layer = CalibratedSurrogate(Constant([30.0, 90.0], [1.0, 2.0]), np.ones(2), np.zeros(2), np.ones((15, 2)),
                                15, 0.9, metrics=STRUCTURE)
    stack = CalibratedStack([four, layer])
    X = np.array([[70.0, 0.0], [40.0, 10.0]])
    assert stack.metrics == (*METRICS, *STRUCTURE)
    assert stack.quantities == (*QUANTITIES, *STRUCTURE)
    mean, std = stack.predict(X, return_std=True)
    assert mean[0] == pytest.approx([0.01, 20.0, 80.0, 50.0, 30.0, 90.0]) and std.shape == (2, 6)
    for k, (a, b) in enumerate(zip(four.half_widths(X), layer.half_widths(X))):
        assert stack.half_widths(X)[k] == pytest.approx(np.column_stack([a, b]))
    assert stack.n_runs == 15 and stack.is_finite() and stack.runs_needed() == 9
    assert isinstance(stack.model, SurrogateStack) and stack.model.metrics == stack.metrics
    assert stack.model.predict(X).shape == (2, 6)
    with pytest.raises(ValueError, match="share a confidence level"):
        CalibratedStack([four, CalibratedSurrogate(layer.model, np.ones(2), np.zeros(2), np.ones((15, 2)), 15, 0.8,
                                                   metrics=STRUCTURE)])
    with pytest.raises(ValueError, match="disjoint metrics"):
        CalibratedStack([four, four])


# --- fitted beside the four ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def gp_params(fit_params):
    return {**fit_params, "models": ["gp"], "cv_repeats": 2, "gp_restarts": 0, "test_splits": 3, "grid_points": 11}


def test_fit_structure_scores_a_known_surface(gp_params):
    df = structured_dataset(noise=0.0)
    train, test = split_runs(df, 10, 0)
    model, record = fit_structure(df, gp_params, "gp", {"train": train, "test": test})
    assert model.metrics == tuple(STRUCTURE) and model.n_runs == 45
    assert record["model"] == "gp" and record["n_train"] == 35
    for m in STRUCTURE:                       # smooth, noise-free: the GP gets them almost exactly
        assert record["test"][m]["R"] > 0.99 and record["cv"]["kfold"][m]["R2"] > 0.97
    # the test R is the model's on the test runs, recomputed here
    derived = with_structure_metrics(df)
    pred = model.predict(inputs_of(derived)[test])
    r = np.corrcoef(derived["void_fraction_pct"].to_numpy()[test], pred[:, 0])[0, 1]
    assert record["test"]["void_fraction_pct"]["R"] == pytest.approx(r)
    assert "eps test R" in format_structure(record) and "C test R" in format_structure(record)
    json.dumps(record)                                                    # JSON-ready


def test_stack_structure_leaves_the_four_metrics_model_as_it_was(gp_params):
    df = structured_dataset()
    train, test = split_runs(df, 10, 0)
    four = CalibratedSurrogate(GPSurrogate(n_restarts=0).fit(inputs_of(df)[train], targets_of(df)[train]),
                               np.ones(6), np.full(6, 0.02), np.ones((45, 6)), 45, gp_params["confidence"])
    stacked, record = stack_structure(four, df, gp_params, "gp", {"train": train, "test": test})
    assert stacked.parts[0] is four and stacked.metrics == (*METRICS, *STRUCTURE)
    X = inputs_of(df)
    assert stacked.predict(X)[:, :4] == pytest.approx(four.predict(X), rel=0, abs=0)
    same, skipped = stack_structure(four, synthetic_dataset(0), gp_params, "gp", {"train": train, "test": test})
    assert same is four and skipped == {"skipped": "the dataset lacks packing_fraction, coverage"}


def _run_fit_surrogate(df, params, tmp_path, fake_snakemake):
    """The surrogate rule's script on ``df`` with a GP chosen; returns (scores, grid, model, log)."""
    tmp_path.mkdir(exist_ok=True)
    df.to_csv(tmp_path / "dataset.csv", index=False)
    table, held_out = cross_validate_models(df, params, return_predictions=True)
    write_model_choice(table, "gp", tmp_path / "choice.csv", tmp_path / "choice.md",
                       predictions=held_out, predictions_path=tmp_path / "cv.csv")
    out = {name: str(tmp_path / "surrogate" / file) for name, file in
           (("model", "model.joblib"), ("scores", "scores.json"), ("split", "split.csv"), ("grid", "grid.csv"))}
    smk = fake_snakemake({"dataset": str(tmp_path / "dataset.csv"), "choice": str(tmp_path / "choice.csv"),
                          "predictions": str(tmp_path / "cv.csv")}, out, {"surrogate": params, "grid_points": 11})
    smk.log = [str(tmp_path / "rule.log")]
    runpy.run_path(str(smk.scriptdir / "fit_surrogate.py"), init_globals={"snakemake": smk})
    return (json.loads(Path(out["scores"]).read_text()), pd.read_csv(out["grid"]), load_surrogate(out["model"])[0],
            (tmp_path / "rule.log").read_text())


def test_the_surrogate_rule_maps_them_and_changes_nothing_of_the_four(gp_params, tmp_path, fake_snakemake):
    with_layer = structured_dataset(noise=0.01)
    without = with_layer.drop(columns=["packing_fraction", "coverage"])
    scores, grid, model, log = _run_fit_surrogate(with_layer, gp_params, tmp_path / "with", fake_snakemake)
    plain, plain_grid, plain_model, _ = _run_fit_surrogate(without, gp_params, tmp_path / "without", fake_snakemake)
    # the paper's network and the chosen model score the four exactly as without the structure metrics
    assert scores["test"] == plain["test"] and scores["cv"] == plain["cv"]
    assert scores["test_spread"] == plain["test_spread"]
    assert scores["model"]["test"] == plain["model"]["test"] and scores["model"]["cv"] == plain["model"]["cv"]
    assert grid[list(plain_grid.columns)].to_numpy() == pytest.approx(plain_grid.to_numpy(), rel=1e-12)
    # ... and the structure metrics are fitted beside them, on the same split
    layer = scores["structure"]
    assert plain["structure"] == {"skipped": "the dataset lacks packing_fraction, coverage"}
    assert layer["model"] == "gp" and set(layer["test"]) == set(STRUCTURE) == set(layer["cv"]["kfold"])
    assert min(layer["test"][m]["R"] for m in STRUCTURE) > 0.95
    assert isinstance(model, CalibratedStack) and isinstance(plain_model, CalibratedSurrogate)
    for m in STRUCTURE:                       # on the grid with their calibrated intervals around the mean
        assert (grid[f"{m}_lo"] < grid[f"{m}_mean_lo"]).all() and (grid[f"{m}_mean_lo"] <= grid[m]).all()
        assert (grid[m] <= grid[f"{m}_mean_hi"]).all() and (grid[f"{m}_mean_hi"] < grid[f"{m}_hi"]).all()
    U, omega = grid["U_mm_s"].to_numpy(), grid["omega_rad_s"].to_numpy()
    truth = with_structure_metrics(pd.DataFrame(layer_structure(U, omega)))
    assert np.abs(grid["void_fraction_pct"] - truth["void_fraction_pct"]).max() < 1.0     # % points, 1 % noise
    assert "layer-structure metrics (gp, fitted on their own): eps test R" in log
