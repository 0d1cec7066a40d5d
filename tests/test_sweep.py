"""Sweeps over extra axes (sweep.<config key>): validation of every value, run and heap folders,
the DAG (what a new value re-runs, by Snakemake's dry run over stand-in outputs), the
dataset's columns and the surrogate over N inputs, on synthetic data (no LIGGGHTS)."""
import copy
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from analysis.columns import input_columns, input_units
from analysis.config.errors import ConfigError
from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.config.sweep import heap_config, run_config, simulation_fingerprint, sweep_points, sweep_runs, variants
from analysis.metrics.dataset import build_dataset, point_groups, point_means
from analysis.surrogate.data import inputs_of, split_runs

ROOT = Path(__file__).resolve().parents[1]
#: config.yaml's own particle sliding friction: a swept value equal to it names no folder
OWN_FRICTION = yaml.safe_load((ROOT / "config.yaml").read_text())["material"]["sliding_friction_particle"]
THREE_AXES = {"U_mm_s": [85, 100], "omega_rad_s": [-10, 5], "replicates": 1,
              "roller.gap_um": [300, 400], "material.sliding_friction_particle": [0.3, OWN_FRICTION]}


@pytest.fixture(scope="module")
def base():
    return yaml.safe_load((ROOT / "config.yaml").read_text())


def with_sweep(base, **sweep):
    config = copy.deepcopy(base)
    config["sweep"].update(sweep)
    return config


def test_default_sweep_keeps_its_run_folders(base):
    """No extra axis: the paper's folders, U outer, one heap per replicate."""
    config = load_config(with_sweep(base, replicates=2))
    runs = sweep_runs(config)
    assert [r.name for r in runs[:3]] == ["U40_w-20_r0", "U40_w-20_r1", "U40_w-15_r0"]
    assert len(runs) == 5 * 9 * 2
    assert {r.heap for r in runs} == {"r0", "r1"}
    assert variants(config) == [{}]
    assert run_config(config, runs[0]) == config


def test_extra_axes_make_a_full_grid_with_nested_folders(base):
    config = load_config(with_sweep(base, **THREE_AXES))
    runs = sweep_runs(config)
    assert len(runs) == 2 * 2 * 2 * 2
    # a value equal to the config's own (gap 300 um, its friction) is left out of the folder names
    assert [r.name for r in runs[:4]] == ["material.sliding_friction_particle=0.3/U85_w-10_r0", "U85_w-10_r0",
                                          "roller.gap_um=400/material.sliding_friction_particle=0.3/U85_w-10_r0",
                                          "roller.gap_um=400/U85_w-10_r0"]
    assert len({r.name for r in runs}) == len(runs)
    # the gap shares its heap: one settle per friction value, not per (gap, friction)
    assert {r.heap for r in runs} == {"material.sliding_friction_particle=0.3/r0", "r0"}
    run = next(r for r in runs if r.name.startswith("roller.gap_um=400/material.sliding_friction_particle=0.3"))
    spread, heap = run_config(config, run), heap_config(config, run)
    assert spread["roller"]["gap_um"] == 400 and spread["material"]["sliding_friction_particle"] == 0.3
    assert heap["roller"]["gap_um"] == 300 and heap["material"]["sliding_friction_particle"] == 0.3
    assert scene(spread).roller_gap == pytest.approx(400e-6)
    # the fingerprints Snakemake re-runs on: the gap changes the spread's, not the heap's
    twin = next(r for r in runs if r.name.startswith("material.sliding_friction_particle=0.3"))
    level = config["level"]
    assert simulation_fingerprint(heap_config(config, twin), level) == simulation_fingerprint(heap, level)
    assert simulation_fingerprint(run_config(config, twin), level) != simulation_fingerprint(spread, level)


