"""benchmarks/bench_fidelity.py: the convergence judgement on hand-made runs, and a smoke run of
the benchmark itself through real LIGGGHTS (the study: benchmarks/measured/stiffness.md), whose kept
layer is bench_region.py's smoke run."""
import json

import numpy as np
import pandas as pd
import pytest

from analysis.config.load import load_config
from analysis.metrics.dump import read_dump
from benchmarks import (
    bench_fidelity,
    bench_region,
    bench_stress,
    compare_maps,
    layer_formation,
    reference_front,
    travel_time,
)
from benchmarks.bench_fidelity import METRICS, convergence


def runs_of(variant, means, sds, points=((70, -15), (70, 0))):
    """Three seeds per point whose sample mean and sd are ``means``/``sds`` (per metric)."""
    rows = []
    for U, omega in points:
        for z in (-1.0, 0.0, 1.0):  # sample sd of (-1, 0, 1) is 1
            rows.append({"variant": variant, "seed": int(z + 1), "U_mm_s": U, "omega_rad_s": omega,
                         **{k: means[k] + z * sds[k] for k in METRICS}})
    return rows


def test_a_step_is_judged_in_the_finer_scenes_sd_not_the_coarser_ones():
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    tight = {k: 0.02 * v for k, v in base.items()}          # the finer scene: 2 % seed sd
    noisy = {k: 0.20 * v for k, v in base.items()}          # the coarse one: 20 %
    shifted = {**base, "roughness_um": 80.0 * 1.05}          # R_q 5 % off: 2.5 finer sds, 0.25 coarse
    runs = pd.DataFrame(runs_of("soft", shifted, noisy) + runs_of("stiff", base, tight))
    (step,) = convergence(runs, ["soft", "stiff"]).to_dict("records")
    assert step["step"] == "soft -> stiff" and step["points"] == 2 and step["finer seeds"] == 3
    assert step["R_q shift (finer sds)"] == pytest.approx(2.5)
    assert step["R_q change (%)"] == pytest.approx(5.0)
    assert step["M_s shift (finer sds)"] == pytest.approx(0.0, abs=1e-9)
    assert not step["converged"]
    # how much of the shift the seed noise of two 3-packing means could make: 4 um over sqrt(16^2/3 + 1.6^2/3)
    assert step["largest Welch t"] == pytest.approx(4.0 / np.sqrt(16.0**2 / 3 + 1.6**2 / 3))
    assert step["at"] == "R_q, U 70, omega -15"
    # the same shift judged in the noisy scene's sd would pass: the order matters
    (back,) = convergence(runs, ["stiff", "soft"]).to_dict("records")
    assert back["R_q shift (finer sds)"] == pytest.approx(4.0 / 16.0) and back["converged"]


def test_mass_is_compared_per_unit_sampling_area_and_failed_runs_are_left_out():
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.05 * v for k, v in base.items()}
    wide = pd.DataFrame(runs_of("wide", {**base, "mass_g": 2.0}, {**sds, "mass_g": 0.1})).assign(
        sampling_area_mm2=10.0)
    narrow = pd.DataFrame(runs_of("narrow", base, sds)).assign(sampling_area_mm2=5.0)
    broken = pd.DataFrame([{"variant": "narrow", "U_mm_s": 70, "omega_rad_s": -15, "error": "ERROR: lost atoms"}])
    (step,) = convergence(pd.concat([narrow, broken, wide]), ["narrow", "wide"]).to_dict("records")
    assert step["M_s shift (finer sds)"] == pytest.approx(0.0, abs=1e-9) and step["converged"]


