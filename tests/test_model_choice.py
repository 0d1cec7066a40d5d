"""Replicates, noise floor, candidate surrogates with a predictive std, cross-validated choice:
on synthetic data whose truth is known (their calibrated intervals: tests/test_intervals.py)."""

import re
import runpy

import numpy as np
import pandas as pd
import pytest
from conftest import synthetic_dataset, synthetic_metrics

from analysis.columns import METRICS
from analysis.metrics.dataset import point_groups, point_means
from analysis.metrics.noise_floor import POOLED, accuracy_ceiling, noise_floor, noise_floor_markdown, two_run_tolerance
from analysis.surrogate.candidates import GPSurrogate, MLPEnsemble, TreeEnsemble, make_candidate, refit_warm
from analysis.surrogate.data import inputs_of, point_folds, split_runs, targets_of
from analysis.surrogate.predict import predict_grid, predict_with_std
from analysis.surrogate.scores import regression_scores
from analysis.surrogate.selection import (
    choose_model,
    cross_validate_models,
    fold_scores,
    loo_candidates,
    model_choice_markdown,
    read_choice,
    write_model_choice,
)
from analysis.viz.maps import render_maps

NOISE = 0.05          # relative std of the synthetic runs' noise


def replicated(n_rep, noise, seed=0, metrics=synthetic_metrics):
    """The synthetic 45-point design with n_rep noisy replicates per point, as the dataset orders them."""
    parts = [synthetic_dataset(seed + r, noise=noise, metrics=metrics).assign(replicate=r)
             for r in range(n_rep)]
    return (pd.concat(parts).sort_values(["U_mm_s", "omega_rad_s", "replicate"], ignore_index=True))


@pytest.fixture(scope="module")
def dense():
    """400 random off-grid speeds and the noise-free metrics there, (n, 2) and (n, 4)."""
    rng = np.random.default_rng(5)
    X = np.c_[rng.uniform(40, 100, 400), rng.uniform(-20, 20, 400)]
    return X, np.column_stack(list(synthetic_metrics(X[:, 0], X[:, 1]).values()))


@pytest.fixture(scope="module")
def noisy():
    return synthetic_dataset(3, noise=NOISE)


@pytest.fixture(scope="module")
def gp(noisy):
    return GPSurrogate().fit(inputs_of(noisy), targets_of(noisy))


# --- replicates --------------------------------------------------------------------------

def test_replicates_of_a_point_never_straddle_train_and_test():
    df = replicated(3, 0.02)
    train, test = split_runs(df, 10, 0)
    assert len(test) == 30 and len(train) == 105
    groups = point_groups(df)
    assert not set(groups[train]) & set(groups[test])
    assert len(np.unique(groups[test])) == 10
    for tr, te in point_folds(df, 5, 0):
        assert not set(groups[tr]) & set(groups[te])
        assert len(te) % 3 == 0


def test_folds_test_every_point_exactly_once():
    df = replicated(2, 0.02)
    groups = point_groups(df)
    folds = point_folds(df, 5, 2)
    tested = np.concatenate([te for _, te in folds])
    assert sorted(tested) == list(range(len(df)))              # a partition of the runs
    assert all(len(np.unique(groups[te])) == 9 for _, te in folds)   # 45 points / 5 folds
    assert [te.tolist() for _, te in folds] != [te.tolist() for _, te in point_folds(df, 5, 3)]  # seeded
    loo = point_folds(df, 45, 0)
    assert len(loo) == 45 and all(len(np.unique(groups[te])) == 1 for _, te in loo)


def test_point_means_average_the_replicates():
    df = replicated(4, 0.05)
    points, split = point_means(df, split_runs(df, 10, 0))
    assert len(points) == 45 and (points["n_replicates"] == 4).all()
    first = df[(df.U_mm_s == 40) & (df.omega_rad_s == -20)]
    row = points[(points.U_mm_s == 40) & (points.omega_rad_s == -20)].iloc[0]
    assert row["porosity_pct"] == pytest.approx(first["porosity_pct"].mean())
    assert row["porosity_pct_sd"] == pytest.approx(first["porosity_pct"].std())
    assert (len(split[0]), len(split[1])) == (35, 10)