def test_an_axis_added_to_a_finished_study_reuses_its_runs(base):
    """The runs at the config's own value of a new axis are the (U, omega) study's, folder and
    physics fingerprint alike, so Snakemake runs only the new value's."""
    plain = load_config(with_sweep(base))
    swept = load_config(with_sweep(base, **{"roller.gap_um": [300, 350]}))
    level = base["level"]
    old = {r.name: simulation_fingerprint(run_config(plain, r), level) for r in sweep_runs(plain)}
    new = {r.name: simulation_fingerprint(run_config(swept, r), level) for r in sweep_runs(swept)}
    assert {k: new[k] for k in old} == old
    assert sorted(set(new) - set(old)) == sorted(f"roller.gap_um=350/{name}" for name in old)


def test_explicit_points_over_all_axes(base):
    points = [{"U_mm_s": 70, "omega_rad_s": -5, "roller.gap_um": 350},
              {"U_mm_s": 47.5, "omega_rad_s": 2.5, "roller.gap_um": 300},
              {"U_mm_s": 100, "omega_rad_s": 0, "roller.gap_um": 400},
              {"U_mm_s": 85, "omega_rad_s": 10, "roller.gap_um": 300}]
    config = with_sweep(base, points=points, **{"roller.gap_um": [300, 400]})
    config["surrogate"]["n_test"] = 1               # 4 points: 3 to train on
    config["surrogate"]["cv_folds"] = 4
    config = load_config(config)
    assert [r.name for r in sweep_runs(config)] == [
        "roller.gap_um=350/U70_w-5_r0", "U47.5_w2.5_r0", "roller.gap_um=400/U100_w0_r0", "U85_w10_r0"]
    assert sweep_points(config)[1] == {"U_mm_s": 47.5, "omega_rad_s": 2.5, "roller.gap_um": 300.0}
    points[0]["roller.gap_um"] = 250                # a point's value is checked as a listed one is
    with pytest.raises(ConfigError, match="'sweep.roller.gap_um' = 250"):
        load_config(with_sweep(config, points=points))


@pytest.mark.parametrize("sweep, words", [
    ({"psd.mean_diameter_um": [175, 90]}, "'sweep.psd.mean_diameter_um' = 90: in its place, config key "
                                          "'psd.mean_diameter_um' = 90: must lie between the min and max"),
    ({"material.poisson_ratio": [0.3, 0.6]}, "'sweep.material.poisson_ratio' = 0.6"),
    ({"fidelity.default.heap_particles": [300, 100.5]}, "'sweep.fidelity.default.heap_particles' = 100.5"),
    ({"roller.gap_um": [300, 80]}, "'sweep.roller.gap_um' = 80"),
    ({"surrogate.alpha": [0.1]}, "'sweep.surrogate.alpha'"),
    ({"substrate.seed": [1, 2]}, "sweep.replicates varies the seeds"),
    ({"fidelity.smoke.heap_particles": [100]}, "names fidelity level 'smoke', but level is 'default'"),
    ({"fidelity.default.mpi_ranks": [1, 2]}, "'sweep.fidelity.default.mpi_ranks'"),
    ({"material.no_such_key": [1, 2]}, "'sweep.material.no_such_key'"),
    ({"roller.gap_um": [300, "wide"]}, "sweep.roller.gap_um.1"),
    ({"roller.gap_um": [300, 300.0000001]}, "'sweep.roller.gap_um' = 300.0000001: has the folder name "
                                           "roller.gap_um=300 of 300"),
    ({"psd.min_diameter_um": [100, 150], "psd.mean_diameter_um": [120, 175]},
     "in that combination, config key 'psd.mean_diameter_um' = 120"),
    ({"roller.gap_um": [300, 400], "points_mm_s_rad_s": [[40, 0], [70, 5], [100, 0], [85, 5]]},
     "list the points over all axes in sweep.points"),
    ({"roller.gap_um": [300, 400], "points": [{"U_mm_s": 40, "omega_rad_s": 0}]}, "sweep.points[0]"),
])
def test_a_bad_swept_value_names_its_axis_and_value(base, sweep, words):
    with pytest.raises(ConfigError) as err:
        load_config(with_sweep(base, **sweep), base_dir=ROOT)
    assert words in str(err.value)
    assert "\n" not in str(err.value)


