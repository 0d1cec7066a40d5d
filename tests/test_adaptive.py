"""Adaptive Design of Simulations on cheap synthetic objectives (no LIGGGHTS)."""

import numpy as np
import pandas as pd
import pytest
import yaml

from analysis.adaptive_workflow import WorkflowEvaluator, main, round_config
from analysis.columns import METRICS
from analysis.config.errors import ConfigError
from analysis.config.load import load_config
from analysis.config.sweep import run_name, runs_by_name
from analysis.surrogate.acquisition import choose_batch
from analysis.surrogate.adaptive import check_settings, run_adaptive
from analysis.surrogate.design_space import initial_design, lattice, snap, sweep_bounds, sweep_resolution
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
    from analysis.surrogate.acquisition import _reference, _variance_reduction
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


def fake_snakemake(work, calls):
    """A stand-in for ``subprocess.run`` of Snakemake: checks the merged round config and writes
    each requested run's metrics (Q_s = U, R_q = the gap if swept), health and benchmark files,
    the run found by its folder name in that config (:func:`analysis.config.sweep.runs_by_name`)."""
    import json
    import subprocess

    from snakemake.utils import update_config

    def fake_run(cmd, stdout=None, stderr=None):
        calls.append(cmd)
        targets = [c for c in cmd if c.endswith("metrics.json")]
        configs = cmd[cmd.index("--configfile") + 1:cmd.index("--cores")]
        merged = yaml.safe_load(open(configs[0]))
        for path in configs[1:]:
            update_config(merged, yaml.safe_load(open(path)))
        table = runs_by_name(load_config(merged, base_dir=ROOT))       # the round's config is valid
        stdout.write("rule spread:\n" * len(targets))
        for target in targets:
            name = target.split("/runs/", 1)[1].rsplit("/", 1)[0]
            run = table[name]
            folder = work / target.rsplit("/", 1)[0]
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "metrics.json").write_text(json.dumps({
                **run.point, "replicate": run.replicate, "mass_g": 1.0,
                "throughput_mm2_s": run.U, "roughness_um": run.point.get("roller.gap_um", 50.0),
                "porosity_pct": 40.0, "n_particles": 10}))
            (folder / "health.json").write_text(json.dumps({
                "heap_exhausted": False, "lost": 0, "through_substrate": 0,
                "max_overlap_fraction": 0.01}))
            bench = work / f"results/benchmarks/smoke/spread/{name}.tsv"
            bench.parent.mkdir(parents=True, exist_ok=True)
            bench.write_text("s\tcpu_time\tmax_rss\n1\t1.0\t10\n")
        return subprocess.CompletedProcess(cmd, 0)

    return fake_run


def test_workflow_evaluator_asks_snakemake_for_the_new_runs_only(tmp_path, monkeypatch):
    """The evaluator's plumbing, with Snakemake replaced by a stand-in that writes the files."""
    import subprocess

    calls = []
    monkeypatch.setattr(subprocess, "run", fake_snakemake(tmp_path / "work", calls))
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


# -- three inputs: U, omega and a swept gap (roller.gap_um, um) --------------------------------

GAP = "roller.gap_um"
BOUNDS3 = ((40.0, 100.0), (-20.0, 20.0), (300.0, 400.0))
RES3 = (2.0, 1.0, 25.0)
SETTINGS3 = {**SETTINGS, "initial_points": 12, "batch_size": 4, "max_runs": 40,
             "resolution_U_mm_s": 2.0, "resolution_omega_rad_s": 1.0, "resolution": {GAP: 25.0}}


def gap_feature(U, omega, gap):
    """A plane in all three inputs and a bump (10 mm/s x 30 um) near U = 85, gap = 375 um."""
    return (1 + 0.01 * U + 0.02 * omega - 0.006 * (gap - 300)
            + 3 * np.exp(-0.5 * (((U - 85) / 10) ** 2 + ((gap - 375) / 30) ** 2)))


def synthetic3(points):
    """Evaluator over (U, omega, gap): the four metrics are multiples of ``gap_feature``."""
    P = np.asarray(points, float)
    df = pd.DataFrame({"U_mm_s": P[:, 0], "omega_rad_s": P[:, 1], GAP: P[:, 2]})
    for j, m in enumerate(METRICS):
        df[m] = (j + 1) * gap_feature(*P.T)
    return df