# --- noise floor --------------------------------------------------------------------------

def test_noise_floor_recovers_the_known_noise():
    rel = 0.03
    df = replicated(4, rel)
    table = noise_floor(df)
    assert len(table) == 45 + 1 and table["point"].iloc[-1] == POOLED
    pooled = table.iloc[-1]
    for m in METRICS:
        assert pooled[f"{m}_rel_pct"] == pytest.approx(100 * rel, rel=0.15), m
        per_point = table.iloc[:-1][f"{m}_rel_pct"]
        assert per_point.median() == pytest.approx(100 * rel, rel=0.3), m
    ceiling = accuracy_ceiling(df)
    for m in METRICS:
        c = ceiling[m]
        # MAPE of a perfect model = E|eps| = sqrt(2/pi) x relative noise
        assert c["MAPE_floor_pct"] == pytest.approx(100 * rel * np.sqrt(2 / np.pi), rel=0.2), m
        assert 0 < c["R2_max"] < 1 and c["R_max"] == pytest.approx(np.sqrt(c["R2_max"]))
    assert re.search(r"^\| \*\*pooled\*\* +\| 180 +\|", noise_floor_markdown(table), re.M)


def test_two_run_tolerance_is_k_sds_of_the_difference_of_two_runs():
    # two independent runs of one point (a resumed run scatters about its twin as a new heap
    # does): their difference exceeds k = 2 of its own sds 4.55 % of the time, k = 2 single-run
    # sds 15.7 %
    rng = np.random.default_rng(0)
    sd = dict(zip(METRICS, [1e-4, 2.0, 5.0, 3.0]))
    tolerance = two_run_tolerance(sd, k=2.0)
    for m, s in sd.items():
        d = rng.normal(0, s, 200_000) - rng.normal(0, s, 200_000)
        assert np.mean(np.abs(d) > tolerance[m]) == pytest.approx(0.0455, abs=0.003), m


def test_no_noise_floor_without_replicates(dataset):
    assert noise_floor(dataset).empty
    assert accuracy_ceiling(dataset) is None
    assert "sweep.replicates" in noise_floor_markdown(noise_floor(dataset))


# --- candidates recover a known function ---------------------------------------------------

def _relative_rmse(pred, truth):
    return np.sqrt(((pred - truth) ** 2).mean(axis=0)) / np.abs(truth).mean(axis=0)


def test_gp_recovers_the_function_within_the_noise(gp, dense):
    X, truth = dense
    mean, std = gp.predict(X, return_std=True)
    err = _relative_rmse(mean, truth)
    assert (err < NOISE).all(), err              # 45 noisy runs average below a run's noise
    assert (err < 0.6 * NOISE).mean() >= 0.5, err
    # its white-noise term finds the runs' noise (relative 5 % of each value)
    found = gp.noise_std_ / (NOISE * np.abs(truth).mean(axis=0))
    assert ((found > 0.6) & (found < 1.6)).all(), found
    # fitted length scales: short in omega (the multi-layer jump), in input units
    assert gp.length_scales_.shape == (4, 2)


def test_gp_std_covers_the_truth_at_about_the_nominal_rate(gp, dense):
    X, truth = dense
    mean, std = gp.predict(X, return_std=True)
    z = np.abs(mean - truth) / std
    assert 0.5 < (z < 1).mean() < 0.9                # nominal 68 %
    assert (z < 2).mean() > 0.82                      # nominal 95 %
    assert (std > 0).all()


def test_mlp_ensemble_recovers_the_function_within_the_noise(noisy, dense, fit_params):
    X, truth = dense
    ens = MLPEnsemble(fit_params, n_members=3).fit(inputs_of(noisy), targets_of(noisy))
    mean, std = ens.predict(X, return_std=True)
    err = _relative_rmse(mean, truth)
    assert (err < NOISE).all(), err
    assert (std > 0).all() and len(ens.members_) == 3
    # members differ only by their random seeds
    seeds = {m[-1].regressor.mlp.random_state for m in ens.members_}
    assert seeds == {0, 3, 6}