def test_a_swept_gap_that_puts_the_roller_outside_the_box_is_refused(base):
    config = with_sweep(base, **{"roller.gap_um": [300, 9000]})
    with pytest.raises(ConfigError, match="outside the simulation box"):
        load_config(config, base_dir=ROOT)


def test_a_swept_gap_whose_nip_reaches_the_frozen_layer_is_refused(base):
    """With freeze_lag_mm 8, a 2 mm gap's nip (8.4 mm) would freeze powder the roller still presses."""
    config = with_sweep(base, **{"roller.gap_um": [300, 2000]})
    config["fidelity"]["default"]["freeze_lag_mm"] = 8
    with pytest.raises(ConfigError, match="freezes powder still in the roller's nip"):
        load_config(config, base_dir=ROOT)


def test_a_stiffness_swept_where_the_level_sets_its_own_is_refused(base):
    """The smoke level sets its own Young's modulus: a swept material's would change nothing there."""
    config = with_sweep({**base, "level": "smoke"}, **{"material.youngs_modulus_dem_Pa": [2e7, 5e7]})
    with pytest.raises(ConfigError, match="fidelity.smoke.youngs_modulus_dem_Pa sets the stiffness at level smoke"):
        load_config(config, base_dir=ROOT)
    config["sweep"]["fidelity.smoke.youngs_modulus_dem_Pa"] = config["sweep"].pop("material.youngs_modulus_dem_Pa")
    load_config(config, base_dir=ROOT)


def test_a_gap_below_the_configs_own_is_refused_naming_the_fix(base):
    """The heap is settled, and the substrate's peaks capped, under roller.gap_um: a smaller
    swept gap could meet the substrate's peaks, so the config names the fix."""
    with pytest.raises(ConfigError, match=r"'sweep.roller.gap_um' = 200: .*set roller.gap_um to the smallest"):
        load_config(with_sweep(base, **{"roller.gap_um": [200, 300, 400]}))
    config = copy.deepcopy(base)
    config["roller"]["gap_um"] = 200
    config["substrate"]["peak_cap_fraction_of_gap"] = 0.8   # its peaks clipped at 160 um, 2 Sq
    config = load_config(with_sweep(config, **{"roller.gap_um": [200, 300, 400]}))
    assert {r.heap for r in sweep_runs(config)} == {"r0"}


def test_a_swept_sq_is_judged_against_the_peak_cap_at_the_configs_own_gap(base):
    """Each Sq settles its own substrate, capped at 0.6 x the config's 300 um gap (180 um):
    under 2 Sq at Sq 100 um; a swept gap does not move the cap."""
    load_config(with_sweep(base, **{"substrate.sq_um": [79, 90]}))
    with pytest.raises(ConfigError, match=r"'sweep.substrate.sq_um' = 100: .*peak_cap_fraction_of_gap"):
        load_config(with_sweep(base, **{"substrate.sq_um": [79, 100]}))
    load_config(with_sweep(base, **{"substrate.sq_um": [79, 90], "roller.gap_um": [300, 400]}))


def test_a_bad_swept_value_stops_snakemake_before_any_job(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "-d", str(tmp_path),
                           "-s", str(ROOT / "Snakefile"), "--configfile", str(ROOT / "config.yaml"),
                           "--config", 'sweep={"psd.mean_diameter_um": [175, 90]}'],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert "'sweep.psd.mean_diameter_um' = 90" in proc.stdout + proc.stderr
    assert not (tmp_path / "results").exists()


def _dry_run(workdir, config_file, *extra):
    cmd = [sys.executable, "-m", "snakemake", "-n", "-s", str(ROOT / "Snakefile"), "-d", str(workdir),
           "--rerun-triggers", "mtime", "--configfile", str(ROOT / "config.yaml"), str(config_file), *extra]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def _jobs(dry_run_text):
    """{rule: count} of a dry run."""
    return dict(re.findall(r"^(\w+)\s+(\d+)$", dry_run_text.split("Job stats:")[-1], re.M)) \
        if "Job stats:" in dry_run_text else {}


