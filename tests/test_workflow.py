"""The whole workflow on the smoke level through real LIGGGHTS: config to maps
and report, then a sweep extended and interrupted, resumed without redoing
finished runs."""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import SMOKE_SEED_SD
from PIL import Image

from analysis.metrics.noise_floor import two_run_tolerance
from benchmarks.faults import campaign, compare_runs, half_written_files
from tests.test_config import ROOT

TEST_CONFIG = yaml.safe_load((ROOT / ".test/config.yaml").read_text())
OMEGAS = TEST_CONFIG["sweep"]["omega_rad_s"]
FIRST_U = TEST_CONFIG["sweep"]["U_mm_s"]
SEED_SPREAD = two_run_tolerance(SMOKE_SEED_SD)  # 4 sds of a two-run difference on the smoke scene


def snakemake_cmd(workdir, U, *extra):
    """Snakemake on the CI's config (.test/config.yaml) in ``workdir``, at speeds ``U`` (mm/s)."""
    sweep = json.dumps({"U_mm_s": U})
    return [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "-d", str(workdir),
            "--configfile", str(ROOT / "config.yaml"), str(ROOT / ".test/config.yaml"), "--cores", "2",
            "--rerun-incomplete", "--config", f"sweep={sweep}", *extra]


@pytest.fixture(scope="module")
def workflow(tmp_path_factory):
    """The smoke workflow in a folder whose path holds a space and a non-ASCII letter."""
    workdir = tmp_path_factory.mktemp("workflow") / "My Projects" / "spreadmäp"
    workdir.mkdir(parents=True)
    proc = subprocess.run(snakemake_cmd(workdir, FIRST_U), capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (workdir / "snakemake.out").write_text(proc.stdout + proc.stderr)
    return workdir


def test_the_workflow_ends_on_one_line_of_what_the_spreads_cost(workflow):
    """runs, LIGGGHTS' CPU time, particle-steps per CPU second (every particle integrated) and wall time,
    the numbers those of dataset.csv."""
    data = pd.read_csv(workflow / "results/smoke/dataset.csv")
    found = re.search(r"^spreadmap: (\d+) runs, LIGGGHTS CPU ([\d.]+) min \(\d+ s a run\), ([\d.]+) M particle-steps "
                      r"per CPU second, workflow wall time ([\d.]+) min$", (workflow / "snakemake.out").read_text(),
                      re.MULTILINE)
    assert found, "no summary line"
    runs, cpu_min, rate, wall_min = found.groups()
    assert int(runs) == len(data)
    assert float(cpu_min) == pytest.approx(data.cpu_s.sum() / 60, abs=0.06)
    assert float(rate) == pytest.approx(data.particle_steps.sum() / data.cpu_s.sum() / 1e6, abs=0.006)
    assert 0 < float(wall_min) * 60 >= data.cpu_s.max() / 2
    # counted over every particle integrated: at least every particle present from the start (the final
    # ones and those removed ahead of the stopped roller, less the fed ones) over every step of the travel
    from analysis.config.fidelity import scene
    from analysis.config.load import load_config
    dt = scene(load_config(ROOT / "config.yaml"), "smoke").timestep
    travel_steps = data.roller_travel_m / (data.U_mm_s * 1e-3) / dt
    present = data.atoms + data.removed_ahead_of_roller - data.fed_particles
    assert np.all(data.particle_steps >= present * travel_steps * (1 - 1e-3))


def test_map_record_benchmark_reads_the_finished_map(workflow, tmp_path):
    """benchmarks/map_record.py (the record of `make map`) on the smoke map: its figures are the dataset's
    and the scores' (the benchmark's cheap smoke test, so that it cannot rot unseen)."""
    from benchmarks import map_record
    out = tmp_path / "map_smoke.md"
    assert map_record.main(["--results", str(workflow / "results"), "--level", "smoke", "--out", str(out)]) == 0
    text = out.read_text()
    data = pd.read_csv(workflow / "results/smoke/dataset.csv")
    scores = json.loads((workflow / "results/smoke/surrogate/scores.json").read_text())
    assert f"; {len(data)} spreads" in text
    assert f"LIGGGHTS' CPU: {data.cpu_s.sum():.0f} s in all" in text
    assert f"smallest `supply_margin` {data.supply_margin.min():.2f}" in text
    assert f"the pile at its lightest top-up {data.feed_pile_min_fraction.min():.2f} of its set mass" in text
    assert (f"frozen and dropped from the run: {data.frozen_particles.min():.0f}-{data.frozen_particles.max():.0f} "
            f"particles a run; intruders removed (landed where dropped ones were): "
            f"{int(data.freeze_intruders_removed.sum())} in all") in text
    assert f"| M_s | {scores['test']['mass_g']['R']:.3f} |" in text
    assert f"Chosen model: **{scores['model']['name']}**" in text
    spread_jobs = int(re.search(r"^\| spread \| (\d+) \|", text, re.MULTILINE).group(1))
    assert spread_jobs >= len(data)  # the sweep's spreads (and any run outside it asked for by path)
    assert "## The paper's trends (section 3)" in text and "| agrees" in text
    kept = pd.read_csv(tmp_path / "map_smoke_dataset.csv")
    assert kept[["U_mm_s", "omega_rad_s", "roughness_um"]].equals(data[["U_mm_s", "omega_rad_s", "roughness_um"]])


def test_dataset_has_one_sane_row_per_run(workflow):
    data = pd.read_csv(workflow / "results/smoke/dataset.csv")
    assert len(data) == len(FIRST_U) * len(OMEGAS)
    assert sorted(zip(data.U_mm_s, data.omega_rad_s)) == sorted((u, w) for u in FIRST_U for w in OMEGAS)
    for col in ["mass_g", "throughput_mm2_s", "roughness_um", "thickness_um", "n_particles"]:
        assert np.all(np.isfinite(data[col])) and np.all(data[col] > 0), col
    assert np.all((data.porosity_pct > 0) & (data.porosity_pct < 100))
    assert np.all((data.coverage > 0) & (data.coverage <= 1))
    assert np.all(data.lost == 0) and np.all(data.through_substrate == 0)
    # eq. 5: Q_s = U thk_avg
    assert np.allclose(data.throughput_mm2_s, data.U_mm_s * data.thickness_um * 1e-3)
    assert np.all(data.wall_s > 0) and np.all(data.steps > 0)
    # the smoke scene's pile (760 particles of the tests' powder, fed on its slope and toe) is held at the
    # points the tests use: forward rolling at U = 85 and 100 mm/s leaves 0.93 of it (2026-12-05; a sixth
    # when the feed could only place particles behind the pile's front); LIGGGHTS' own CPU time is the cost
    assert not data.heap_exhausted.any() and np.all(data.supply_margin > 0.8)
    # the feed tops every pile up on its slope and toe: placed at most a largest diameter (0.21 mm here)
    # ahead of its front, and rolled at most one more by the next top-up
    assert np.all(data.fed_particles > 0) and np.all(data.feed_topups > 5)
    assert np.all(data.fed_max_ahead_of_front_mm < 0.42)
    assert np.all((data.fed_share_of_region_layer >= 0) & (data.fed_share_of_region_layer < 1))
    assert np.all((data.cpu_s > 0) & (data.cpu_s <= 1.05 * data.wall_s))  # one rank: CPU within the wall time
    assert (data.resumed_from_step == 0).all()                            # none was interrupted


def test_random_kills_lose_nothing(workflow, tmp_path):
    """The short fault-injection campaign (benchmarks/bench_faults.py runs 20 kills): the U = 100 mm/s
    runs killed twice at seeded random moments (SIGKILL to Snakemake and LIGGGHTS), resumed each
    time; every run is in the dataset once, runs never interrupted are bit-identical to the
    uninterrupted workflow's, resumed ones within the tolerance of two runs, and no half-written
    file is left. The killed runs are those at omega >= 0, where the smoke pile holds its fed mass: at
    omega = -10 rad/s it runs down to a fifth of it and a top-up now and then refills it at once, so a
    resume there, like a new heap, can give another layer than the seed spread's (measured 2026-12-04:
    R_q 139 against 98 um, 6.6 pooled sds; docs/reliability.md)."""
    workdir = tmp_path / "faulted"
    for stage in ("meshes", "settle"):  # the same geometry and heap: only the spreads are killed
        shutil.copytree(workflow / "results/smoke" / stage, workdir / "results/smoke" / stage)
    # U = 100 mm/s at the CI's omegas >= 0 and two more (4 points: the config check wants 3 to train on)
    held = [w for w in OMEGAS if w >= 0]
    omegas = held + [10, 15]
    cmd = [*snakemake_cmd(workdir, [100]), f"sweep={json.dumps({'U_mm_s': [100], 'omega_rad_s': omegas})}",
           'surrogate={"n_test": 1}', "--", "results/smoke/dataset.csv"]
    result = campaign(cmd, workdir, workdir / "results/smoke/runs", n_kills=2, min_delay_s=8, max_delay_s=40,
                      seed=1, log=lambda line: None)
    assert result["final"]["returncode"] == 0, result["final"]["log_tail"]
    assert result["kills"] >= 1
    data = pd.read_csv(workdir / "results/smoke/dataset.csv")
    names = [f"U100_w{w:g}_r0" for w in held]
    assert sorted(data.omega_rad_s) == sorted(omegas) and set(data.U_mm_s) == {100}
    runs = compare_runs(workdir / "results/smoke/runs", workflow / "results/smoke/runs", names, SEED_SPREAD)
    for name, row in runs.items():
        if name not in result["interrupted"] or row["resumed_from_step"] == 0:
            assert row["identical"], (name, row)
        else:
            assert row["within_tolerance"], (name, row)
    assert half_written_files(workdir / "results") == []


def test_deposit_profile_shows_the_layer_along_the_travel(workflow):
    out = workflow / "results/smoke"
    profiles = pd.read_csv(out / "deposit_profile.csv")
    assert sorted(set(zip(profiles.U_mm_s, profiles.omega_rad_s))) == [(100, -10), (100, 0), (100, 5)]  # middle U
    in_region = profiles[(profiles.x_mm > 4.5) & (profiles.x_mm < 6.5)]
    # mass per area in the region: the dataset's M_s over the region's 2 x 1 mm
    data = pd.read_csv(out / "dataset.csv").set_index(["U_mm_s", "omega_rad_s"])
    for (U, w), group in in_region.groupby(["U_mm_s", "omega_rad_s"]):
        expected = data.loc[(U, w), "mass_g"] * 1e3 / 2.0  # mg/mm^2
        assert group.areal_mass_mg_mm2.mean() == pytest.approx(expected, rel=0.15)
    assert (out / "deposit_profile.png").stat().st_size > 20_000


def test_surrogate_scores_maps_and_grid_are_made(workflow):
    out = workflow / "results/smoke"
    scores = json.loads((out / "surrogate/scores.json").read_text())
    for part in ("train", "test", "cv"):
        assert set(scores[part]) == {"mass_g", "throughput_mm2_s", "roughness_um", "porosity_pct"}
    assert scores["split"]["n_test"] == 2 and scores["split"]["n_train"] == 4
    for part in ("train", "test", "cv"):
        # Pearson R (two test points: exactly +-1 up to rounding)
        assert all(abs(s["R"]) <= 1 + 1e-9 for s in scores[part].values() if s["R"] is not None), part
    grid = pd.read_csv(out / "surrogate/grid.csv")
    assert {"U_mm_s", "omega_rad_s", "throughput_index", "defect_index"} <= set(grid.columns)
    if np.isinf(grid.select_dtypes("number").to_numpy()).any():   # too few runs to calibrate: said so
        log = (workflow / "results/logs/smoke/surrogate.log").read_text()
        assert "interval columns of the grid are infinite" in log
    # the grid spans the swept speeds; the indices are products of two ratios to the grid's maxima
    assert (grid.U_mm_s.min(), grid.U_mm_s.max()) == (min(FIRST_U), max(FIRST_U))
    assert (grid.omega_rad_s.min(), grid.omega_rad_s.max()) == (min(OMEGAS), max(OMEGAS))
    for index in ("throughput_index", "defect_index"):
        assert grid[index].between(0, 1 + 1e-9).all() and grid[index].max() > 0.1, index
    # the predicted metrics stay within a factor of the simulated ones
    data = pd.read_csv(out / "dataset.csv")
    for m in ("mass_g", "throughput_mm2_s", "roughness_um", "porosity_pct"):
        assert data[m].min() / 3 < grid[m].median() < 3 * data[m].max(), m
    for name in ["process_map", "mass_g_surface", "porosity_pct_parity"]:
        with Image.open(out / "maps" / f"{name}.png") as png:
            assert png.size[0] >= 600 and png.size[1] >= 400, (name, png.size)
            assert len(png.convert("L").getcolors(1 << 16) or []) > 50, name   # a drawing, not a blank
        assert "<svg" in (out / "maps" / f"{name}.svg").read_text()[:2000]
    # Figure 4's top views: fastest U, the swept omegas nearest -5, 0 and +5 rad/s
    assert {p.stem for p in out.glob("top_views/*.png")} == {"U100_w-10_r0", "U100_w0_r0", "U100_w5_r0"}
    assert len(list(out.glob("runs/*/final.vtp"))) == len(FIRST_U) * len(OMEGAS)
    assert len(list((workflow / "results/benchmarks/smoke/spread").glob("*.tsv"))) == 6


def test_report_gathers_figures(workflow):
    proc = subprocess.run(snakemake_cmd(workflow, FIRST_U, "--report", "results/smoke/report.html"),
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (workflow / "results/smoke/report.html").stat().st_size > 100_000


def test_extended_sweep_interrupted_then_resumed_runs_only_what_is_missing(workflow):
    """A third speed added to the sweep (130 mm/s: the cheapest spreads), Snakemake and LIGGGHTS
    killed once its first run is recorded, then resumed up to the dataset (the maps are the
    fixture's and the gap test's business): only the missing spreads run, finished runs are untouched."""
    runs = workflow / "results/smoke/runs"
    finished = {p.parent.name: p.stat().st_mtime_ns for p in runs.glob("*/health.json")}
    U = [130] + FIRST_U
    dataset = ["--", "results/smoke/dataset.csv"]
    killed = subprocess.Popen([*snakemake_cmd(workflow, U), *dataset], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 600
    # a spread counts as finished once its metrics job has run: Snakemake starts
    # that only after recording the spread complete (a run killed between its
    # last write and that record is incomplete, and is rightly redone)
    while time.time() < deadline and not list(runs.glob("U130_*/metrics.json")):
        time.sleep(0.5)
    os.killpg(killed.pid, signal.SIGKILL)      # a crash: no clean-up at all
    killed.wait()
    recorded = {p.parent.name for p in runs.glob("U130_*/metrics.json")}
    written = {p.parent.name for p in runs.glob("U130_*/health.json")}
    assert 1 <= len(recorded) < 3
    # an interrupted run left no result that looks finished
    for run in runs.glob("U130_*"):
        assert (run / "final.dump").exists() == (run / "health.json").exists()
    finished.update({name: (runs / name / "health.json").stat().st_mtime_ns for name in recorded})

    subprocess.run([*snakemake_cmd(workflow, U), "--unlock"], capture_output=True, check=True)
    proc = subprocess.run([*snakemake_cmd(workflow, U), *dataset], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    spread_jobs = proc.stderr.count("rule spread:") + proc.stdout.count("rule spread:")
    assert 3 - len(written) <= spread_jobs <= 3 - len(recorded)
    after = {p.parent.name: p.stat().st_mtime_ns for p in runs.glob("*/health.json")}
    assert all(after[name] == mtime for name, mtime in finished.items())   # finished runs untouched
    assert len(pd.read_csv(workflow / "results/smoke/dataset.csv")) == 9


def test_spread_on_two_mpi_ranks_through_the_workflow_matches_one_rank(workflow):
    """Re-run one smoke spread through Snakemake with `mpi_ranks: 2` (mpirun -np 2,
    the strip cut across its width) from the same settled heap: the layer's
    metrics agree with the single-rank run's within the smoke scene's
    seed-to-seed spread (benchmarks/measured/noise_smoke.md)."""
    run = workflow / "results/smoke/runs/U100_w0_r0"
    one = json.loads((run / "metrics.json").read_text())
    cmd = [*snakemake_cmd(workflow, FIRST_U, 'fidelity={"smoke": {"mpi_ranks": 2}}'), "--forcerun", "spread",
           "--", "results/smoke/runs/U100_w0_r0/metrics.json"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "rule settle:" not in proc.stderr + proc.stdout         # the same settled heap
    health = json.loads((run / "health.json").read_text())
    assert health["ranks"] == 2 and health["processors"] == "1 2 1" and health["lost"] == 0
    assert "1 by 2 by 1 MPI processor grid" in (run / "spread.log").read_text()
    two = json.loads((run / "metrics.json").read_text())
    for key, tolerance in SEED_SPREAD.items():
        assert abs(two[key] - one[key]) <= tolerance, (key, one[key], two[key])


def test_changed_physics_reruns_the_simulations_but_more_ranks_do_not(workflow):
    """Snakemake sees the level's physics as a rule parameter: a new restitution
    plans the settle and all six spreads again; more MPI ranks plan nothing."""
    def planned(*config):
        proc = subprocess.run([*snakemake_cmd(workflow, FIRST_U), *config, "--dry-run"], capture_output=True, text=True)
        assert proc.returncode == 0, proc.stderr[-3000:]
        counts = dict(re.findall(r"^(\w+)\s+(\d+)$", proc.stdout + proc.stderr, re.MULTILINE))
        return {rule: int(n) for rule, n in counts.items()}
    physics = planned('material={"restitution": 0.5}')
    assert physics.get("settle") == 1 and physics.get("spread") == 6
    assert "spread" not in planned('fidelity={"smoke": {"mpi_ranks": 2}}')


def test_a_gap_axis_added_to_the_study_runs_only_its_spreads_to_maps_and_a_recommendation(workflow):
    """A 2 x 2 x 2 sweep over (U, omega, gap) through real LIGGGHTS (#19): the runs at the config's
    own gap (300 um) are the study's, reused; the 350 um gap spreads its 4 runs from the same
    settled heap; the dataset, surrogate, maps over (U, gap) per omega and a recommendation with the
    gap held follow.
    Last in the module: it rewrites the study's dataset and maps."""
    finished = {p.parent.name: p.stat().st_mtime_ns for p in (workflow / "results/smoke/runs").glob("*/health.json")}
    sweep = json.dumps({"U_mm_s": FIRST_U, "omega_rad_s": [-10, 5], "roller.gap_um": [300, 350]})
    maps = json.dumps({"axes": ["U_mm_s", "roller.gap_um"]})           # maps over (U, gap), one set per omega
    cmd = [*snakemake_cmd(workflow, FIRST_U)[:-1], f"sweep={sweep}", f"maps={maps}", "--",  # what is checked here
           *(f"results/smoke/{out}" for out in ("dataset.csv", "surrogate/scores.json", "maps",
                                                 "runs/roller.gap_um=350/U85_w-10_r0/parameters.yaml"))]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    log = proc.stderr + proc.stdout
    assert log.count("rule spread:") == 4 and "rule settle:" not in log and "rule geometry:" not in log
    runs = workflow / "results/smoke/runs"
    assert sorted(p.parent.name for p in runs.glob("roller.gap_um=350/*/health.json")) == \
        sorted(f"U{U}_w{w}_r0" for U in FIRST_U for w in (-10, 5))
    assert all(p.stat().st_mtime_ns == finished[p.parent.name] for p in runs.glob("*/health.json"))
    params = yaml.safe_load((runs / "roller.gap_um=350/U85_w-10_r0/parameters.yaml").read_text())
    assert params["config"]["roller"]["gap_um"] == 350 and params["heap"] == "r0"
    assert yaml.safe_load((runs / "U85_w-10_r0/parameters.yaml").read_text())["config"]["roller"]["gap_um"] == 300
    data = pd.read_csv(workflow / "results/smoke/dataset.csv")
    assert len(data) == 8 and sorted(set(data["roller.gap_um"])) == [300, 350]
    assert np.all(data.lost == 0) and not data.heap_exhausted.any()
    # the wider gap lays a thicker layer (eq. 5: more throughput), on the mean over the four (U, omega)
    wide = data.set_index(["U_mm_s", "omega_rad_s", "roller.gap_um"])["throughput_mm2_s"].unstack()
    assert wide[350].mean() > wide[300].mean(), wide
    scores = json.loads((workflow / "results/smoke/surrogate/scores.json").read_text())
    assert list(scores["inputs"]) == ["U_mm_s", "omega_rad_s", "roller.gap_um"]
    maps = workflow / "results/smoke/maps"
    for omega in (-10, 5):
        assert (maps / f"omega_rad_s={omega}/process_map.png").stat().st_size > 10_000
        assert (maps / f"omega_rad_s={omega}/roughness_um_surface.png").exists()
    found = subprocess.run([sys.executable, "-m", "analysis.surrogate.recommend", "--model",
                            str(workflow / "results/smoke/surrogate/model.joblib"), "--max-porosity", "100",
                            "--confidence", "0.5", "--fix", "roller.gap_um=350"], capture_output=True, text=True)
    assert found.returncode == 0, found.stderr + found.stdout
    assert "roller.gap_um = 350 um" in found.stdout
