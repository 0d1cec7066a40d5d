"""Adaptive Design of Simulations on cheap synthetic objectives (no LIGGGHTS)."""

import numpy as np
import pandas as pd
import pytest
import yaml

from analysis.config import load_config, run_name
from analysis.metrics.dataset import METRICS
from analysis.surrogate.adaptive import (
    WorkflowEvaluator,
    choose_batch,
    initial_design,
    lattice,
    main,
    run_adaptive,
    snap,
)
from tests.test_config import ROOT

BOUNDS = ((40.0, 100.0), (-20.0, 20.0))
RES = (0.5, 0.25)
SETTINGS = {"initial_points": 10, "initial_design": "sobol", "batch_size": 3, "max_runs": 21,
            "target_loo_r2": None, "error_weight": 0.5, "seed": 0,
            "resolution_U_mm_s": 0.5, "resolution_omega_rad_s": 0.25}


def corner_feature(U, omega):
    """A gentle plane plus a sharp bump (6 mm/s x 2.5 rad/s wide) near U = 92, omega = 15."""
    bump = np.exp(-0.5 * (((U - 92) / 6) ** 2 + ((omega - 15) / 2.5) ** 2))
    return 1 + 0.01 * U + 0.02 * omega + 3 * bump


def broad_feature(U, omega):
    """The same plane with a wider bump (12 mm/s x 5 rad/s) near U = 88, omega = 12."""
    return 1 + 0.01 * U + 0.02 * omega + 3 * np.exp(-0.5 * (((U - 88) / 12) ** 2
                                                          + ((omega - 12) / 5) ** 2))


def near_feature(points):
    return (points[:, 0] >= 78) & (points[:, 1] >= 8)      # 11 % of the design space


class Synthetic:
    """Evaluator: the four metrics are multiples of ``corner_feature``; counts its calls."""

    def __init__(self, replicates=1, noise=0.0, function=corner_feature):
        self.replicates, self.noise, self.calls, self.function = replicates, noise, [], function
        self.rng = np.random.default_rng(0)

    def __call__(self, points):
        self.calls.append(np.array(points))
        P = np.repeat(np.asarray(points, float), self.replicates, axis=0)
        df = pd.DataFrame({"U_mm_s": P[:, 0], "omega_rad_s": P[:, 1]})
        f = self.function(P[:, 0], P[:, 1])
        for j, m in enumerate(METRICS):
            df[m] = (j + 1) * f * (1 + self.noise * self.rng.standard_normal(len(P)))
        return df


def test_initial_design_is_space_filling_seeded_nested_and_on_the_lattice():
    a = initial_design(12, BOUNDS, RES, "sobol", seed=3)
    assert a.shape == (12, 2) and len(np.unique(a, axis=0)) == 12
    assert np.array_equal(a, initial_design(12, BOUNDS, RES, "sobol", seed=3))
    assert not np.array_equal(a, initial_design(12, BOUNDS, RES, "sobol", seed=4))
    assert np.array_equal(initial_design(8, BOUNDS, RES, "sobol", seed=3), a[:8])   # nested
    assert np.allclose(a, snap(a, BOUNDS, RES))
    assert np.allclose((a[:, 0] - 40) / 0.5, np.round((a[:, 0] - 40) / 0.5))
    # every quarter of each axis holds points (space-filling)
    for j, (lo, hi) in enumerate(BOUNDS):
        quarter = np.floor(4 * (a[:, j] - lo) / (hi - lo)).clip(0, 3)
        assert set(quarter) == {0, 1, 2, 3}
    lhs = initial_design(12, BOUNDS, RES, "lhs", seed=0)
    assert lhs.shape == (12, 2) and (lhs[:, 0] >= 40).all() and (lhs[:, 1] <= 20).all()
    with pytest.raises(ValueError, match="'grid'"):
        initial_design(5, BOUNDS, RES, "grid")


def test_snap_and_lattice_stay_inside_the_range():
    assert snap([[39.0, 20.3], [70.26, -0.13]], BOUNDS, RES).tolist() == [[40.0, 20.0], [70.5, -0.25]]
    grid = lattice(BOUNDS, RES)
    assert len(grid) == 121 * 161 and grid.min(axis=0).tolist() == [40, -20]
    assert grid.max(axis=0).tolist() == [100, 20]


def test_adaptive_points_go_to_the_feature_and_it_stops_exactly_at_its_budget():
    evaluate = Synthetic()
    result = run_adaptive(evaluate, BOUNDS, SETTINGS, log=lambda line: None)
    assert result.stop == "budget"
    assert len(result.data) == 21 == len(result.design)           # 10 + 3 + 3 + 3 + 2
    assert [len(c) for c in evaluate.calls] == [10, 3, 3, 3, 2]
    added = result.design[result.design["round"] > 0][["U_mm_s", "omega_rad_s"]].to_numpy()
    assert near_feature(added).mean() > 0.4                       # area: 11 %
    assert near_feature(added[:6]).sum() >= 4                     # the first two batches
    assert len(np.unique(result.design[["U_mm_s", "omega_rad_s"]], axis=0)) == 21
    assert result.rounds["loo_R2_mean"].iloc[-1] > result.rounds["loo_R2_mean"].iloc[0] + 0.3
    assert list(result.rounds["n_runs"]) == [10, 13, 16, 19, 21]