def test_a_variant_run_at_fewer_points_is_judged_at_those_points_only():
    """A knob run at omega -15 only, 10 % off there, against a reference that also ran omega 0 with
    ten times less mass: 10 %, not 10 % of the mass at -15 over the mean of both points (18 %)."""
    big = {"mass_g": 10.0, "throughput_mm2_s": 50.0, "roughness_um": 160.0, "porosity_pct": 30.0}
    small = {"mass_g": 1.0, "throughput_mm2_s": 12.0, "roughness_um": 85.0, "porosity_pct": 65.0}
    sds = dict.fromkeys(METRICS, 0.01)
    reference = (runs_of("ref", big, sds, points=((70, -15),))
                 + runs_of("ref", small, sds, points=((70, 0),)))
    knob = runs_of("knob", {**big, "mass_g": 11.0}, sds, points=((70, -15),))
    runs = pd.DataFrame(reference + knob).assign(cpu_s=100.0, wall_s=110.0, steps=1000, particles=500)
    table = bench_fidelity.summarise(runs, "ref").set_index("variant")
    assert table.loc["knob", "points"] == 1 and table.loc["ref", "points"] == 2
    assert table.loc["knob", "err_M_s"] == pytest.approx(0.10)
    assert table.loc["knob", "err_Q_s"] == pytest.approx(0.0, abs=1e-12)