#: The workflow's rules in the order their outputs are made.
RULE_ORDER = ("geometry", "settle", "spread", "layer_metrics", "run_parameters", "top_view", "deposit_profile",
              "dataset", "trends", "noise_floor", "model_choice", "surrogate", "maps", "front_page")


def _stand_in_outputs(workdir, dry_run_text):
    """Every output and benchmark a dry run lists, as empty files, each rule's newer than
    those of the rules before it (:data:`RULE_ORDER`)."""
    t0, rule = time.time() - 1000, None
    for line in dry_run_text.splitlines():
        named = re.match(r"^(?:local)?rule (\w+):", line)
        rule = named.group(1) if named else rule
        files = re.match(r"^\s+(?:output|benchmark): (.*)$", line)
        if not files or rule not in RULE_ORDER:
            continue
        stamp = t0 + 10 * RULE_ORDER.index(rule)
        for f in files.group(1).split(", "):
            path = workdir / f
            if rule == "maps":
                path.mkdir(parents=True, exist_ok=True)
            else:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.touch()
            os.utime(path, (stamp, stamp))


def test_a_new_value_runs_only_what_it_changes(tmp_path):
    """Over stand-in outputs of a 2 x 2 x 2 x 2 sweep: a new gap adds its spreads and no settle; a new
    friction its settle (one heap) and its spreads; nothing is redone for the old values."""
    smoke = yaml.safe_load((ROOT / ".test/config.yaml").read_text())
    config_file = tmp_path / "three.yaml"
    config_file.write_text(yaml.safe_dump({**smoke, "sweep": THREE_AXES}))
    workdir = tmp_path / "work"
    first = _dry_run(workdir, config_file)
    assert _jobs(first)["settle"] == "2" and _jobs(first)["spread"] == "16"
    _stand_in_outputs(workdir, first)
    assert _jobs(_dry_run(workdir, config_file)) == {}
    gap = _jobs(_dry_run(workdir, config_file, "--config", 'sweep={"roller.gap_um": [300, 400, 350]}'))
    assert gap["spread"] == "8" and "settle" not in gap and "geometry" not in gap
    friction = _jobs(_dry_run(workdir, config_file, "--config",
                              f'sweep={{"material.sliding_friction_particle": [0.3, {OWN_FRICTION}, 0.7]}}'))
    assert (friction["geometry"], friction["settle"], friction["spread"]) == ("1", "1", "8")


def _synthetic_runs(tmp_path, with_gap=True):
    """metrics/health/benchmark files of a small (U, omega[, gap]) sweep with a known trend."""
    rng = np.random.default_rng(0)
    files = {"metrics": [], "health": [], "bench": []}
    gaps = [300.0, 400.0] if with_gap else [None]
    for i, (U, w, gap) in enumerate((U, w, g) for g in gaps for U in (40, 70, 100) for w in (-10, 0, 10)):
        thick = 0.3 * (gap or 300) + 2 * w + rng.normal(0, 1)
        row = {"U_mm_s": float(U), "omega_rad_s": float(w), **({"roller.gap_um": gap} if gap else {}),
               "replicate": 0, "mass_g": thick * 1e-5, "throughput_mm2_s": U * thick * 1e-3,
               "roughness_um": 60 + w + rng.normal(0, 1), "porosity_pct": 50 - 0.02 * (gap or 300) + w,
               "n_particles": 100, "thickness_um": thick}
        health = {"heap_exhausted": False, "lost": 0, "through_substrate": 0, "through_roller": 0,
                  "max_overlap_fraction": 0.01, "peak_speed_m_s": 0.5}
        for key, content in (("metrics", json.dumps(row)), ("health", json.dumps(health)),
                             ("bench", "s\tmax_rss\tcpu_time\n1.0\t100\t0.9\n")):
            path = tmp_path / f"{key}{i}.json"
            path.write_text(content)
            files[key].append(path)
    return files


