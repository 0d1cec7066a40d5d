"""Real LIGGGHTS runs: the smoke scene settles and spreads, the material
reaches the engine in the right units, and failures are loud."""
import copy
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest
import yaml
from conftest import SMOKE_SEED_SD
from scipy.spatial import cKDTree

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from analysis.config.fidelity import scene
from analysis.config.sweep import resolve
from analysis.dem.health import substrate_height_at
from analysis.dem.inputs import (
    FEED_AHEAD_OF_FRONT_DIAMETERS,
    checkpoint_plan,
    feed_plan,
    processors_grid,
    travel_segments,
)
from analysis.dem.liggghts import LiggghtsError, UnstableRunError, check_seeds, input_path, read_log, run
from analysis.dem.simulate import make_geometry, settle, spread
from analysis.metrics.dump import read_dump
from benchmarks.restitution_drop import drop_sphere, first_bounce, free_fall_time
from tests.test_config import ROOT  # noqa: E402

U_MM_S, OMEGA = 100.0, -5.0


@pytest.fixture(scope="module")
def smoke(config, tmp_path_factory):
    """Geometry, a settled heap and one spreading pass at U = 100 mm/s, omega = -5 rad/s, in a
    folder whose path holds a space and a non-ASCII letter (LIGGGHTS splits input lines at spaces)."""
    root = tmp_path_factory.mktemp("smoke") / "My Projects" / "spreadmäp"
    make_geometry(config, "smoke", root / "meshes")
    settled = settle(config, "smoke", root / "meshes", root / "settle")
    result = spread(config, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", root / "run")
    return {"root": root, "settled": settled, "spread": result, "scene": scene(config, "smoke")}


def roller_state(path):
    import pyvista as pv
    mesh = pv.read(path)
    return mesh.cell_centers().points, mesh.cell_data["v"]


def test_inputs_name_files_relative_to_the_run_folder(smoke):
    """No input holds the project's absolute path, so any folder works (the fixture's has a space)."""
    assert " " in str(smoke["root"])
    for name in ("settle/settle.in", "run/spread.in"):
        text = (smoke["root"] / name).read_text()
        assert str(smoke["root"]) not in text and "../meshes/substrate.stl" in text, name


def test_a_path_liggghts_cannot_read_is_refused_by_name(tmp_path):
    (tmp_path / "a b").mkdir()
    assert input_path(tmp_path / "a b" / "x.stl", tmp_path / "a b") == "x.stl"
    with pytest.raises(LiggghtsError, match="a b/x.stl"):
        input_path(tmp_path / "a b" / "x.stl", tmp_path)


def test_heap_settles_whole(smoke):
    h, s = smoke["settled"], smoke["scene"]
    assert h["inserted"] == s.heap_particles
    # strays that rolled towards the sampling region are removed (at most 1 %), nothing else is
    assert h["atoms"] == h["inserted"] - h["strays_removed"]
    assert h["strays_removed"] <= 0.01 * s.heap_particles
    assert h["lost"] == 0 and h["through_substrate"] == 0
    assert h["max_overlap_fraction"] < 0.02


def test_roller_travels_U_t_and_turns_as_the_paper_says(smoke):
    run_dir, s = smoke["root"] / "run", smoke["scene"]
    start, end = sorted(run_dir.glob("roller_*.vtk"), key=lambda p: int(p.stem.split("_")[1]))
    steps = int(end.stem.split("_")[1])
    c0, _ = roller_state(start)
    c1, v1 = roller_state(end)
    travelled = c1[:, 0].mean() - c0[:, 0].mean()
    assert travelled == pytest.approx(U_MM_S * 1e-3 * steps * s.timestep, rel=1e-5)  # dt printed to 6 digits
    bottom = np.argmin(c1[:, 2])
    # the roller's bottom point moves at U + omega R along the travel (paper: +25 mm/s here)
    assert v1[bottom, 0] * 1e3 == pytest.approx(U_MM_S + OMEGA * s.roller_radius * 1e3, abs=0.2)
    top = np.argmax(c1[:, 2])
    assert v1[top, 0] * 1e3 == pytest.approx(U_MM_S - OMEGA * s.roller_radius * 1e3, abs=0.2)


def test_spread_lays_powder_past_the_heap_and_loses_nothing(smoke):
    s, root = smoke["scene"], smoke["root"]
    x0, x1, y0, y1 = s.sampling_region
    before = read_dump(root / "settle" / "settled.dump").atoms
    after = read_dump(root / "run" / "final.dump").atoms
    in_region = lambda a: ((a.x > x0) & (a.x < x1)).sum()  # noqa: E731
    assert in_region(before) == 0 and in_region(after) >= 20
    # the powder pushed past the stopped roller is counted, then removed (a skip), with any
    # sphere that rolled on under the stopped roller while the layer came to rest
    removed = smoke["spread"]["removed_ahead_of_roller"]
    assert smoke["spread"]["particles_ahead_of_roller"] > 0
    escaped = removed - smoke["spread"]["particles_ahead_of_roller"]
    assert 0 <= escaped <= 0.05 * smoke["spread"]["atoms"]      # a few (6 of 523 seen), not the layer
    fed = smoke["spread"]["fed_particles"]
    assert len(after) + removed == len(before) + fed and smoke["spread"]["lost"] == 0
    # removing it keeps every other particle's id (fed particles are told by theirs): each heap
    # particle left has its settled radius, and the ids run past the count
    kept = after.merge(before, on="id", suffixes=("", "_settled"))
    assert len(kept) > 100 and np.array_equal(kept.radius, kept.radius_settled)
    assert after["id"].max() > len(after) and after["id"].is_unique
    assert after.x.max() < s.travel_end + 2 * max(s.diameters)  # what sat under the roller may slump forward
    # nothing below the substrate: every centre at least half a radius above it
    b = substrate_height_at(root / "meshes" / "substrate.stl")(after.x, after.y)
    assert np.all(after.z - b > 0.5 * after.radius)
    # the spread layer is one to three particles thick
    layer = after[(after.x > x0) & (after.x < x1)]
    assert layer.z.max() < s.roller_gap + 0.1e-3


def test_feed_tops_the_pile_up_on_its_slope_and_never_past_its_reach(smoke):
    """The feed places new particles on the pile and its front slope, at most
    FEED_AHEAD_OF_FRONT_DIAMETERS largest diameters ahead of the pile's front (measured by LIGGGHTS at
    each top-up), so none lands on bare bed farther ahead: read back from the top-ups' printed fronts
    and insertion bounds in the log, and from where each fed particle (tagged by its id) was at the
    next top-up (feed_landings.csv)."""
    h, s, run_dir = smoke["spread"], smoke["scene"], smoke["root"] / "run"
    assert h["fed_particles"] > 0 and not h["heap_exhausted"]
    printed = read_log((run_dir / "spread.log").read_text())["printed"]
    steps = sorted(int(k.rsplit("_", 1)[1]) for k in printed if k.startswith("feed_front_"))
    assert len(steps) == h["feed_topups"] > 5
    # the lightest the pile was weighed at a top-up, over the mass it is held at: the feed holds the smoke
    # level's 10 mg/mm pile under forward rolling (0.95 on 2026-12-05; 0.38 when new particles had to go
    # behind the front, where the roller packs the pile and leaves no room)
    lightest = min(printed[f"feed_pile_kg_{step}"] for step in steps) / s.feed_pile_mass
    assert h["feed_pile_min_fraction"] == pytest.approx(lightest) and 0.85 < lightest < 1.05
    ahead = FEED_AHEAD_OF_FRONT_DIAMETERS * max(s.diameters)
    for step in steps:                           # every insertion zone ends within reach of its front
        assert printed[f"feed_x1_{step}"] <= printed[f"feed_front_{step}"] + ahead + 1e-12
    landed = pd.read_csv(run_dir / "feed_landings.csv")
    assert len(landed) == h["fed_particles"] and landed["id"].is_unique
    assert landed["id"].min() > read_dump(smoke["root"] / "settle" / "settled.dump").atoms["id"].max()
    # within the travel since the top-up, no fed particle rolled more than a largest diameter beyond that reach
    assert landed["ahead_of_front_m"].max() < ahead + max(s.diameters)
    assert h["fed_max_ahead_of_front_mm"] == pytest.approx(landed["ahead_of_front_m"].max() * 1e3)
    assert 0 <= h["fed_share_of_region_layer"] < 1


def test_inrun_overlaps_and_squeeze_outs_are_in_the_health(smoke):
    """The largest overlaps during the run (sampled at every thermo line) are in health.json, and
    bound the final state's: the final dump's largest particle-particle overlap, computed here from
    its positions, is at most the in-run maximum (the last thermo line is that state)."""
    h, s = smoke["spread"], smoke["scene"]
    for key in ("inrun_max_overlap_um", "inrun_max_wall_overlap_um", "squeeze_outs_max", "squeeze_out_samples"):
        assert key in h and np.isfinite(h[key]), key
    atoms = read_dump(smoke["root"] / "run" / "final.dump").atoms
    xyz, r = atoms[["x", "y", "z"]].to_numpy(), atoms["radius"].to_numpy()
    pairs = cKDTree(xyz).query_pairs(2 * r.max(), output_type="ndarray")
    overlap = (r[pairs].sum(1) - np.linalg.norm(xyz[pairs[:, 0]] - xyz[pairs[:, 1]], axis=1)).max() * 1e6
    assert 0 < overlap <= h["inrun_max_overlap_um"] + 1e-3
    assert h["inrun_max_overlap_fraction"] == pytest.approx(h["inrun_max_overlap_um"] * 1e-6 / (min(s.diameters) / 2))
    assert h["inrun_max_wall_overlap_um"] > 0                   # the bed rests on the substrate
    thermo = read_log((smoke["root"] / "run" / "spread.log").read_text())["thermo"]
    assert h["squeeze_outs_max"] == thermo["squeezed"].max()
    assert h["squeeze_out_samples"] == (thermo["squeezed"] > 0).sum()


def test_time_step_is_the_configured_fraction_of_the_rayleigh_time(smoke, config):
    h = smoke["spread"]
    assert h["rayleigh_fraction"] == pytest.approx(config["timestep"]["rayleigh_fraction"], rel=1e-3)
    assert h["rayleigh_fraction"] <= config["timestep"]["max_rayleigh_fraction"]
    assert h["hertz_fraction"] < 0.2


def test_a_spread_that_blows_up_runs_again_at_the_retry_step(smoke, config):
    """At 1.2 Rayleigh times the smoke spread blows up in LIGGGHTS (benchmarks/measured/stress.md):
    without a retry it is refused; with timestep.unstable_retry_fraction it runs once more from the
    start at that step, lays the same layer as a run made there, and says so in its health."""
    root = smoke["root"]
    steep = {"timestep.rayleigh_fraction": 1.2, "timestep.max_rayleigh_fraction": 1.2}
    args = ("smoke", U_MM_S, OMEGA, root / "meshes", root / "settle")
    with pytest.raises(UnstableRunError, match="blow-up|through the roller"):
        spread(resolve(config, {**steep, "timestep.unstable_retry_fraction": None}), *args, root / "unstable")
    retry = config["timestep"]["rayleigh_fraction"]
    h = spread(resolve(config, {**steep, "timestep.unstable_retry_fraction": retry}), *args, root / "unstable")
    assert h["unstable_retries"] == 1 and ("blow-up" in h["unstable_error"] or "roller" in h["unstable_error"])
    assert h["timestep_s"] == smoke["spread"]["timestep_s"]
    assert h["rayleigh_fraction"] == pytest.approx(retry, rel=1e-3)
    assert (h["atoms"], h["lost"]) == (smoke["spread"]["atoms"], 0)
    assert smoke["spread"]["unstable_retries"] == 0


def test_settled_bed_solid_fraction_is_that_of_poured_spheres(smoke):
    """Solid fraction inside the settled heap, by Monte Carlo points, in 0.55-0.64."""
    s = smoke["scene"]
    atoms = read_dump(smoke["root"] / "settle" / "settled.dump").atoms
    xyz, r, width = atoms[["x", "y", "z"]].to_numpy(), atoms.radius.to_numpy(), s.strip_width
    # periodic images across y, then points in the heap's core (away from its free surface and the substrate)
    images = np.concatenate([xyz + [0, dy, 0] for dy in (-width, 0, width)])
    radii = np.tile(r, 3)
    core_x = np.quantile(xyz[:, 0], [0.4, 0.6])          # the heap's thickest part
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(*core_x, 40000), rng.uniform(0, width, 40000),
                           rng.uniform(0.1e-3, 0.45e-3, 40000)])   # above the substrate's peaks, below the slope
    near = cKDTree(images).query(pts, k=12)
    inside = np.any(near[0] < radii[near[1]], axis=1)
    assert 0.55 <= inside.mean() <= 0.64