def test_variance_alone_spreads_out_instead():
    """Why the error term: the GP's variance does not see where the function varies."""
    result = run_adaptive(Synthetic(), BOUNDS, {**SETTINGS, "error_weight": 0.0},
                          log=lambda line: None)
    added = result.design[result.design["round"] > 0][["U_mm_s", "omega_rad_s"]].to_numpy()
    assert near_feature(added).mean() < 0.25
    assert near_feature(added[:6]).sum() <= 1


def test_adaptive_beats_a_quasi_random_design_of_the_same_size():
    """On the broad feature the adaptive map (22 runs) is better than a Sobol design's.

    (On the sharp one it finds the feature but, its GP being stationary, its map
    error at 19-22 runs is no better than Sobol's: see docs/uncertainty.md.)"""
    from analysis.surrogate.candidates import GPSurrogate
    result = run_adaptive(Synthetic(function=broad_feature), BOUNDS, {**SETTINGS, "max_runs": 22},
                          log=lambda line: None)
    sobol = initial_design(22, BOUNDS, RES, "sobol", seed=0)
    quasi = Synthetic(function=broad_feature)(sobol)
    gp = GPSurrogate().fit(sobol, quasi[list(METRICS)].to_numpy())
    test = lattice(BOUNDS, (2.0, 1.0))
    truth = broad_feature(test[:, 0], test[:, 1])
    err = {name: np.sqrt(np.mean((model.predict(test)[:, 0] - truth) ** 2))
           for name, model in (("adaptive", result.model), ("sobol", gp))}
    assert err["adaptive"] < 0.85 * err["sobol"], err


def test_target_accuracy_stops_early_and_replicates_count_against_the_budget():
    result = run_adaptive(Synthetic(), BOUNDS, {**SETTINGS, "target_loo_r2": -10.0},
                          log=lambda line: None)
    assert result.stop == "target" and len(result.data) == 10
    evaluate = Synthetic(replicates=2, noise=0.01)
    result = run_adaptive(evaluate, BOUNDS, {**SETTINGS, "initial_points": 6, "max_runs": 17},
                          replicates=2, log=lambda line: None)
    assert len(result.data) == 16 and len(result.design) == 8      # 17 // 2 points
    assert [len(c) for c in evaluate.calls] == [6, 2]


def test_excluded_points_are_never_chosen():
    held_out = lattice(((82.0, 100.0), (9.0, 16.0)), (0.5, 0.25))    # most of the feature
    result = run_adaptive(Synthetic(), BOUNDS, SETTINGS, exclude=held_out, log=lambda line: None)
    added = result.design[result.design["round"] > 0][["U_mm_s", "omega_rad_s"]].to_numpy()
    inside = (added[:, 0] >= 82) & (added[:, 1] >= 9) & (added[:, 1] <= 16)
    assert len(added) == 11
    assert not inside.any()


def test_choose_batch_spreads_a_batch_out():
    from analysis.surrogate.candidates import GPSurrogate
    X = initial_design(10, BOUNDS, RES, seed=1)
    Y = np.column_stack([corner_feature(*X.T)] * 4)
    gp = GPSurrogate().fit(X, Y)
    batch, acq = choose_batch(gp, X, lattice(BOUNDS, (2.0, 1.0)), 4, 0.0)
    assert batch.shape == (4, 2) and len(np.unique(batch, axis=0)) == 4
    assert (np.diff(acq) <= 1e-12).all()                 # each pick lowers the next one's value
    gaps = np.linalg.norm((batch[:, None] - batch[None]) / [60, 40], axis=2)
    assert gaps[np.triu_indices(4, 1)].min() > 0.1


def test_imse_is_the_brute_force_drop_of_the_mean_variance():
    """The closed-form integrated variance reduction equals refitting the variance with the run added."""
    from analysis.surrogate.adaptive import _reference, _variance_reduction
    from analysis.surrogate.candidates import GPSurrogate
    X = initial_design(8, BOUNDS, RES, seed=2)
    Y = np.column_stack([corner_feature(*X.T), broad_feature(*X.T), X[:, 0], X[:, 1] ** 2])
    gp = GPSurrogate().fit(X, Y)
    Xs = gp.x_scaler_.transform(X)
    cand = gp.x_scaler_.transform(np.array([[41.0, 0.0], [70.0, 0.0], [99.0, 19.0]]))
    ref = _reference(((-1.5, 1.5), (-1.5, 1.5)), n=9)
    fast = _variance_reduction(gp, cand, Xs, ref, np.ones(len(ref)))
    before = gp._latent_var(ref, Xs).sum(axis=1).mean()
    slow = [before - gp._latent_var(ref, np.r_[Xs, c[None]]).sum(axis=1).mean() for c in cand]
    np.testing.assert_allclose(fast, slow, rtol=1e-6)
    assert fast.min() > 0