def test_dataset_has_a_column_per_axis_and_points_span_all_axes(tmp_path):
    files = _synthetic_runs(tmp_path)
    df = build_dataset(files["metrics"], files["health"], files["bench"], tmp_path / "dataset.csv")
    assert list(df.columns[:4]) == ["U_mm_s", "omega_rad_s", "roller.gap_um", "replicate"]
    df = pd.read_csv(tmp_path / "dataset.csv")
    assert input_columns(df) == ["U_mm_s", "omega_rad_s", "roller.gap_um"]
    assert input_units(input_columns(df)) == {"U_mm_s": "mm/s", "omega_rad_s": "rad/s", "roller.gap_um": "um"}
    assert inputs_of(df).shape == (18, 3)
    assert point_groups(df).max() == 17                    # (U, omega) twins at two gaps are two points
    points, _ = point_means(df)
    assert list(points.columns[:4]) == ["U_mm_s", "omega_rad_s", "roller.gap_um", "n_replicates"]
    train, test = split_runs(df, 4, 0)
    assert len(test) == 4 and len(train) == 14


def test_the_run_table_gives_the_inputs_of_a_run_written_before_its_axis(tmp_path):
    """A plain (U, omega) run reused at the config's own gap has no gap in its metrics.json: the
    dataset takes every run's inputs from the run table (``points``)."""
    files = _synthetic_runs(tmp_path, with_gap=False)
    points = [{"U_mm_s": U, "omega_rad_s": w, "roller.gap_um": 300.0} for U in (40, 70, 100) for w in (-10, 0, 10)]
    df = build_dataset(files["metrics"], files["health"], files["bench"], tmp_path / "dataset.csv", points=points)
    assert list(df.columns[:4]) == ["U_mm_s", "omega_rad_s", "roller.gap_um", "replicate"]
    assert np.all(df["roller.gap_um"] == 300) and len(df) == 9
    with pytest.raises(ValueError):         # one point per run
        build_dataset(files["metrics"], files["health"], files["bench"], tmp_path / "x.csv", points=points[:-1])


def test_dataset_without_axes_has_the_papers_columns(tmp_path):
    files = _synthetic_runs(tmp_path, with_gap=False)
    df = build_dataset(files["metrics"], files["health"], files["bench"], tmp_path / "dataset.csv")
    assert list(df.columns[:3]) == ["U_mm_s", "omega_rad_s", "replicate"]
    assert input_columns(df) == ["U_mm_s", "omega_rad_s"]


def gap_dataset():
    """5 U x 5 omega x 3 gaps, metrics linear in each: Q_s and porosity rise with U and the gap.
    Under porosity <= 34 % the best is the smallest gap (300 um) at U = 70 mm/s, omega = -20 rad/s
    (Q_s 39 mm^2/s); with the gap held at 400 um, U = 50 mm/s (Q_s 35)."""
    U, w, gap = (a.ravel().astype(float) for a in np.meshgrid([40, 55, 70, 85, 100], [-20, -10, 0, 10, 20],
                                                                 [300, 350, 400], indexing="ij"))
    return pd.DataFrame({"U_mm_s": U, "omega_rad_s": w, "roller.gap_um": gap,
                         "mass_g": 0.01 + 1e-4 * U + 1e-5 * gap,
                         "throughput_mm2_s": 10 + 0.3 * U - 0.1 * w + 0.02 * gap,
                         "roughness_um": 40 + 0.5 * np.abs(w) + 0.01 * gap,
                         "porosity_pct": 20 + 0.2 * U + 0.04 * (gap - 300)})


@pytest.fixture(scope="module")
def gap_model(fit_params):
    """The chosen-model path on three inputs: a GP candidate and the paper's network's scores as meta."""
    from analysis.surrogate.candidates import make_candidate
    from analysis.surrogate.network import fit_surrogate
    df = gap_dataset()
    _, scores = fit_surrogate(df, {**fit_params, "n_test": 10})
    return make_candidate("gp", fit_params).fit(inputs_of(df), df[["mass_g", "throughput_mm2_s", "roughness_um",
                                                                    "porosity_pct"]].to_numpy()), scores, df