def on_lattice(points, bounds, resolution):
    lo, res = np.array([b[0] for b in bounds]), np.array(resolution)
    steps = (points - lo) / res
    return np.allclose(steps, np.round(steps)) and np.allclose(points, snap(points, bounds, resolution))


def test_three_input_lattice_and_snap_cover_the_box():
    grid = lattice(BOUNDS3, RES3)
    assert grid.shape == (31 * 41 * 5, 3) and len(np.unique(grid, axis=0)) == len(grid)
    assert grid.min(axis=0).tolist() == [40, -20, 300] and grid.max(axis=0).tolist() == [100, 20, 400]
    assert sorted(set(grid[:, 2])) == [300, 325, 350, 375, 400]
    assert on_lattice(grid, BOUNDS3, RES3)
    assert snap([[39.0, 20.3, 290.0], [70.9, -0.4, 362.4], [101.0, 0.0, 413.0]], BOUNDS3, RES3).tolist() \
        == [[40.0, 20.0, 300.0], [70.0, 0.0, 350.0], [100.0, 0.0, 400.0]]


def test_three_input_initial_design_is_distinct_seeded_nested_and_on_the_lattice():
    for method in ("sobol", "lhs"):
        a = initial_design(20, BOUNDS3, RES3, method, seed=5)
        assert a.shape == (20, 3) and len(np.unique(a, axis=0)) == 20
        assert on_lattice(a, BOUNDS3, RES3)
        assert ((a >= [b[0] for b in BOUNDS3]) & (a <= [b[1] for b in BOUNDS3])).all()
        assert np.array_equal(a, initial_design(20, BOUNDS3, RES3, method, seed=5))
        assert not np.array_equal(a, initial_design(20, BOUNDS3, RES3, method, seed=6))
        assert len(set(a[:, 2])) >= 4                    # the gap is a design dimension
    a = initial_design(20, BOUNDS3, RES3, "sobol", seed=5)
    assert np.array_equal(initial_design(12, BOUNDS3, RES3, "sobol", seed=5), a[:12])   # nested
    with pytest.raises(ValueError, match=r"\(2 mm/s x 1 rad/s x 25 um \(roller\.gap_um\)\) is too coarse for 31"):
        initial_design(31, ((40.0, 42.0), (-1.0, 1.0), (300.0, 400.0)), RES3, names=["U_mm_s", "omega_rad_s", GAP])


def test_a_single_valued_axis_is_held_and_leaves_the_two_input_design_as_it_was():
    held = (*BOUNDS, (350.0, 350.0))
    a = initial_design(12, held, (*RES, 25.0), "sobol", seed=3)
    assert np.array_equal(a[:, :2], initial_design(12, BOUNDS, RES, "sobol", seed=3))
    assert (a[:, 2] == 350.0).all()
    assert set(lattice(held, (2.0, 1.0, 25.0))[:, 2]) == {350.0}
    assert snap([[70.0, 0.0, 390.0]], held, (*RES, 25.0)).tolist() == [[70.0, 0.0, 350.0]]


def test_choose_batch_over_three_inputs_picks_distinct_unrun_lattice_points():
    from analysis.surrogate.candidates import GPSurrogate
    X = initial_design(12, BOUNDS3, RES3, seed=1)
    gp = GPSurrogate().fit(X, synthetic3(X)[list(METRICS)].to_numpy())
    cands = lattice(BOUNDS3, (4.0, 2.0, 25.0))
    exclude = cands[cands[:, 2] == 400.0]
    for acquisition in ("mepe", "imse"):
        batch, acq = choose_batch(gp, X, cands, 5, 0.5, exclude=exclude, acquisition=acquisition,
                                  bounds=BOUNDS3)
        assert batch.shape == (5, 3) and len(np.unique(batch, axis=0)) == 5 and np.isfinite(acq).all()
        rows = {tuple(p) for p in cands.tolist()}
        assert all(tuple(p) in rows for p in batch.tolist())                 # on the lattice
        assert not {tuple(p) for p in batch.tolist()} & {tuple(p) for p in X.tolist()}   # not run yet
        assert (batch[:, 2] != 400.0).all()                                  # not excluded