@pytest.mark.parametrize("d_um", [100, 175, 250])   # the PSD's smallest, mean and largest
def test_restitution_and_free_fall_time(config, tmp_path, d_um):
    s = scene(config, "smoke")
    d, height = d_um * 1e-6, 1e-3
    trace = drop_sphere(s, tmp_path, d, height, 0.02)
    bounce = first_bounce(trace["t"], trace["z"], trace["vz"], d / 2)
    # The configured 0.4 T_R resolves a contact in few steps and loses up to 6 % of the
    # restitution (the smallest sphere; benchmarks/measured/restitution_dt.md). A wrong
    # material or unit mapping is off by far more.
    assert bounce["restitution"] == pytest.approx(config["material"]["restitution"], rel=0.07)
    assert bounce["impact_time"] == pytest.approx(free_fall_time(height), rel=0.01)
    assert bounce["v_in"] == pytest.approx((2 * 9.81 * height) ** 0.5, rel=0.01)


def test_repeated_seed_is_refused_before_liggghts_runs(tmp_path):
    text = ("fix pts1 all particletemplate/sphere 15485863 atom_type 1\n"
            "fix ins all insert/pack seed 15485863 distributiontemplate pdd\n")
    with pytest.raises(LiggghtsError, match="used twice"):
        check_seeds(text)
    with pytest.raises(LiggghtsError, match="not a prime"):
        check_seeds("fix pts1 all particletemplate/sphere 12345 atom_type 1\n")