def test_trees_give_a_spread_and_a_rough_fit(noisy, dense):
    X, truth = dense
    trees = TreeEnsemble(100).fit(inputs_of(noisy), targets_of(noisy))
    mean, std = trees.predict(X, return_std=True)
    assert (_relative_rmse(mean, truth) < 3 * NOISE).all()
    assert std.shape == (400, 4) and (std.mean(axis=0) > 0).all()


def test_predict_with_std_needs_a_model_with_std(fitted, gp):
    with pytest.raises(ValueError, match="no predictive standard deviation"):
        predict_with_std(fitted[0], [70.0], [0.0])
    mean, std = predict_with_std(gp, [70.0, 85.0], [0.0, -5.0])
    assert mean.shape == std.shape == (2, 4)


def test_unknown_model_is_refused(fit_params):
    with pytest.raises(ValueError, match="'svm'"):
        make_candidate("svm", fit_params)


# --- cross-validated choice ----------------------------------------------------------------

@pytest.fixture(scope="module")
def cv_small(fit_params):
    """The CV table of all three candidates on a 3-replicate, 15-point design (quick settings)."""
    def metrics(U, omega):
        return synthetic_metrics(U, omega)
    df = replicated(2, 0.03, metrics=metrics)
    df = df[df.omega_rad_s.isin([-20, -10, 0, 10, 20])].reset_index(drop=True)   # 25 points
    params = {**fit_params, "hidden_units": 50, "mlp_members": 2, "cv_loo": True,
              "cv_repeats": 2, "cv_folds": 5, "gp_restarts": 0, "tree_count": 50}
    return df, params, cross_validate_models(df, params)


def test_cv_table_has_every_model_scheme_and_metric(cv_small):
    df, params, table = cv_small
    assert len(table) == 3 * 2 * 4
    assert set(table["model"]) == {"mlp", "gp", "trees"}
    assert set(table["scheme"]) == {"kfold", "loo"}
    assert np.isfinite(table[["R", "R2", "MAPE_pct", "R_sd", "R2_sd", "coverage_pct", "width_pct",
                              "interval_score_pct", "std_coverage_pct"]].to_numpy()).all()
    assert (table.loc[table.scheme == "kfold", "n_splits"] == 10).all()      # 5 folds x 2 repeats
    assert (table.loc[table.scheme == "loo", "n_splits"] == 25).all()        # one per point
    # on a smooth function every candidate is far better than the mean
    assert (table.groupby("model")["R2"].mean() > 0.8).all()
    # the GP is at or near the noise ceiling of these runs
    ceiling = accuracy_ceiling(df)
    gp = table[(table.model == "gp") & (table.scheme == "kfold")].set_index("metric")
    for m in ("roughness_um", "porosity_pct"):
        assert gp.loc[m, "R2"] <= ceiling[m]["R2_max"] + 0.02
        assert gp.loc[m, "R2"] > ceiling[m]["R2_max"] - 0.1


def test_choice_is_the_best_mean_kfold_r2_and_is_written(cv_small, tmp_path):
    _, params, table = cv_small
    chosen, ranking = choose_model(table, params["models"])
    kfold = table[table.scheme == "kfold"].groupby("model")["R2"].mean()
    se = table[table.scheme == "kfold"].groupby("model")["mean_R2_se"].first()
    assert ranking.index[0] == kfold.idxmax() and (se > 0).all()
    assert kfold.max() - kfold[chosen] <= se[kfold.idxmax()]
    write_model_choice(table, chosen, tmp_path / "c.csv", tmp_path / "c.md", confidence=0.9, min_coverage=85)
    name, back = read_choice(tmp_path / "c.csv")
    assert name == chosen and len(back) == len(table)
    text = (tmp_path / "c.md").read_text()
    assert f"Chosen: **{chosen}**" in text and "## Intervals: 90 % single-run" in text


def test_folds_fitted_in_parallel_score_the_same(cv_small):
    df, params, table = cv_small
    quick = {**params, "models": ["gp", "trees"], "cv_repeats": 1}
    serial = cross_validate_models(df, quick).drop(columns="fit_s")
    parallel = cross_validate_models(df, quick, n_jobs=2).drop(columns="fit_s")
    pd.testing.assert_frame_equal(serial, parallel)