def test_surrogate_scores_name_every_input(gap_model):
    _, scores, _ = gap_model
    assert scores["inputs"] == {"U_mm_s": "mm/s", "omega_rad_s": "rad/s", "roller.gap_um": "um"}
    assert scores["input_range"]["roller.gap_um"] == [300.0, 400.0]
    assert scores["swept"]["roller.gap_um"] == [300.0, 350.0, 400.0]
    assert scores["test"]["throughput_mm2_s"]["R"] > 0.99      # a linear trend in three inputs


def test_recommend_searches_every_axis_and_holds_one(gap_model):
    from analysis.surrogate.recommend import recommend
    model, meta, _ = gap_model
    found = recommend(model, meta, max_porosity_pct=34.0, n=121, axis_points=11)
    assert found["inputs"] == ["U_mm_s", "omega_rad_s", "roller.gap_um"]
    assert found["roller.gap_um"] == pytest.approx(300, abs=1)
    assert found["U_mm_s"] == pytest.approx(70, abs=1.5)
    assert found["omega_rad_s"] == pytest.approx(-20, abs=0.5)
    assert found["n_grid"] == 121 * 121 * 11
    held = recommend(model, meta, max_porosity_pct=34.0, n=121, fixed={"roller.gap_um": 400})
    assert held["roller.gap_um"] == 400 and held["U_mm_s"] == pytest.approx(50, abs=1.5)
    assert held["throughput_mm2_s"] == pytest.approx(35, abs=0.5)
    assert held["n_grid"] == 121 * 121
    with pytest.raises(ValueError, match="roller.gap_um = 500 lies outside the swept range 300..400"):
        recommend(model, meta, max_porosity_pct=34.0, fixed={"roller.gap_um": 500})
    with pytest.raises(ValueError, match="cannot fix material.restitution"):
        recommend(model, meta, max_porosity_pct=34.0, fixed={"material.restitution": 0.5})