def test_liggghts_error_names_the_error_and_the_input_line(tmp_path):
    (tmp_path / "bad.in").write_text("units si\natom_style granular\nregion r block 0 1 0 1 0 1\n"
                                     "create_box 1 r\nfix broken all no_such_style 1 2 3\nrun 10\n")
    with pytest.raises(LiggghtsError) as err:
        run(tmp_path / "bad.in", tmp_path / "bad.log")
    message = str(err.value)
    assert "ERROR" in message and "no_such_style" in message


def test_read_log_parses_thermo_and_insertions():
    log = ("INFO: Particle insertion ins: inserted 400 particle templates (mass 5e-06) at step 1\n"
           "    Step    Atoms         KinEng            rke          ts[1]          ts[2]            CPU \n"
           "       1      400  1.8e-16              0              0.2              0.05              0 \n"
           "WARNING: something\n"
           "    1000      400  7.2e-10              0      0.2    0.06    0.05 \n"
           "Loop time of 0.05 on 1 procs for 1000 steps with 400 atoms\n")
    parsed = read_log(log)
    assert parsed["inserted"] == 400 and parsed["atoms_final"] == 400
    assert len(parsed["thermo"]) == 2 and parsed["measured_max_hertz_fraction"] == pytest.approx(0.06)
    assert parsed["warnings"] == ["WARNING: something"]