def test_the_benchmark_runs_a_smoke_scene_through_liggghts_and_the_region_benchmark_remeasures_its_layer(tmp_path):
    """One smoke spread, the ladder's table, and the kept layer re-measured by bench_region.py over a
    longer region: both benchmarks' own paths, on one LIGGGHTS run."""
    kept = tmp_path / "kept"
    assert bench_fidelity.main(["--level", "smoke", "--points", "100:0", "--seeds", "1", "--jobs", "1",
                                "--variants", "default", "--reference", "default", "--name", "smoke",
                                "--out", str(tmp_path), "--keep", str(kept), "--movie-every-mm", "2"]) == 0
    runs = pd.read_csv(tmp_path / "smoke.csv")
    assert len(runs) == 1 and ("error" not in runs or runs["error"].isna().all())
    row = runs.iloc[0]
    assert row["cpu_s"] > 0 and row["steps"] > 1000 and not row["heap_exhausted"]
    assert 0 < row["mass_g"] and 0 < row["roughness_um"] < 300
    assert np.isfinite(row["inrun_max_overlap_fraction"]) and row["squeeze_outs_max"] >= 0
    table = (tmp_path / "smoke.md").read_text()
    assert "| default " in table and "0.0%" in table  # the reference against itself

    run = kept / "default_s0_U100_w0"
    assert (run / "final.dump").exists() and (run / "health.json").exists()
    assert "spreadmap feed_pile_kg_" in (run / "spread.log").read_text()  # the feed's weighings, kept
    frames = (run / "movie.dump").read_text().count("ITEM: TIMESTEP")  # a frame every 2 mm of the travel
    travel_mm = (row["steps"] * row["timestep_s"]) * 100.0  # at most: the steps include the rest phase
    assert 2 <= frames <= travel_mm / 2 + 2
    landed = pd.read_csv(run / "feed_landings.csv")  # where each fed particle landed: every one
    assert 0 < len(landed) == json.loads((run / "health.json").read_text())["fed_particles"]
    assert bench_region.main(["--replicates", str(kept), "--level", "smoke", "--regions", "3.5-6.5", "--jobs", "1",
                              "--name", "region", "--out", str(tmp_path)]) == 0
    measured = pd.read_csv(tmp_path / "region.csv").set_index("region_mm")
    assert sorted(measured.index) == ["3.5-6.5", "4.5-6.5"]
    assert measured.loc["3.5-6.5", "length_mm"] == pytest.approx(3.0)
    for k in METRICS:  # over the level's own region: the fidelity benchmark's numbers exactly
        assert measured.loc["4.5-6.5", k] == pytest.approx(row[k], rel=1e-9)
    assert 0 < measured.loc["3.5-6.5", "mass_g"] < 1.4 * row["mass_g"]  # per the level's area, not 1.5x its mass
    assert "| 3.5-6.5 " in (tmp_path / "region.md").read_text()
    assert (measured["fed_pct"].between(0, 100)).all()

    # the kept movie: how far behind the roller the layer is laid, bin by bin
    assert layer_formation.main(["--runs", str(kept), "--level", "smoke", "--name", "formation", "--past-mm", "0,2",
                                 "--stop-rules", "1e9:1,1e-9:1", "--rules-from-mm", "0", "--out", str(tmp_path)]) == 0
    bins = pd.read_csv(tmp_path / "formation.csv")
    rest = read_dump(run / "final.dump").atoms
    inside = rest["x"].between(bins["bin_start_mm"].min() * 1e-3, bins["bin_end_mm"].max() * 1e-3, inclusive="left")
    density = load_config(bench_fidelity.ROOT / "config.yaml")["material"]["density_kg_m3"]
    width_mm = read_dump(run / "final.dump").box[1, 1] * 1e3
    assert (bins["layer_mg_per_mm2"] * width_mm).sum() == pytest.approx(  # every particle at rest counted once
        (density * 4 / 3 * np.pi * rest.loc[inside, "radius"] ** 3).sum() * 1e6)
    region = bins[bins["bin_start_mm"].between(4.0, 6.0)]  # the smoke level's 4.5-6.5 mm, a frame every 2 mm
    assert region["complete_before_stop"].all() and (region["x_roller_complete_mm"] < region["stop_mm"]).all()
    assert (region["formation_length_mm"] > -2.0 - 1.0).all()  # not laid before the axis arrives (frame, bin)
    unlaid = bins[~bins["complete_before_stop"] & (bins["layer_mg_per_mm2"] > 0)]  # a lower bound: to the stop
    assert np.allclose(unlaid["formation_length_mm"], unlaid["stop_mm"] - unlaid["bin_end_mm"])
    past = pd.read_csv(tmp_path / "formation_past.csv")  # the region at rest: the benchmark's own numbers
    at_rest = past[past["past_mm"].isna()].iloc[0]
    for k in METRICS:
        assert at_rest[k] == pytest.approx(row[k], rel=1e-9)
    assert past["past_mm"].dropna().tolist() == [0.0, 2.0]  # the smoke roller stops 3 mm past the region
    assert "| default " in (tmp_path / "formation.md").read_text().split("travels on")[1]
    rules = pd.read_csv(tmp_path / "formation_rules.csv").set_index("rule_mm_s")
    # any speed is below 1e9 mm/s: the first frame past the region's end (the movie's frames are 2 mm apart);
    # none is below 1e-9 mm/s: the rule is never met, the roller stops where the run stopped, at rest
    assert rules.loc[1e9, "laid_before_end"] and 0 <= rules.loc[1e9, "stop_past_mm"] < 2.0
    assert not rules.loc[1e-9, "laid_before_end"] and rules.loc[1e-9, "stop_past_mm"] == pytest.approx(3.0, abs=1e-3)
    assert (rules.loc[1e-9, [f"{m}_change_pct" for m in METRICS.values()]] == 0).all()
    table = (tmp_path / "formation.md").read_text().split("Stop rules")[1]
    assert sum(line.startswith("|") for line in table.splitlines()) == 2 + 2  # header, rule, one row per rule

    # where along the travel the kept run's time went: every thermo interval in one phase, the run-in first
    assert travel_time.main(["--runs", str(kept), "--level", "smoke", "--name", "travel", "--out", str(tmp_path)]) == 0
    phases = pd.read_csv(tmp_path / "travel.csv").set_index("phase")
    assert list(phases.index) == list(travel_time.PHASES) and (phases["time_s"] >= 0).all()
    assert phases.loc["region", "travel_mm"] == pytest.approx(2.0, abs=0.2)  # the smoke region, 4.5-6.5 mm
    assert phases.loc["run_in", "time_s"] > 0 and phases["time_s"].sum() <= row["wall_s"]