def test_adaptive_design_over_three_inputs_reaches_its_target_loo_r2():
    result = run_adaptive(synthetic3, BOUNDS3, {**SETTINGS3, "target_loo_r2": 0.95}, axes=[GAP],
                          log=lambda line: None)
    assert result.stop == "target" and len(result.data) <= 28            # measured: 24 runs
    r2 = result.rounds["loo_R2_mean"]
    assert r2.iloc[0] < 0.9 and r2.iloc[-1] >= 0.95
    assert list(result.design.columns) == ["U_mm_s", "omega_rad_s", GAP, "round", "acquisition"]
    points = result.design[["U_mm_s", "omega_rad_s", GAP]].to_numpy()
    assert len(np.unique(points, axis=0)) == len(points) and on_lattice(points, BOUNDS3, RES3)
    assert len(set(points[result.design["round"] > 0, 2])) >= 3          # batches move the gap too
    assert result.model.length_scales_.shape[-1] == 3


def test_bounds_and_resolution_errors_name_the_axis():
    names = ["U_mm_s", "omega_rad_s", GAP]
    with pytest.raises(ValueError, match=r"roller\.gap_um \(um\) range 400\.\.300 is reversed"):
        initial_design(5, ((40.0, 100.0), (-20.0, 20.0), (400.0, 300.0)), RES3, names=names)
    with pytest.raises(ValueError, match=r"lattice spacing of roller\.gap_um \(um\) is 0"):
        initial_design(5, BOUNDS3, (2.0, 1.0, 0.0), names=names)
    with pytest.raises(ValueError, match=r"the U \(mm/s\) range 70\.\.70 is empty"):
        initial_design(5, ((70.0, 70.0), (-20.0, 20.0), (300.0, 400.0)), RES3, names=names)
    with pytest.raises(ValueError, match=r"adaptive\.resolution\.roller\.gap_um is not given"):
        run_adaptive(synthetic3, BOUNDS3, SETTINGS, axes=[GAP], log=lambda line: None)
    with pytest.raises(ValueError, match=r"adaptive\.resolution\.psd\.mean_diameter_um: not an extra axis"):
        check_settings({**SETTINGS3, "resolution": {"psd.mean_diameter_um": 5}}, axes=(GAP,))
    with pytest.raises(ValueError, match=r"adaptive\.resolution\.roller\.gap_um = -5"):
        check_settings({**SETTINGS3, "resolution": {GAP: -5}}, axes=(GAP,))
    with pytest.raises(ValueError, match=r"returned runs over U_mm_s, omega_rad_s; the design's inputs are"):
        run_adaptive(lambda P: synthetic3(P).drop(columns=GAP), BOUNDS3, SETTINGS3, axes=[GAP],
                     log=lambda line: None)


def gap_config(tmp_path, gaps=(300, 350, 400), resolution=None):
    """config.yaml with the gap swept (and ``adaptive.resolution`` if given), written to tmp_path."""
    raw = yaml.safe_load((ROOT / "config.yaml").read_text())
    raw["sweep"][GAP] = list(gaps)
    if resolution is not None:
        raw["adaptive"]["resolution"] = resolution
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def test_the_box_and_lattice_of_a_sweep_with_a_gap_axis(tmp_path):
    config = load_config(gap_config(tmp_path, (300, 320, 400)), base_dir=ROOT)
    assert sweep_bounds(config) == ((40.0, 100.0), (-20.0, 20.0), (300.0, 400.0))
    assert sweep_resolution(config, config["adaptive"]) == (0.5, 0.25, 20.0)   # its smallest spacing
    config = load_config(gap_config(tmp_path, resolution={GAP: 25}), base_dir=ROOT)
    assert sweep_resolution(config, config["adaptive"]) == (0.5, 0.25, 25.0)
    with pytest.raises(ConfigError, match=r"'adaptive\.resolution\.roller\.gap_um'"):
        load_config(gap_config(tmp_path, resolution={GAP: 0}), base_dir=ROOT)