def test_killed_spread_resumes_from_its_newest_checkpoint(smoke, config):
    """SIGKILL a spread (the scheduler's time limit) after its second checkpoint,
    and the resumed run after its third: the last call resumes there, the roller
    ends where the uninterrupted run's did, and nothing is lost."""
    root, s = smoke["root"], smoke["scene"]
    out = root / "killed"
    killed_config = root / "killed_config.yaml"  # the tests' powder, as the in-process runs: same physics
    killed_config.write_text(yaml.safe_dump(config))
    cmd = [sys.executable, "-m", "analysis.dem.simulate", "spread", "--config", str(killed_config), "--level", "smoke",
           "--U", str(U_MM_S), "--omega", str(OMEGA), "--meshes", str(root / "meshes"),
           "--settled", str(root / "settle"), "--out", str(out)]
    job = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    travel_steps = max(int(p.stem.split("_")[1]) for p in (root / "run").glob("roller_*.vtk"))
    plan = checkpoint_plan(travel_steps, s.checkpoints_per_run)
    second = out / "checkpoint" / f"travel.{plan[1][0]}.restart"
    deadline = time.time() + 300
    while time.time() < deadline and not second.exists():
        time.sleep(0.2)
    time.sleep(0.5)
    os.killpg(job.pid, signal.SIGKILL)
    job.wait()
    assert not (out / "health.json").exists() and not (out / "final.dump").exists()
    # the older checkpoint was removed once the newer was written
    assert not (out / "checkpoint" / f"travel.{plan[0][0]}.restart").exists()
    # killed again after the resumed run's own next checkpoint (a second time limit): the last
    # resume starts from a restart file that a resumed run wrote
    job = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    third = out / "checkpoint" / f"travel.{plan[2][0]}.restart"
    while time.time() < deadline + 300 and not third.exists():
        time.sleep(0.2)
    time.sleep(0.5)
    os.killpg(job.pid, signal.SIGKILL)
    job.wait()
    assert third.exists() and not (out / "health.json").exists()
    resumed = spread(config, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", out)
    assert resumed["resumed_from_step"] >= plan[2][0]
    # (chunked runs are not bit-identical: the powder ahead of the roller may differ by a particle)
    whole = lambda h: h["atoms"] + h["removed_ahead_of_roller"] - h["fed_particles"]  # noqa: E731
    assert whole(resumed) == whole(smoke["spread"]) and resumed["lost"] == 0
    # the resumed state is the uninterrupted run's: one top-up later the pile ahead of the roller has
    # the same mass (0.1-0.5 % measured; a run's chaos takes longer to grow than one top-up interval)
    pile = lambda log: {int(k.rsplit("_", 1)[1]): float(v)  # noqa: E731
                        for k, v in read_log(log.read_text())["printed"].items() if k.startswith("feed_pile_kg_")}
    after, whole_run = pile(out / "spread.log"), pile(root / "run" / "spread.log")
    first = min(after)
    assert first > resumed["resumed_from_step"] and after[first] == pytest.approx(whole_run[first], rel=0.02)
    assert not (out / "checkpoint").exists()              # cleaned up after success
    full_end = root / "run" / f"roller_{travel_steps}.vtk"
    c_full, v_full = roller_state(full_end)
    c_res, v_res = roller_state(out / full_end.name)
    assert np.abs(c_res - c_full).max() < 1e-6          # the roller was re-placed where its motion had taken it
    assert np.abs(v_res - v_full).max() < 1e-5


def test_the_roller_stops_once_the_regions_layer_is_laid(smoke, config):
    """layer_laid: from run_out_mm past the region on, the roller travels on until the region's particles
    have been at rest at ``checks`` checks in a row, run_out_max_mm at the latest. Where it stopped follows
    from the values LIGGGHTS printed at each check, and the run's health and final dump follow the roller
    there. (Same box as the fixture's, so its settled heap serves; the smoke scene's soft particles jitter
    at about 3 mm/s at rest, hence its at-rest speed.)"""
    import copy
    cfg = copy.deepcopy(config)
    level = cfg["fidelity"]["smoke"]
    level.update(run_out_mm=0.5, run_out_max_mm=level["run_out_mm"])
    cfg["layer_laid"] = {"rms_speed_mm_s": 8.0, "checks": 2, "check_every_mm": 0.5}
    s, root = scene(cfg, "smoke"), smoke["root"]
    assert s.box == smoke["scene"].box
    out = root / "laid"
    health = spread(cfg, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", out)
    printed = read_log((out / "spread.log").read_text())["printed"]
    checks = sorted((int(k.split("_")[-1]), v) for k, v in printed.items() if k.startswith("laid_check_"))
    at_rest = [ke < 0.5 * s.mean_particle_mass * s.laid_speed**2 for _, ke in checks]
    stop = int(printed["roller_stop_step"])
    # it stopped at the first check ending a run of 2 at rest, and checked nothing after
    first = next(i for i in range(1, len(checks)) if at_rest[i - 1] and at_rest[i])
    assert stop == checks[first][0] and len(checks) == first + 1
    assert not at_rest[0]  # the layer behind a forward-rolling roller still moved at the first check
    speed, step_dx = U_MM_S * 1e-3, U_MM_S * 1e-3 * s.timestep
    run_out = health["run_out_m"]
    assert run_out == pytest.approx(health["roller_start_m"] + stop * step_dx - s.sampling_region[1], rel=1e-9)
    assert s.travel_end - s.sampling_region[1] < run_out < s.travel_end_max - s.sampling_region[1]
    assert health["layer_laid_at_stop"] and health["layer_laid_checks"] == first + 1
    assert health["roller_travel_m"] == pytest.approx(stop * s.timestep * speed)
    after = read_dump(out / "final.dump").atoms
    assert after.x.max() < s.sampling_region[1] + run_out + 2 * max(s.diameters)  # removed ahead of the stop
    assert health["lost"] == 0 and health["through_roller"] == 0


def test_checkpoint_plan_spaces_checkpoints_and_skips_those_passed():
    assert checkpoint_plan(100, 0) == []
    assert checkpoint_plan(100, 3) == [(25, None), (50, 25), (75, 50)]
    assert checkpoint_plan(100, 3, resume_step=50) == [(75, 50)]
    assert checkpoint_plan(100, 3, resume_step=75) == []


def test_travel_is_cut_at_checkpoints_and_feeds_and_resumes_after_them():
    segs = travel_segments(100, [(25, None), (50, 25), (75, 50)], [10, 30, 50])
    assert [(g["start"], g["end"]) for g in segs] == [(0, 10), (10, 25), (25, 30), (30, 50), (50, 75), (75, 100)]
    assert [g["start"] for g in segs if g["feed"]] == [10, 30, 50]
    assert [g["checkpoint"] for g in segs if g["checkpoint"]] == [(25, None), (50, 25), (75, 50)]
    # resumed at the checkpoint of step 50: the feed due there is still made, nothing earlier
    segs = travel_segments(100, [(75, 50)], [10, 30, 50], resume_step=50)
    assert [(g["start"], g["end"], g["feed"]) for g in segs] == [(50, 75, True), (75, 100, False)]
    assert travel_segments(100, [], []) == [{"start": 0, "end": 100, "feed": False, "checkpoint": None,
                                             "check": False}]
    # stop checks past the fixed travel cut it too (those passed by a resumed run are not repeated)
    segs = travel_segments(100, [(25, None)], [10], checks=[60, 80])
    assert [(g["end"], g["check"]) for g in segs] == [(10, False), (25, False), (60, True), (80, True), (100, False)]
    assert [g["end"] for g in travel_segments(100, [], [], resume_step=70, checks=[60, 80]) if g["check"]] == [80]


def test_feed_starts_once_its_zone_covers_the_heap_and_repeats_every_feed_every_mm(config):
    from dataclasses import replace

    def with_interval(mm):
        level = {**config["fidelity"]["default"], "feed_every_mm": mm}
        cfg = {**config, "fidelity": {**config["fidelity"], "default": level}}
        return replace(scene(cfg, "default"), feed_pile_mass=1e-5, feed_length=8e-3)

    s = with_interval(0.5)
    speed = 0.1                                      # m/s
    every = round(0.5e-3 / (speed * s.timestep))     # steps per 0.5 mm of travel
    plan = feed_plan(s, x0=-0.01, speed=speed, travel_steps=40 * every, heap_toe=0.003)
    first = plan[0]                                   # the zone's front (axis + 8 mm) reaches the toe at 3 mm
    assert -0.01 + 8e-3 + speed * s.timestep * first == pytest.approx(0.003, abs=speed * s.timestep)
    assert np.all(np.diff(plan) == every) and plan[-1] < 40 * every
    assert feed_plan(replace(s, feed_pile_mass=None), -0.01, speed, 1000, 0.003) == []   # no feed configured
    denser = feed_plan(with_interval(0.25), x0=-0.01, speed=speed, travel_steps=40 * every, heap_toe=0.003)
    assert denser[0] == first and np.all(np.diff(denser) == round(0.25e-3 / (speed * s.timestep)))
    # the shipped default level tops up every 0.25 mm (docs/scene_size.md: the reference at omega 0 and +10)
    assert config["fidelity"]["default"]["feed_every_mm"] == 0.25


def test_processors_grid_cuts_a_strip_across_its_width(config):
    from dataclasses import replace
    s = scene(config, "default")
    assert processors_grid(s) == "1 1 1"
    assert processors_grid(replace(s, mpi_ranks=2)) == "1 2 1"      # 0.6 mm slabs, cutoff 0.28 mm
    assert processors_grid(replace(s, mpi_ranks=8)) == "* * 1"      # slabs thinner than the cutoff
    assert processors_grid(scene(config, "paper")) == "* * 1"       # a wide scene: LIGGGHTS chooses


def test_same_input_on_one_rank_gives_a_bit_identical_layer(smoke, config):
    """Determinism: the same settled heap, config and speeds on one rank give the
    same final state (every particle as dumped, 6 significant digits) and the
    same kinetic energy (8 digits) at every thermo step."""
    root = smoke["root"]
    again = spread(config, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", root / "again")
    first = read_dump(root / "run" / "final.dump").atoms.sort_values("id").to_numpy()
    second = read_dump(root / "again" / "final.dump").atoms.sort_values("id").to_numpy()
    assert np.array_equal(first, second)
    assert again["steps"] == smoke["spread"]["steps"]
    ke = [read_log((root / run / "spread.log").read_text())["thermo"]["KinEng"].to_numpy() for run in ("run", "again")]
    assert np.array_equal(*ke)


def test_skips_change_the_cost_not_the_layer(smoke, config):
    """The same spread with no skips (wait the full rest time, keep the powder
    pushed past the roller, dump a movie): the travel is the same run (the
    same powder ahead of the roller), the skipped run takes fewer steps, and
    the layer's mass in the sampling region is the same within the smoke level's
    seed-to-seed spread (benchmarks/measured/noise_smoke.md). The two runs part
    at the roller's stop (the fed pile ahead removed, or kept and slumping while
    the run waits) and the last-laid layer is still settling then: one particle
    more or less in the smoke region's ~110 moves its R_q and Phi by about a
    seed sd (measured: 92.5 against 97.9 um, 55.0 against 57.8 %), so they are
    not compared here."""
    from analysis.metrics.spread_layer import spread_layer_metrics
    root, s = smoke["root"], smoke["scene"]
    full = spread(config, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", root / "noskips", skips=())
    assert full["removed_ahead_of_roller"] == 0
    assert full["particles_ahead_of_roller"] == smoke["spread"]["particles_ahead_of_roller"]
    assert full["atoms"] == smoke["spread"]["atoms"] + smoke["spread"]["removed_ahead_of_roller"]
    assert smoke["spread"]["steps"] < full["steps"]
    assert (root / "noskips" / "movie.dump").exists() and not (root / "run" / "movie.dump").exists()
    metrics = [spread_layer_metrics(read_dump(root / run / "final.dump"), s.sampling_region, U_MM_S * 1e-3,
                                    s.density, substrate=root / "meshes" / "substrate.stl",
                                    n_lines=s.profilometer_lines, seed=0) for run in ("run", "noskips")]
    first, second = metrics
    assert first["M_s"] == pytest.approx(second["M_s"], abs=SMOKE_SEED_SD["mass_g"] * 1e-3)  # one seed sd, kg
    assert first["thk_avg"] == pytest.approx(second["thk_avg"], rel=0.05)


def test_freezing_the_laid_layer_changes_the_cost_not_the_layer(smoke, config):
    """The same spread with freeze_lag_mm: the layer laid before the region is frozen at rest once the
    roller is that far past it, dropped from the run and restored to the final dump. Fewer particles
    are integrated, nothing is lost (an intruder that fell where dropped ones were is counted), no frozen
    particle is in or within 1 mm of the region, and the region's mass is the unfrozen run's within the
    smoke level's seed sd (the runs part once a particle is frozen, as any two packings do)."""
    from analysis.config.fidelity import FREEZE_MARGIN_MM
    from analysis.metrics.spread_layer import spread_layer_metrics
    root, s = smoke["root"], smoke["scene"]
    lag = 4.5  # mm: the smallest whole-half mm past the nip (4.06 mm at the smoke level)
    with_freeze = copy.deepcopy(config)
    with_freeze["fidelity"]["smoke"]["freeze_lag_mm"] = lag
    frozen = spread(with_freeze, "smoke", U_MM_S, OMEGA, root / "meshes", root / "settle", root / "frozen")
    h, free = frozen, smoke["spread"]
    assert h["frozen_particles"] > 100 and h["lost"] == 0 and h["through_substrate"] == 0
    assert h["particle_steps"] < free["particle_steps"]
    assert h["atoms"] + h["removed_ahead_of_roller"] + h["freeze_intruders_removed"] \
        == smoke["settled"]["atoms"] + h["fed_particles"]
    assert not (root / "frozen" / "laid").exists()
    log = (root / "frozen" / "spread.log").read_text()
    cuts = [float(line.split()[2]) for line in log.splitlines() if line.startswith("spreadmap freeze_cut_")]
    assert cuts and max(cuts) <= s.sampling_region[0] - FREEZE_MARGIN_MM * 1e-3 + 1e-12
    # each segment's cut is the planned one, or behind it where powder in the roller's wake still moved
    planned = [float(line.split("(v_wake_rear<")[1].split(")")[0])
               for line in (root / "frozen" / "spread.in").read_text().splitlines()
               if line.startswith("variable freeze_cut equal")][:len(cuts)]
    behind = np.array(planned) - np.array(cuts)
    assert behind.min() > -1e-12 and (behind < 1e-12).any() and (behind > 1e-5).any()
    metrics = [spread_layer_metrics(read_dump(root / run / "final.dump"), s.sampling_region, U_MM_S * 1e-3,
                                    s.density, substrate=root / "meshes" / "substrate.stl",
                                    n_lines=s.profilometer_lines, seed=0) for run in ("run", "frozen")]
    assert metrics[0]["M_s"] == pytest.approx(metrics[1]["M_s"], abs=SMOKE_SEED_SD["mass_g"] * 1e-3)


def test_unknown_skip_is_refused(smoke, config, tmp_path):
    with pytest.raises(ValueError, match="unknown skip"):
        spread(config, "smoke", U_MM_S, OMEGA, smoke["root"] / "meshes", smoke["root"] / "settle", tmp_path,
               skips={"stop_at_rest", "no_such_skip"})


def test_the_dropped_frozen_layer_is_restored_to_the_final_dump(tmp_path):
    """A run with freeze_lag_mm writes the frozen layer it drops to laid/; restore_dropped puts it back
    into final.dump.part (ids, positions and columns as written; empty drops add nothing) and removes
    a particle that fell where dropped ones were (overlapping one dropped earlier by more than MAX_OVERLAP):
    a free one, or one frozen and dropped later itself (a U 70, omega -20 map run: 137 % of a radius)."""
    from analysis.dem.simulate import LAID_DIR, restore_dropped
    from analysis.metrics.dump import write_dump
    box = [[-0.01, 0.02], [0.0, 0.0012], [-0.001, 0.04]]
    cols = ["id", "type", "x", "y", "z", "radius", "vx", "vy", "vz"]
    row = lambda i, x, z=1e-4: [i, 1, x, 0.0006, z, 1e-4, 0.0, 0.0, 0.0]  # noqa: E731
    # 2 rests on 1 (1 um overlap: a resting contact); 4 sits half inside 9 (an intruder)
    live = [row(7, 0.008), row(2, -0.001, 2.9999e-4), row(4, 0.0001)]
    write_dump(tmp_path / "final.dump.part", pd.DataFrame(live, columns=cols), box, 900)
    (tmp_path / LAID_DIR).mkdir()
    assert restore_dropped(tmp_path) == (0, 0)                  # nothing dropped: the dump as it was
    assert len(read_dump(tmp_path / "final.dump.part").atoms) == 3
    write_dump(tmp_path / LAID_DIR / "dropped.300.dump", pd.DataFrame([row(5, -0.003)], columns=cols), box, 300)
    write_dump(tmp_path / LAID_DIR / "dropped.600.dump", pd.DataFrame([row(1, -0.001), row(9, 0.0)], columns=cols),
               box, 600)
    write_dump(tmp_path / LAID_DIR / "dropped.700.dump", pd.DataFrame(columns=cols), box, 700)
    # 11 landed half inside 5 after 5 was dropped, came to rest and was dropped at step 1000 (after 300 in
    # steps, before it by name): 11 is the intruder, not 5
    write_dump(tmp_path / LAID_DIR / "dropped.1000.dump", pd.DataFrame([row(11, -0.00295)], columns=cols), box, 1000)
    assert restore_dropped(tmp_path) == (3, 2)
    final = read_dump(tmp_path / "final.dump.part")
    assert final.timestep == 900 and list(final.atoms.columns) == cols
    assert final.atoms["id"].tolist() == [1, 2, 5, 7, 9]
    assert final.atoms.set_index("id").loc[5, "x"] == -0.003
    assert len(list((tmp_path / LAID_DIR).iterdir())) == 4      # kept for a resume until the run is published
    assert restore_dropped(tmp_path) == (0, 0) and len(read_dump(tmp_path / "final.dump.part").atoms) == 5


def test_a_resumed_run_forgets_the_layer_dropped_after_its_checkpoint(tmp_path):
    from analysis.dem.simulate import LAID_DIR, forget_drops_after
    (tmp_path / LAID_DIR).mkdir()
    for step in (300, 600, 900):
        (tmp_path / LAID_DIR / f"dropped.{step}.dump").write_text("")
    forget_drops_after(tmp_path, 600)
    assert sorted(p.name for p in (tmp_path / LAID_DIR).iterdir()) == ["dropped.300.dump", "dropped.600.dump"]