def test_the_stop_rule_sees_the_regions_mean_kinetic_energy_and_needs_its_checks_in_a_row():
    rho, r = 4000.0, 50e-6
    m = rho * 4 / 3 * np.pi * r**3
    atoms = pd.DataFrame({"x": [1e-3, 2e-3, 9e-3], "radius": [r, 2 * r, r], "vx": [3e-3, 0.0, 5.0],
                          "vy": [0.0, 1e-3, 0.0], "vz": [4e-3, 0.0, 0.0]})
    # in the region 0-5 mm: (m 25e-6 + 8 m 1e-6) / 2 = 16.5 m [m^2/s^2] per particle; the fast one is outside
    assert layer_formation.region_speed(atoms, (0.0, 5e-3), rho, m) == pytest.approx(np.sqrt(16.5e-6))
    assert layer_formation.region_speed(atoms.iloc[2:], (0.0, 5e-3), rho, m) == 0.0  # no particle: at rest
    speeds = np.array([5.0, 0.5, 2.0, 0.5, 0.4, 0.1])
    assert layer_formation.rule_stop(speeds, 1.0, 2) == 4 and layer_formation.rule_stop(speeds, 1.0, 1) == 1
    assert layer_formation.rule_stop(speeds, 1.0, 4) is None and layer_formation.rule_stop(speeds, 10.0, 3) == 2


def test_a_bin_is_complete_from_the_first_frame_after_which_it_stays_complete():
    """Frames x bins: a bin that leaves 95-105 % of its mass at rest after first reaching it (a pile
    passing over it, or a dip) is complete only once it stays there."""
    masses = np.array([[0.0, 3.0, 1.0], [0.96, 1.0, 1.0], [0.9, 0.97, 1.0], [1.0, 1.04, 1.0]])
    at_rest = np.ones(3)
    assert layer_formation.completion_frame(masses, at_rest).tolist() == [3, 1, 0]
    assert layer_formation.completion_frame(masses[:, :1] * 0.5, at_rest[:1]).tolist() == [4]  # never: all frames


def test_two_ladders_from_one_base_are_each_judged_in_their_own_finer_scenes_sd(tmp_path):
    """``--ladder 'a,b;a,c' --summarise``: a base against two references, one table, no simulation."""
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.02 * v for k, v in base.items()}
    runs = pd.DataFrame(runs_of("default", base, sds) + runs_of("E2e7", {**base, "mass_g": 1.04}, sds)
                        + runs_of("E5e7", {**base, "mass_g": 1.01}, sds)).assign(cpu_s=1.0, wall_s=1.0, steps=10,
                                                                                   particles=5)
    runs.to_csv(tmp_path / "two.csv", index=False)
    assert bench_fidelity.main(["--variants", "default,E2e7,E5e7", "--reference", "E2e7", "--name", "two",
                                "--ladder", "default,E2e7;default,E5e7", "--summarise", "--out", str(tmp_path)]) == 0
    table = (tmp_path / "two.md").read_text()
    assert "| default -> E2e7 " in table and "| default -> E5e7 " in table
    steps = convergence(runs, ["default", "E2e7"]), convergence(runs, ["default", "E5e7"])
    assert not steps[0]["converged"].iloc[0] and steps[1]["converged"].iloc[0]  # 2 sds off, then 0.5


def test_a_summary_states_each_variants_own_packings_not_the_seeds_flag(tmp_path):
    """Tables joined from several studies hold different packings per variant: the summary says how many
    each has, whatever ``--seeds`` was given."""
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.02 * v for k, v in base.items()}
    runs = pd.DataFrame(runs_of("default", base, sds) + runs_of("E2e7", base, sds)).assign(
        cpu_s=1.0, wall_s=1.0, steps=10, particles=5)
    runs = runs[(runs["variant"] == "default") | (runs["seed"] < 2)]  # E2e7 with 2 packings, default with 3
    runs.to_csv(tmp_path / "joined.csv", index=False)
    assert bench_fidelity.main(["--variants", "default,E2e7", "--reference", "E2e7", "--name", "joined",
                                "--seeds", "5", "--summarise", "--out", str(tmp_path)]) == 0
    assert "seeds (heap packings) per variant: `default` 3, `E2e7` 2." in (tmp_path / "joined.md").read_text()