def _scored(r2, se=0.0):
    """A k-fold table of models with a mean R^2 each (``{model: r2}``) and one standard error."""
    return pd.DataFrame([{"model": m, "scheme": "kfold", "metric": x, "R2": v, "mean_R2_se": se}
                         for m, v in r2.items() for x in METRICS])


def test_ties_go_to_the_first_listed_smooth_model():
    tied = _scored({"trees": 0.9, "gp": 0.9, "mlp": 0.9})
    assert choose_model(tied, ["trees", "gp", "mlp"])[0] == "gp"
    assert choose_model(tied, ["mlp", "gp", "trees"])[0] == "mlp"
    assert choose_model(tied.drop(columns="mean_R2_se"), ["gp", "trees"])[0] == "gp"   # an older table


def test_trees_win_only_by_more_than_the_standard_error():
    # the coin toss: trees 0.9201, mlp 0.9197, gp 0.907, per-fold spread far above the margin
    noisy = _scored({"mlp": 0.9197, "gp": 0.907, "trees": 0.9201}, se=0.01)
    chosen, ranking = choose_model(noisy, ["mlp", "gp", "trees"])
    assert chosen == "mlp" and ranking.index[0] == "trees"
    assert choose_model(noisy, ["gp", "mlp", "trees"])[0] == "mlp"     # gp is not within the margin
    assert choose_model(_scored({"mlp": 0.90, "gp": 0.915, "trees": 0.92}, se=0.01),
                        ["mlp", "gp", "trees"])[0] == "gp"
    assert choose_model(_scored({"mlp": 0.90, "gp": 0.88, "trees": 0.95}, se=0.01),
                        ["mlp", "gp", "trees"])[0] == "trees"
    text = model_choice_markdown(noisy.assign(symbol="x", R=0.9, MAPE_pct=1.0, n_splits=15, fit_s=1.0), "mlp")
    assert "+- 0.0100" in text and "tied with it: mlp 0.9197" in text and "first listed smooth model, **mlp**" in text


def test_leave_one_point_out_only_where_the_kfold_leaves_a_tie():
    """cv_loo: ties: no LOO when the best is clear of the rest by more than its standard error;
    the tied candidates (config order) when two or more are within it; never an under-covering one."""
    params = {"models": ["mlp", "gp", "trees"], "cv_loo": "ties", "confidence": 0.9, "coverage_tolerance_pct": 5}
    clear = _scored({"mlp": 0.90, "gp": 0.93, "trees": 0.85}, se=0.01)          # gp by 0.03 > 0.01
    assert loo_candidates(clear, params) == []
    tie = _scored({"trees": 0.92, "mlp": 0.915, "gp": 0.90}, se=0.01)           # mlp within, gp not
    assert loo_candidates(tie, params) == ["mlp", "trees"]
    assert loo_candidates(_scored({"mlp": 0.9, "gp": 0.9, "trees": 0.9}, se=0.01), params) == ["mlp", "gp", "trees"]
    low = tie.assign(symbol="x", coverage_pct=np.where(tie["model"] == "mlp", 70.0, 90.0))   # mlp under-covers
    assert loo_candidates(low, params) == []
    assert loo_candidates(clear, {**params, "cv_loo": True}) == ["mlp", "gp", "trees"]
    assert loo_candidates(tie, {**params, "cv_loo": False}) == []
    with pytest.raises(ValueError, match="cv_loo"):
        loo_candidates(tie, {**params, "cv_loo": "sometimes"})


def _plane(U, omega):
    """Metrics linear in the speeds: the GP fits them exactly, the trees do not."""
    U, omega = np.asarray(U, float), np.asarray(omega, float)
    return {"mass_g": 0.01 + 1e-4 * U + 2e-4 * omega, "throughput_mm2_s": 1 + 0.1 * U - 0.05 * omega,
            "roughness_um": 50 + 0.2 * U + 0.5 * omega, "porosity_pct": 40 + 0.1 * U + 0.3 * omega}


def _step(U, omega):
    """Metrics that jump where omega turns negative: the trees as good as the GP."""
    U, omega = np.asarray(U, float), np.asarray(omega, float)
    jump = (omega < 0).astype(float)
    return {"mass_g": 0.01 + 0.01 * jump + 1e-5 * U, "throughput_mm2_s": 1 + jump + 1e-3 * U,
            "roughness_um": 50 + 20 * jump, "porosity_pct": 40 + 10 * jump}