def test_an_unswept_resolution_key_is_refused_in_one_line(tmp_path, capsys):
    path = gap_config(tmp_path, resolution={"material.restitution": 0.1})
    with pytest.raises(SystemExit) as exit_:
        main(["--config", str(path), "--level", "smoke"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1
    assert "adaptive.resolution.material.restitution: not an extra axis of the sweep (roller.gap_um)" in err


def test_round_config_lists_points_over_all_axes():
    two = round_config("smoke", [[70.0, 5.5]], replicates=2, n_test=1)
    assert two == {"level": "smoke", "sweep": {"points_mm_s_rad_s": [[70.0, 5.5]], "replicates": 2},
                   "surrogate": {"n_test": 1}}
    three = round_config("smoke", [[70.0, 5.5, 350.0], [40.0, -20.0, 400.0]], [GAP])
    assert three["sweep"] == {"points": [{"U_mm_s": 70.0, "omega_rad_s": 5.5, GAP: 350.0},
                                         {"U_mm_s": 40.0, "omega_rad_s": -20.0, GAP: 400.0}],
                              "replicates": 1}
    with pytest.raises(ValueError, match="3 inputs"):
        round_config("smoke", [[70.0, 5.5]], [GAP])


def test_workflow_evaluator_runs_a_gap_axis_in_the_config_s_run_folders(tmp_path, monkeypatch):
    """Folders come from the round's config (Run.name), the gap reaches the dataset's rows."""
    import subprocess

    calls = []
    monkeypatch.setattr(subprocess, "run", fake_snakemake(tmp_path / "work", calls))
    ev = WorkflowEvaluator("smoke", tmp_path / "out", tmp_path / "work", cores=1,
                           configfile=gap_config(tmp_path), log=lambda s: None)
    assert ev.axes == [GAP]
    first = ev(np.array([[47.5, -3.25, 300.0], [90.0, 12.0, 350.0], [62.0, 0.0, 400.0],
                         [100.0, -20.0, 325.0]]))
    assert sorted(zip(first["U_mm_s"], first[GAP], first["roughness_um"])) == \
        [(47.5, 300.0, 300.0), (62.0, 400.0, 400.0), (90.0, 350.0, 350.0), (100.0, 325.0, 325.0)]
    second = ev(np.array([[70.0, 5.5, 400.0]]))
    assert second[["U_mm_s", "omega_rad_s", GAP]].to_numpy().tolist() == [[70.0, 5.5, 400.0]]
    round1 = yaml.safe_load((tmp_path / "out" / "round_1.yaml").read_text())
    assert "points_mm_s_rad_s" not in round1["sweep"] and len(round1["sweep"]["points"]) == 5
    config = ev.resolved(round1)
    expected = [run.name for run in runs_by_name(config).values()
                if run.point == {"U_mm_s": 70.0, "omega_rad_s": 5.5, GAP: 400.0}]
    assert [c for c in calls[1] if c.endswith("metrics.json")] == \
        [f"results/smoke/runs/{name}/metrics.json" for name in expected]
    assert expected == [f"{GAP}=400/{run_name(70.0, 5.5, 0)}"]         # today's naming (docs/sweep.md)


def test_a_three_input_design_is_saved_for_recommend_over_every_axis(tmp_path):
    from analysis.surrogate.adaptive import write_result
    from analysis.surrogate.persistence import load_surrogate
    from analysis.surrogate.recommend import recommend
    result = run_adaptive(synthetic3, BOUNDS3, {**SETTINGS3, "max_runs": 20}, axes=[GAP], log=lambda line: None)
    params = load_config(ROOT / "config.yaml")["surrogate"]
    write_result(result, tmp_path, "smoke", surrogate_params={**params, "cv_repeats": 1})
    model, meta = load_surrogate(tmp_path / "model.joblib")
    assert meta["inputs"] == {"U_mm_s": "mm/s", "omega_rad_s": "rad/s", GAP: "um"}
    assert meta["input_range"][GAP] == [300.0, 400.0]
    assert recommend(model, meta, 1e9, n=11, fixed={GAP: 350.0})[GAP] == 350.0
    assert list(pd.read_csv(tmp_path / "design.csv").columns[:3]) == ["U_mm_s", "omega_rad_s", GAP]