def test_a_summary_states_where_a_variants_packings_differ_between_points():
    """A variant with an extra packing at one point says so, point by point."""
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.02 * v for k, v in base.items()}
    runs = pd.DataFrame(runs_of("default", base, sds) + runs_of("E2e7", base, sds))
    extra = runs[runs["variant"] == "E2e7"].iloc[[0]].assign(seed=99)
    other = runs[runs["variant"] == "E2e7"].iloc[[0]].assign(omega_rad_s=10.0, seed=0)
    runs = pd.concat([runs, extra, other], ignore_index=True)
    assert bench_fidelity.packings_per_variant(runs) == "`default` 3, `E2e7` 1-4 (4 at 70:-15; 3 at 70:0; 1 at 70:10)"


def test_the_reference_front_judges_and_costs_each_knob_once_per_run(tmp_path):
    """``reference_front.py`` on hand-made run tables: a run repeated in two tables counts once, a
    CSV's ``default`` is renamed, each knob's shift is in its finer scene's sd and its cost relative
    to the default scene."""
    base = {"mass_g": 1.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.02 * v for k, v in base.items()}
    stiff = pd.DataFrame(runs_of("default", {**base, "mass_g": 1.06}, sds) + runs_of("E2e7", base, sds)
                         ).assign(cpu_s=lambda d: d["variant"].map({"default": 50.0, "E2e7": 100.0}))
    strip = pd.DataFrame(runs_of("E2e7", base, sds) + runs_of("E2e7+strip2.5", {**base, "mass_g": 1.01}, sds)
                         ).assign(cpu_s=lambda d: d["variant"].map({"E2e7": 100.0, "E2e7+strip2.5": 200.0}))
    stiff.to_csv(tmp_path / "a.csv", index=False)
    strip.to_csv(tmp_path / "b.csv", index=False)
    assert reference_front.main(["--runs", "a.csv,b.csv", "--measured", str(tmp_path), "--name", "front"]) == 0
    table = pd.read_csv(tmp_path / "front.csv").set_index("knob")
    assert list(table.index) == ["stiffness 5 -> 20 MPa", "strip 1.2 -> 2.5 mm (20 MPa)"]
    soft, wide = table.loc["stiffness 5 -> 20 MPa"], table.loc["strip 1.2 -> 2.5 mm (20 MPa)"]
    assert soft["M_s shift (finer sds)"] == pytest.approx(3.0) and not soft["converged"]   # 0.06 / 0.02
    assert wide["largest shift (finer sds)"] == pytest.approx(0.5) and wide["converged"]
    assert (soft["cpu_coarser_rel"], soft["cpu_finer_rel"], wide["cpu_finer_rel"]) == pytest.approx((0.5, 1, 2))
    assert (tmp_path / "front.png").stat().st_size > 0 and "| stiffness 5 -> 20 MPa" in (
        tmp_path / "front.md").read_text()
    with pytest.raises(SystemExit):
        reference_front.main(["--runs", "a.csv,none.csv", "--measured", str(tmp_path)])


def test_the_stress_benchmark_records_the_check_that_refused_a_case(tmp_path):
    """bench_stress.py's smoke run: a step past the wrapper's guard is refused before LIGGGHTS runs,
    and the table names the check; a stiffness case sets the level's own Young's modulus."""
    assert bench_stress.main(["--cases", "dt 0.6 T_R, guarded", "--jobs", "1", "--name", "s",
                              "--out", str(tmp_path)]) == 0
    row = pd.read_csv(tmp_path / "s.csv").iloc[0]
    assert row["variant"] == "dt 0.6 T_R, guarded" and "exceeds the allowed fraction" in row["outcome"]
    assert "| dt 0.6 T_R, guarded " in (tmp_path / "s.md").read_text()
    assert set(bench_stress.CASES["E 50 MPa (stiffer)"][0]) == {"LEVEL.youngs_modulus_dem_Pa"}