def test_cross_validation_runs_leave_one_point_out_for_the_tied_candidates_only(fit_params):
    quick = {**fit_params, "models": ["gp", "trees"], "cv_repeats": 1, "gp_restarts": 0, "tree_count": 20,
             "cv_loo": "ties"}
    # the GP fits a plane exactly: the k-fold decides alone, no leave-one-point-out, and the table says so
    clear = cross_validate_models(synthetic_dataset(0, metrics=_plane), quick)
    assert set(clear["scheme"]) == {"kfold"} and choose_model(clear, quick["models"], 85)[0] == "gp"
    text = model_choice_markdown(clear, "gp", confidence=0.9, min_coverage=85, cv_loo="ties")
    assert "Leave-one-point-out skipped" in text and "margin of gp" in text
    # a step both model about as well (0.683 against 0.677, margin 0.050): both tied, both left out point
    # by point, with the scores every-candidate leave-one-point-out gives them
    df = synthetic_dataset(0, noise=0.1, metrics=_step)
    tied, predictions = cross_validate_models(df, quick, return_predictions=True)
    every = cross_validate_models(df, {**quick, "cv_loo": True}).drop(columns="fit_s")
    assert list(zip(tied["model"], tied["scheme"]))[::4] == [("gp", "kfold"), ("gp", "loo"),
                                                             ("trees", "kfold"), ("trees", "loo")]
    pd.testing.assert_frame_equal(tied.drop(columns="fit_s"), every)
    assert (tied.loc[tied.scheme == "loo", "n_splits"] == 45).all()
    assert len(predictions) == 2 * (45 + 45)
    text = model_choice_markdown(tied, "gp", confidence=0.9, min_coverage=85, cv_loo="ties")
    assert "only for the candidates tied within the margin (gp, trees" in text


def test_trees_predict_what_their_trees_predict(noisy):
    """TreeEnsemble.predict skips each tree's input checks: the mean and spread of the trees'
    own predict(), exactly, for several targets and for one."""
    X, Y = inputs_of(noisy), targets_of(noisy)
    grid = np.c_[np.linspace(40, 100, 7), np.linspace(-20, 20, 7)]
    for y in (Y, Y[:, 2]):
        model = TreeEnsemble(n_trees=25).fit(X, y)
        trees = np.stack([t.predict(grid) for t in model.forest_.estimators_]).reshape(25, len(grid), -1)
        mean, std = model.predict(grid, return_std=True)
        np.testing.assert_array_equal(mean, model._shaped(trees.mean(axis=0) * model.y_scale_ + model.y_mean_))
        np.testing.assert_array_equal(std, model._shaped(trees.std(axis=0) * model.y_scale_))
        assert mean.shape == ((7, 4) if y.ndim == 2 else (7,))


def test_ensemble_members_fitted_in_parallel_are_the_same(noisy, fit_params):
    params = {**fit_params, "hidden_units": 20, "n_init": 1}
    X, Y = inputs_of(noisy), targets_of(noisy)
    serial = MLPEnsemble(params, n_members=3).fit(X, Y)
    parallel = MLPEnsemble(params, n_members=3, n_jobs=2).fit(X, Y)
    for a, b in zip(serial.predict(X, return_std=True), parallel.predict(X, return_std=True)):
        np.testing.assert_array_equal(a, b)
    assert serial.predict(X, return_std=True)[1].min() > 0          # three different networks


def test_fold_scores_average_to_the_pooled_r2():
    rng = np.random.default_rng(1)
    Y = rng.normal(size=(45, 4)) * [1e-3, 10, 5, 3]
    pred = Y + rng.normal(size=Y.shape) * [3e-4, 2, 1, 1]
    folds = point_folds(synthetic_dataset(0), 5, 0)
    pooled = np.mean([v["R2"] for v in regression_scores(Y, pred).values()])
    assert fold_scores(Y, pred, folds).mean() == pytest.approx(pooled)