def test_imse_serves_the_box_where_maximum_variance_goes_to_its_edge():
    """Runs crowded at low U: maximum variance picks the far edge U = 100, IMSE steps inside it."""
    from analysis.surrogate.candidates import GPSurrogate
    X = np.array([(u, w) for u in (40.0, 50.0, 60.0) for w in (-20.0, 0.0, 20.0)])
    Y = np.column_stack([broad_feature(*X.T)] * 4) + 0.01 * np.arange(len(X))[:, None]
    gp = GPSurrogate(length_scale_bounds=(1.0, 1.0 + 1e-9)).fit(X, Y)
    cands = lattice(BOUNDS, (2.0, 1.0))
    mepe, _ = choose_batch(gp, X, cands, 1, 0.0)
    imse, _ = choose_batch(gp, X, cands, 1, 0.0, acquisition="imse", bounds=BOUNDS)
    assert mepe[0, 0] == 100.0
    assert 60.0 < imse[0, 0] < 100.0
    with pytest.raises(ValueError, match="'ei'"):
        choose_batch(gp, X, cands, 1, 0.0, acquisition="ei")


def test_too_small_a_budget_is_refused(capsys):
    with pytest.raises(ValueError, match="max_runs = 8"):
        run_adaptive(Synthetic(), BOUNDS, {**SETTINGS, "max_runs": 8}, log=lambda line: None)
    with pytest.raises(SystemExit) as exit_:
        main(["--max-runs", "5", "--level", "smoke"])
    assert exit_.value.code == 2 and "adaptive.max_runs = 5" in capsys.readouterr().err


def test_workflow_evaluator_asks_snakemake_for_the_new_runs_only(tmp_path, monkeypatch):
    """The evaluator's plumbing, with Snakemake replaced by a stand-in that writes the files."""
    import json
    import subprocess

    calls = []

    def fake_run(cmd, stdout=None, stderr=None):
        calls.append(cmd)
        targets = [c for c in cmd if c.endswith("metrics.json")]
        configs = cmd[cmd.index("--configfile") + 1:cmd.index("--cores")]
        merged = yaml.safe_load(open(configs[0]))
        for path in configs[1:]:
            for key, value in yaml.safe_load(open(path)).items():
                merged[key] = {**merged[key], **value} if isinstance(value, dict) else value
        load_config(merged)                                  # the round's config is valid
        stdout.write("rule spread:\n" * len(targets))
        for target in targets:
            run = target.split("/")[-2]
            U, w = float(run.split("_")[0][1:]), float(run.split("_")[1][1:])
            folder = tmp_path / "work" / target.rsplit("/", 1)[0]
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "metrics.json").write_text(json.dumps({
                "U_mm_s": U, "omega_rad_s": w, "replicate": 0, "mass_g": 1.0,
                "throughput_mm2_s": U, "roughness_um": 50.0, "porosity_pct": 40.0,
                "n_particles": 10}))
            (folder / "health.json").write_text(json.dumps({
                "heap_exhausted": False, "lost": 0, "through_substrate": 0,
                "max_overlap_fraction": 0.01}))
            bench = tmp_path / "work" / f"results/benchmarks/smoke/spread/{run}.tsv"
            bench.parent.mkdir(parents=True, exist_ok=True)
            bench.write_text("s\tcpu_time\tmax_rss\n1\t1.0\t10\n")
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(subprocess, "run", fake_run)
    ev = WorkflowEvaluator("smoke", tmp_path / "out", tmp_path / "work", cores=1, log=lambda s: None)
    first = ev(np.array([[47.5, -3.25], [90.0, 12.0], [62.0, 0.0], [100.0, -20.0]]))
    assert list(first["throughput_mm2_s"]) == [47.5, 62.0, 90.0, 100.0]
    second = ev(np.array([[70.0, 5.5]]))
    assert len(second) == 1 and second["omega_rad_s"].iloc[0] == 5.5
    asked = [c for c in calls[1] if c.endswith("metrics.json")]
    assert asked == [f"results/smoke/runs/{run_name(70.0, 5.5, 0)}/metrics.json"]
    round1 = yaml.safe_load((tmp_path / "out" / "round_1.yaml").read_text())
    assert round1["sweep"]["points_mm_s_rad_s"][-1] == [70.0, 5.5]
    assert len(round1["sweep"]["points_mm_s_rad_s"]) == 5 and round1["level"] == "smoke"
    assert str(ROOT / "Snakefile") in calls[0]