def test_recommend_command_line_fix(gap_model, tmp_path):
    from analysis.surrogate.persistence import save_surrogate
    model, meta, _ = gap_model
    save_surrogate(model, tmp_path / "model.joblib", meta)
    proc = subprocess.run([sys.executable, "-m", "analysis.surrogate.recommend", "--max-porosity", "34",
                           "--model", str(tmp_path / "model.joblib"), "--grid-points", "61",
                           "--fix", "roller.gap_um=400"], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "roller.gap_um = 400 um" in proc.stdout and "roller.gap_um 400 um" in proc.stdout
    bad = subprocess.run([sys.executable, "-m", "analysis.surrogate.recommend", "--max-porosity", "34",
                          "--model", str(tmp_path / "model.joblib"), "--fix", "roller.gap_um"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "give AXIS=VALUE" in bad.stderr


def test_maps_over_a_third_axis_are_drawn_per_value(gap_model, tmp_path):
    from analysis.surrogate.data import split_runs
    from analysis.viz.maps import render_maps
    model, _, df = gap_model
    paths = render_maps(model, df, split_runs(df, 10, 0), tmp_path / "maps", n=11,
                        window={"max_porosity_pct": 40, "max_roughness_um": None})
    names = {str(p.relative_to(tmp_path / "maps")) for p in paths}
    assert "mass_g_parity.png" in names                         # parity: every point, once
    for gap in (300, 350, 400):
        assert f"roller.gap_um={gap}/mass_g_surface.png" in names
        assert f"roller.gap_um={gap}/mass_g_contour.png" in names
        assert f"roller.gap_um={gap}/process_map.png" in names
        assert f"roller.gap_um={gap}/operating_window.png" in names
    assert not any(n.startswith("roller.gap_um=300/") and "parity" in n for n in names)


def test_a_map_over_any_pair_predicts_at_the_right_inputs(gap_model):
    """A (U, gap) map with omega held: each grid node is the model's prediction at the full input
    (U, omega, gap) in the model's order, and the iso-lines are the two mapped inputs'."""
    from analysis.viz.figures import MapView
    from analysis.viz.process_map import process_map_lines
    model, _, df = gap_model
    view = MapView(("U_mm_s", "roller.gap_um"), ("U_mm_s", "omega_rad_s", "roller.gap_um"), (("omega_rad_s", -10.0),))
    grid = view.grid(model, (40, 100), (300, 400), 5)
    expect = model.predict(np.c_[grid["U_mm_s"], np.full(25, -10.0), grid["roller.gap_um"]])
    assert np.allclose(grid[["mass_g", "throughput_mm2_s", "roughness_um", "porosity_pct"]], expect)
    assert grid["U_mm_s"].iloc[5] == 55 and grid["roller.gap_um"].iloc[1] == 325    # U outer, the gap inner
    assert np.allclose(grid["throughput_mm2_s"], 10 + 0.3 * grid["U_mm_s"] + 1 + 0.02 * grid["roller.gap_um"],
                       atol=0.2)
    lines = process_map_lines(model, [40, 100], [300, 400], {m: 1.0 for m in ("mass_g", "throughput_mm2_s",
                                                                               "roughness_um", "porosity_pct")},
                              n=3, view=view)
    assert set(lines["family"]) == {"U", "roller.gap_um"}
    assert np.all(lines["omega_rad_s"] == -10)


def test_maps_over_a_chosen_pair_hold_or_panel_the_other_inputs(gap_model, tmp_path):
    from analysis.metrics.dataset import point_means
    from analysis.viz.maps import map_views, render_maps
    from analysis.viz.process_map import process_map_figure
    model, _, df = gap_model
    points, _ = point_means(df)
    # (U, gap): one set per omega (5), 5 x 3 points in each
    sets = map_views(points, ("U_mm_s", "roller.gap_um"))
    assert [values for values, _ in sets] == [{"omega_rad_s": w} for w in (-20, -10, 0, 10, 20)]
    assert all(len(views) == 1 and len(views[0][1]) == 15 for _, views in sets)
    # held: one set; panels: the gap's three values side by side, 25 points each
    held = map_views(points, ("U_mm_s", "omega_rad_s"), hold={"roller.gap_um": 350})
    assert len(held) == 1 and held[0][0] == {} and len(held[0][1][0][1]) == 25
    panels = map_views(points, ("U_mm_s", "omega_rad_s"), panels="roller.gap_um")
    assert len(panels) == 1 and [v.held for v, _ in panels[0][1]] == [(("roller.gap_um", g),) for g in (300, 350, 400)]
    with pytest.raises(ValueError, match="'material.restitution' is not an input"):
        map_views(points, ("U_mm_s", "material.restitution"))
    split = split_runs(df, 10, 0)
    paths = render_maps(model, df, split, tmp_path / "maps", n=9, panels="roller.gap_um",
                        window={"max_porosity_pct": 40, "max_roughness_um": 70})
    names = {str(p.relative_to(tmp_path / "maps")) for p in paths}
    assert {"process_map.png", "mass_g_surface.png", "mass_g_parity.png", "operating_window.png"} <= names
    assert not any("/" in n for n in names)                          # one set, in maps/ itself
    views = [(v, points.iloc[rows].reset_index(drop=True), (np.arange(len(rows)), np.array([], int)))
             for v, rows in panels[0][1]]
    assert len(process_map_figure(model, None, None, n=21, panels=views).axes) == 3


@pytest.mark.parametrize("maps, words", [
    ({"axes": ["U_mm_s", "material.restitution"]}, "'maps.axes' = ['U_mm_s', 'material.restitution']: names "
                                                   "'material.restitution', not an input"),
    ({"axes": ["U_mm_s", "roller.gap_um"], "hold": {"omega_rad_s": 30}},
     "'maps.hold.omega_rad_s' = 30: lies outside the swept range -20..20"),
    ({"hold": {"U_mm_s": 70}}, "'maps.hold.U_mm_s' = 70: holds what is not an input outside maps.axes"),
    ({"panels": "omega_rad_s"}, "'maps.panels' = 'omega_rad_s': must be an input neither mapped"),
])
def test_bad_maps_settings_name_the_key(base, maps, words):
    config = with_sweep(base, **{"roller.gap_um": [300, 400]})
    config["maps"].update(maps)
    with pytest.raises(ConfigError) as err:
        load_config(config)
    assert words in str(err.value)