def test_warm_refit_is_close_to_a_fresh_fit_and_cheaper(noisy, fit_params):
    params = {**fit_params, "hidden_units": 50}
    X, Y = inputs_of(noisy), targets_of(noisy)
    start = MLPEnsemble(params, n_members=2).fit(X[:36], Y[:36])
    warm = refit_warm(start, X[:44], Y[:44])
    fresh = MLPEnsemble(params, n_members=2).fit(X[:44], Y[:44])
    assert start.predict(X[44:]) != pytest.approx(warm.predict(X[44:]))         # it was refitted ...
    scale = np.abs(Y).mean(axis=0)
    assert (np.abs(warm.predict(X) - fresh.predict(X)).mean(axis=0) < 0.05 * scale).all()   # ... to about the same
    iterations = [m[-1].regressor_.n_iter_ for m in warm.members_]
    assert sum(iterations) < sum(m[-1].regressor_.n_iter_ for m in fresh.members_) * params["n_init"]


def test_markdown_puts_the_noise_ceiling_beside_the_scores(cv_small):
    df, params, table = cv_small
    text = model_choice_markdown(table, "gp", accuracy_ceiling(df), "smoke")
    assert re.search(r"^\| \*\*gp\*\* +\| kfold +\|", text, re.M)
    assert re.search(r"^\| \*noise ceiling\* +\| replicates +\|", text, re.M)
    assert "not measured" in model_choice_markdown(table, "gp", None)


def test_scripts_write_noise_floor_and_model_choice(tmp_path, fake_snakemake, fit_params):
    df = replicated(2, 0.03)
    df = df[df.omega_rad_s.isin([-20, 0, 20])].reset_index(drop=True)
    df.to_csv(tmp_path / "dataset.csv", index=False)
    smk = fake_snakemake({"dataset": str(tmp_path / "dataset.csv")},
                         {"csv": str(tmp_path / "nf.csv"), "md": str(tmp_path / "nf.md")},
                         {"level": "smoke"})
    runpy.run_path(str(smk.scriptdir / "noise_floor.py"), init_globals={"snakemake": smk})
    assert len(pd.read_csv(tmp_path / "nf.csv")) == 15 + 1
    params = {**fit_params, "models": ["gp", "trees"], "cv_repeats": 1,
              "cv_folds": 3, "cv_loo": False, "tree_count": 20}
    smk = fake_snakemake({"dataset": str(tmp_path / "dataset.csv")},
                         {"csv": str(tmp_path / "mc.csv"), "md": str(tmp_path / "mc.md"),
                          "predictions": str(tmp_path / "cv.csv")},
                         {"surrogate": params, "level": "smoke"})
    runpy.run_path(str(smk.scriptdir / "model_choice.py"), init_globals={"snakemake": smk})
    name, table = read_choice(tmp_path / "mc.csv")
    assert name in ("gp", "trees") and len(table) == 2 * 4
    text = (tmp_path / "mc.md").read_text()
    assert "noise ceiling" in text and "interval score" in text
    held_out = pd.read_csv(tmp_path / "cv.csv")
    assert len(held_out) == 2 * len(df) and set(held_out["model"]) == {"gp", "trees"}
    assert {f"{m}_std" for m in METRICS} <= set(held_out.columns)


# --- uncertainty on the maps (the recommendation: tests/test_intervals.py) -----------------

def test_grid_and_maps_carry_the_predictive_std(gp, noisy, tmp_path):
    grid = predict_grid(gp, (40, 100), (-20, 20), 11)
    for m in METRICS:
        assert (grid[f"{m}_std"] > 0).all()
    assert (grid["throughput_index_std"] > 0).all() and (grid["defect_index_std"] >= 0).all()
    # the std grows away from the runs
    at_run = gp.predict(np.array([[70.0, 0.0]]), return_std=True)[1]
    beyond = gp.predict(np.array([[130.0, 30.0]]), return_std=True)[1]
    assert (beyond > 2 * at_run).all()
    train, test = split_runs(noisy, 10, 0)
    paths = render_maps(gp, noisy, (train, test), tmp_path / "maps", n=15)
    names = {p.name for p in paths}
    # an uncalibrated model draws no uncertainty maps and no crosses: its std is not an interval
    assert not any("_interval" in n or "_std" in n for n in names) and "process_map.svg" in names
    assert "interval" not in (tmp_path / "maps" / "process_map.svg").read_text()