def test_two_maps_are_compared_per_group_of_points_in_the_seed_sd_given(tmp_path):
    """compare_maps.py on hand-made datasets: a new map 10 % higher at omega < 0 and the same
    elsewhere; the change judged in a run table's seed sd."""
    points = [(U, w) for U in (40, 70) for w in (-10, 0, 10)]
    base = {"mass_g": 2.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    old = pd.DataFrame([{"U_mm_s": U, "omega_rad_s": w, "replicate": 0, **base} for U, w in points])
    new = old.copy()
    new.loc[new["omega_rad_s"] < 0, list(METRICS)] *= 1.1
    old.to_csv(tmp_path / "old.csv", index=False)
    new.to_csv(tmp_path / "new.csv", index=False)
    sds = {k: 0.05 * v for k, v in base.items()}
    pd.DataFrame(runs_of("E2e7", base, sds)).to_csv(tmp_path / "runs.csv", index=False)
    assert compare_maps.main([str(tmp_path / "old.csv"), str(tmp_path / "new.csv"), "--labels", "5 MPa,20 MPa",
                              "--noise", str(tmp_path / "runs.csv"), "--noise-variant", "E2e7",
                              "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "maps_compared.csv").set_index(["points", "metric"])
    assert table.loc[("omega < 0", "M_s"), "change_pct"] == pytest.approx(10.0)
    assert table.loc[("omega < 0", "M_s"), "abs_change_in_sds"] == pytest.approx(2.0)   # 0.2 / 0.1
    assert table.loc[("omega > 0", "Q_s"), "change_pct"] == pytest.approx(0.0)
    assert table.loc[("all", "Phi"), "change_pct"] == pytest.approx(10.0 / 3)
    assert table.loc[("all", "R_q"), "20 MPa mean"] == pytest.approx(80.0 * (1 + 0.1 / 3))
    with pytest.raises(SystemExit):
        compare_maps.main([str(tmp_path / "old.csv"), str(tmp_path / "none.csv")])


def test_the_paired_t_of_a_maps_change_weighs_the_shared_shift_against_the_points_scatter():
    """Differences 0.1, 0.3, -0.1, 0.1: mean 0.1, sd 0.163 over 4 points, t = 0.1 / (0.163 / 2) = 1.22;
    a uniform shift has no scatter to weigh (NaN), one point neither, nor identical runs printed at another
    precision."""
    assert compare_maps.paired_t(np.array([0.1, 0.3, -0.1, 0.1])) == pytest.approx(0.1 / (np.sqrt(0.08 / 3) / 2))
    assert np.isnan(compare_maps.paired_t(np.array([0.2, 0.2]))) and np.isnan(compare_maps.paired_t(np.array([1.0])))
    assert np.isnan(compare_maps.paired_t(np.array([1e-4, -5e-4, 0.0]), scale=80.0))


def test_a_map_is_compared_with_a_run_tables_seed_means_at_the_points_it_ran(tmp_path):
    """--old-variant: the old map is one variant's seed means (two points of a bench_fidelity table);
    the new map's other points are left out, and a table without that variant is refused by name."""
    base = {"mass_g": 2.0, "throughput_mm2_s": 20.0, "roughness_um": 80.0, "porosity_pct": 40.0}
    sds = {k: 0.05 * v for k, v in base.items()}
    runs = pd.DataFrame(runs_of("E2e7", base, sds) + runs_of("other", {k: 9 * v for k, v in base.items()}, sds))
    runs.to_csv(tmp_path / "runs.csv", index=False)
    new = pd.DataFrame([{"U_mm_s": U, "omega_rad_s": w, "replicate": 0, **base} for U in (40, 70) for w in (-15, 0)])
    new.loc[new["omega_rad_s"] == 0, "roughness_um"] = 84.0
    new.to_csv(tmp_path / "new.csv", index=False)
    assert compare_maps.main([str(tmp_path / "runs.csv"), str(tmp_path / "new.csv"), "--old-variant", "E2e7",
                              "--noise", str(tmp_path / "runs.csv"), "--noise-variant", "E2e7",
                              "--out", str(tmp_path), "--name", "c"]) == 0
    table = pd.read_csv(tmp_path / "c.csv").set_index(["points", "metric"])
    assert table.loc[("all", "M_s"), "n"] == 2 and table.loc[("all", "M_s"), "change_pct"] == pytest.approx(0.0)
    assert table.loc[("omega = 0", "R_q"), "change_pct"] == pytest.approx(5.0)
    assert table.loc[("omega = 0", "R_q"), "abs_change_in_sds"] == pytest.approx(1.0)   # 4 um / 4 um
    with pytest.raises(SystemExit):
        compare_maps.main([str(tmp_path / "runs.csv"), str(tmp_path / "new.csv"), "--old-variant", "E5e6",
                           "--out", str(tmp_path)])
    # --old-means: the old map kept only as that comparison's group means ("new mean": the new map's)
    assert compare_maps.main([str(tmp_path / "c.csv"), str(tmp_path / "new.csv"), "--old-means", "new",
                              "--out", str(tmp_path), "--name", "m"]) == 0
    means = pd.read_csv(tmp_path / "m.csv").set_index(["points", "metric"])
    assert means.loc[("omega = 0", "R_q"), "old mean"] == pytest.approx(84.0)
    assert means.loc[("all", "R_q"), "change_pct"] == pytest.approx(100 * (82.0 - 82.0) / 82.0)
    assert means.loc[("omega < 0", "M_s"), "n"] == 2 and means.loc[("omega < 0", "M_s"), "change_pct"] == 0
    with pytest.raises(SystemExit):
        compare_maps.main([str(tmp_path / "c.csv"), str(tmp_path / "new.csv"), "--old-means", "5 MPa",
                           "--out", str(tmp_path)])


def fields_that_differ(a, b) -> set[str]:
    """The names of the fields in which two scenes (dataclasses of one type) differ."""
    from dataclasses import fields

    return {f.name for f in fields(a) if getattr(a, f.name) != getattr(b, f.name)}


def variant_scenes(*names):
    """The default level's scene under each of bench_fidelity's variants ``names``."""
    from analysis.config.fidelity import scene
    from analysis.config.load import load_config

    config = load_config(bench_fidelity.ROOT / "config.yaml")
    return tuple(scene(bench_fidelity.variant_config(config, "default", bench_fidelity.VARIANTS[name]), "default")
                 for name in names)


def test_every_variant_is_a_valid_scene_and_the_fixed_stop_freeze_sets_what_it_says():
    """Each of bench_fidelity's variants passes the config's checks; `freeze8+runout12` is `runout12` with
    the 8 mm freeze and nothing else."""
    names = list(bench_fidelity.VARIANTS)
    scenes = dict(zip(names, variant_scenes(*names)))
    fixed, both = scenes["runout12"], scenes["freeze8+runout12"]
    assert fixed.travel_end == fixed.travel_end_max == pytest.approx(fixed.sampling_region[1] + 12e-3)
    assert both.freeze_lag == pytest.approx(8e-3) and fixed.freeze_lag is None
    assert (both.travel_end, both.travel_end_max, both.box) == (fixed.travel_end, fixed.travel_end_max, fixed.box)


def test_the_reference_level_is_the_scene_the_benchmarks_judge_the_default_against():
    """config.yaml's `reference` level and bench_fidelity's reference variant (the default level with
    100 MPa, a 2.5 mm strip and a 40 mg/mm pile) are one scene: every physical field alike."""
    from analysis.config.fidelity import scene
    from analysis.config.load import load_config

    config = load_config(bench_fidelity.ROOT / "config.yaml")
    level = scene(config, "reference")
    variant = scene(bench_fidelity.variant_config(config, "default", bench_fidelity.VARIANTS["E1e8+strip2.5+pile40"]),
                    "default")
    cluster_only = {"level", "runtime_min", "mem_mb_per_rank"}
    assert fields_that_differ(level, variant) == cluster_only
    assert level.youngs_modulus == pytest.approx(1.0e8) and level.strip_width == pytest.approx(2.5e-3)
    assert bench_fidelity.pile(40, 2.5)["LEVEL.heap_particles"] == level.heap_particles == 7580


def test_a_pile_is_dosed_at_its_mass_per_width():
    """pile(): the default level's 1,820 particles for 20 mg/mm over 1.2 mm, in proportion."""
    assert bench_fidelity.pile(20) == {"LEVEL.feed_pile_mg_per_mm": 20, "LEVEL.heap_particles": 1820}
    assert bench_fidelity.pile(50)["LEVEL.heap_particles"] == 4550
    assert bench_fidelity.pile(15, 1.0)["LEVEL.heap_particles"] == 1140


def test_the_wider_reference_is_the_reference_one_step_wider_at_the_same_pile_per_width():
    """E1e8+strip5+pile40 changes the reference's strip (2.5 -> 5 mm) and its heap in proportion, nothing else."""
    reference, wider = variant_scenes("E1e8+strip2.5+pile40", "E1e8+strip5+pile40")
    # the heap's, region's, box's and pile's extents and masses follow the strip; nothing physical else moves
    assert fields_that_differ(reference, wider) == {"strip_width", "heap_particles", "heap", "sampling_region",
                                                    "box", "substrate_x", "feed_pile_mass"}
    assert wider.strip_width == pytest.approx(5e-3) and wider.heap_particles == 15170
    assert wider.feed_pile_mass == pytest.approx(2 * reference.feed_pile_mass)  # 40 mg/mm over twice the width
    assert wider.sampling_region[3] == pytest.approx(5e-3)


def test_the_shifted_heap_is_the_reference_with_a_longer_run_in_and_nothing_else():
    """E1e8+strip2.5+pile40+heap-8 doses the reference's heap 4 mm further back: the box and its bed grow
    behind it, the region and the roller's stop stay where they are, nothing physical moves."""
    reference, shifted = variant_scenes("E1e8+strip2.5+pile40", "E1e8+strip2.5+pile40+heap-8")
    assert fields_that_differ(reference, shifted) == {"heap", "box", "substrate_x"}  # the bed spans the box
    assert shifted.heap[0] == pytest.approx(reference.heap[0] - 4e-3)
    assert shifted.box[0] == pytest.approx(reference.box[0] - 4e-3) and shifted.box[1:] == reference.box[1:]
    assert shifted.sampling_region == reference.sampling_region and shifted.travel_end == reference.travel_end


def test_the_wider_shifted_heap_is_the_wider_reference_with_the_same_longer_run_in():
    """E1e8+strip5+pile40+heap-8 is E1e8+strip5+pile40 with the heap 4 mm further back, as heap-8 is for
    the 2.5 mm reference."""
    wider, shifted = variant_scenes("E1e8+strip5+pile40", "E1e8+strip5+pile40+heap-8")
    assert fields_that_differ(wider, shifted) == {"heap", "box", "substrate_x"}
    assert shifted.heap[0] == pytest.approx(wider.heap[0] - 4e-3)
    assert shifted.heap_particles == wider.heap_particles == 15170
    assert shifted.sampling_region == wider.sampling_region and shifted.travel_end == wider.travel_end


def test_the_substrate_swaps_put_one_replicates_powder_on_the_other_replicates_substrate():
    """substrate+1 at replicate 0 builds replicate 1's substrate, substrate-1 at replicate 1 replicate 0's;
    the scene (heap, feed, region) is the default's."""
    from analysis.config.load import load_config
    from analysis.dem.simulate import substrate_seed

    config = load_config(bench_fidelity.ROOT / "config.yaml")
    swapped = {name: bench_fidelity.variant_config(config, "default", bench_fidelity.VARIANTS[name])
               for name in ("substrate+1", "substrate-1")}
    assert substrate_seed(swapped["substrate+1"], 0) == substrate_seed(config, 1)
    assert substrate_seed(swapped["substrate-1"], 1) == substrate_seed(config, 0)
    default, plus, minus = variant_scenes("default", "substrate+1", "substrate-1")
    assert fields_that_differ(default, plus) == fields_that_differ(default, minus) == {"substrate"}
