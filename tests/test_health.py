"""Numerical stability: every failure mode of a run is caught by the run wrapper
or refused by the dataset, never passed on as a result.

The real-engine case pushes the time step past the stable range (measured in
benchmarks/measured/stress.md: 0.5 T_R passes, 0.8 T_R and above blow up)."""
import copy

import numpy as np
import pandas as pd
import pytest

from analysis.config.fidelity import scene
from analysis.dem.health import (
    BLOWUP_FLOOR_M_S,
    BLOWUP_SPEED_FACTOR,
    blowup_limit,
    check_kinetic_energy,
    squeeze_out_speed,
    through_roller,
)
from analysis.dem.inputs import THERMO_EVERY
from analysis.dem.liggghts import BlowupWatch, LiggghtsError, UnstableRunError, read_log
from analysis.dem.simulate import make_geometry, settle
from analysis.metrics.dataset import SupplyLimitedError, UnsoundRunError, check_run


def thermo(vmax, energy=None):
    steps = 1000 * np.arange(len(vmax))
    energy = np.full(len(vmax), 1e-9) if energy is None else energy
    return {"thermo": pd.DataFrame({"Step": steps, "KinEng": energy, "vmax": vmax})}


def test_kinetic_energy_check_passes_a_calm_run_and_reports_its_peak():
    assert check_kinetic_energy(thermo([0.1, 0.6, 0.2]), wall_speed=0.1) == {"peak_speed_m_s": 0.6}


def test_kinetic_energy_blow_up_is_refused_naming_speed_step_and_limit():
    wall = 0.4  # m/s: the limit is 10 x 0.4 = 4 m/s, above the 2 m/s floor
    assert BLOWUP_SPEED_FACTOR * wall > BLOWUP_FLOOR_M_S
    check_kinetic_energy(thermo([0.1, 3.9]), wall_speed=wall)
    with pytest.raises(LiggghtsError, match=r"blow-up, a particle at 4\.1 m/s at step 2000 \(limit 4 m/s"):
        check_kinetic_energy(thermo([0.1, 0.2, 4.1, 80.0]), wall_speed=wall)


def test_squeeze_out_speed_is_the_released_hertz_energy():
    # integrate the Hertz sphere-wall force 4/3 E* sqrt(r) d^1.5 up to d = r/2 for a 50 um sphere
    rho, E, nu, r = 4430.0, 5e6, 0.34, 50e-6
    e_star = E / (2 * (1 - nu**2))
    d = np.linspace(0.0, 0.5 * r, 20001)
    work = np.trapezoid(4 / 3 * e_star * np.sqrt(r) * d**1.5, d)
    v = np.sqrt(2 * work / (rho * 4 / 3 * np.pi * r**3))
    assert squeeze_out_speed(rho, E, nu, 0.5) == pytest.approx(v, rel=1e-6)
    assert v == pytest.approx(5.36, abs=0.01)
    # independent of size, and the limit at the default's stiffness lets a 2.5 m/s squeeze-out pass
    check_kinetic_energy(thermo([0.3, 2.5, 0.5]), wall_speed=0.22, squeeze_speed=v)
    with pytest.raises(LiggghtsError, match=r"a particle at 12 m/s .*squeeze-out 5\.36 m/s"):
        check_kinetic_energy(thermo([0.3, 12.0]), wall_speed=0.22, squeeze_speed=v)


def test_non_finite_kinetic_energy_is_refused():
    with pytest.raises(LiggghtsError, match="not finite at step 1000"):
        check_kinetic_energy(thermo([0.1, 0.1], energy=np.array([1e-9, np.nan])))


def test_particles_inside_the_roller_are_counted():
    R, axis = 15e-3, (0.01, 15.3e-3)
    # resting on the roller (centre R + r away), just inside its surface, deep inside
    atoms = pd.DataFrame({"x": [0.01, 0.01, 0.012], "z": [0.3e-3 - 87e-6, 0.5e-3, 10e-3]})
    assert through_roller(atoms, *axis, R) == 2


def healthy_row(**changes):
    row = {"U_mm_s": 70.0, "omega_rad_s": -5.0, "replicate": 0, "lost": 0, "through_substrate": 0,
           "through_roller": 0, "max_overlap_fraction": 0.001, "peak_speed_m_s": 0.3, "n_particles": 120,
           "heap_exhausted": False, "mass_g": 1e-3, "throughput_mm2_s": 10.0, "roughness_um": 80.0,
           "porosity_pct": 70.0}
    row.update(changes)
    return row


@pytest.mark.parametrize("change, message", [
    ({"through_roller": 3}, "through_roller = 3"),
    ({"lost": 1}, "lost = 1"),
    ({"max_overlap_fraction": 0.2}, "max_overlap_fraction = 0.200"),
    ({"peak_speed_m_s": float("nan")}, "blew up"),
    ({"roughness_um": float("nan")}, "roughness_um is not finite"),
    ({"n_particles": 0}, "empty layer"),
])
def test_dataset_refuses_an_unsound_run_naming_it(change, message):
    check_run(healthy_row())
    with pytest.raises(UnsoundRunError, match=message) as err:
        check_run(healthy_row(**change))
    assert "U=70 mm/s, omega=-5 rad/s, replicate 0" in str(err.value)


def test_a_supply_limited_run_is_refused_naming_the_key_unless_kept():
    dry = healthy_row(heap_exhausted=True, n_particles=0)
    with pytest.raises(SupplyLimitedError, match=r"raise fidelity\.smoke\.heap_particles") as err:
        check_run(dry, "smoke")
    assert "U=70 mm/s, omega=-5 rad/s, replicate 0" in str(err.value)
    assert "keep_supply_limited_runs" in str(err.value)
    check_run(dry, "smoke", keep_supply_limited=True)  # kept: an empty region measures no powder
    with pytest.raises(UnsoundRunError, match="empty layer"):  # but not with powder still ahead
        check_run(healthy_row(n_particles=0), "smoke", keep_supply_limited=True)


def test_time_step_above_the_guard_is_refused_before_liggghts_runs(config, tmp_path):
    too_big = copy.deepcopy(config)
    too_big["timestep"]["rayleigh_fraction"] = too_big["timestep"]["max_rayleigh_fraction"] + 0.1
    with pytest.raises(LiggghtsError, match="exceeds the allowed fraction of the Rayleigh time"):
        settle(too_big, "smoke", tmp_path / "meshes", tmp_path / "settle")
    assert not (tmp_path / "settle" / "settle.log").exists()


def test_a_blown_up_settle_fails_loudly_and_publishes_nothing(config, tmp_path):
    """The real engine at 1.2 x the Rayleigh time, the guard lifted: particles
    reach tens of m/s within a few thousand steps; the wrapper stops there."""
    unstable = copy.deepcopy(config)
    unstable["timestep"].update(rayleigh_fraction=1.2, max_rayleigh_fraction=100.0)
    make_geometry(unstable, "smoke", tmp_path / "meshes")
    with pytest.raises(UnstableRunError, match="kinetic-energy blow-up.*stopped there"):
        settle(unstable, "smoke", tmp_path / "meshes", tmp_path / "settle")
    published = {p.name for p in (tmp_path / "settle").iterdir()}
    assert not published & {"settled.restart", "settled.dump", "health.json"}
    # stopped during the run, within a few thermo lines of the first one past the limit
    s = scene(unstable, "smoke")
    thermo = read_log((tmp_path / "settle" / "settle.log").read_text())["thermo"]
    limit = blowup_limit(squeeze_speed=squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio))
    first = int(thermo["Step"][thermo["vmax"] > limit].iloc[0])
    planned = s.settle_time / s.timestep
    print(f"blown at step {first}, stopped at {int(thermo['Step'].iloc[-1])} of {planned:.0f}")
    assert thermo["Step"].iloc[-1] < min(first + 20 * THERMO_EVERY, 0.5 * planned)


def test_squeeze_threshold_is_three_wall_speeds_or_a_fall_from_the_feed_zone():
    from analysis.dem.health import SQUEEZE_FACTOR, squeeze_threshold
    assert squeeze_threshold(0.4, 0.0) == pytest.approx(SQUEEZE_FACTOR * 0.4)
    assert squeeze_threshold(0.04, 4e-3) == pytest.approx(np.sqrt(2 * 9.81 * 4e-3))   # 0.28 m/s > 0.12


def test_workflow_summary_counts_every_integrated_particle_step():
    """Two runs: 100 + 300 CPU s, 2e8 + 4e8 particle-steps -> 1.5 M particle-steps per CPU second."""
    from analysis.metrics.dataset import workflow_summary
    table = pd.DataFrame({"cpu_s": [100.0, 300.0], "particle_steps": [2e8, 4e8]})
    line = workflow_summary(table, wall_s=600.0)
    assert line == ("spreadmap: 2 runs, LIGGGHTS CPU 6.7 min (200 s a run), 1.50 M particle-steps per CPU second, "
                    "workflow wall time 10.0 min")


def test_a_fed_particle_is_judged_against_the_front_where_the_pile_is_when_it_lands(tmp_path):
    """feed_landings: the pile's front at a landing is the top-up's front carried on by the roller,
    or the next top-up's measured front where the pile slumped further forward; a particle of the
    last top-up is judged against the carried front (no later measurement)."""
    from analysis.dem.health import feed_landings
    from analysis.metrics.dump import write_dump

    box = np.array([[-0.01, 0.03], [0, 1e-3], [0, 5e-3]])
    for step, x in ((100, [1.9e-3, 1.2e-3]), (200, [2.7e-3])):
        atoms = pd.DataFrame({"id": [step + i for i in range(len(x))], "x": x, "y": 5e-4, "z": 4e-4,
                              "radius": 1e-4})
        write_dump(tmp_path / f"landed.{step}.dump", atoms, box, timestep=step)
    roller_x = lambda step: 5e-6 * step  # noqa: E731  the roller's axis: 0.5 mm per 100 steps
    printed = {"feed_front_100": 1.0e-3, "feed_front_200": 2.0e-3}  # the pile slumped 0.5 mm past its carry
    landed = feed_landings(tmp_path, printed, roller_x, {100: 200, 200: 300}).set_index("id")
    # top-up 100: landed at step 200, front then max(1.0 + 0.5 carried, 2.0 measured) = 2.0 mm
    assert landed.loc[[100, 101], "front_at_landing_m"].tolist() == pytest.approx([2.0e-3, 2.0e-3])
    assert landed.loc[[100, 101], "ahead_of_front_m"].tolist() == pytest.approx([-0.1e-3, -0.8e-3])
    # top-up 200: landed at the travel's end (step 300), carried front 2.0 + 0.5 = 2.5 mm
    assert landed.loc[200, "ahead_of_front_m"] == pytest.approx(0.2e-3)
    assert landed.loc[200, "ahead_of_roller_m"] == pytest.approx(2.7e-3 - 1.5e-3)
    # a pile that receded is judged where the roller carried it, not nearer
    receded = feed_landings(tmp_path, {"feed_front_100": 1.0e-3, "feed_front_200": 1.2e-3}, roller_x,
                            {100: 200, 200: 300}).set_index("id")
    assert receded.loc[100, "ahead_of_front_m"] == pytest.approx(1.9e-3 - 1.5e-3)


def test_a_jam_under_the_stopped_roller_is_reported_not_refused_but_one_elsewhere_is(config, tmp_path):
    """Final-state overlaps: a pair squeezed 60 % of a radius in the stopped roller's nip is
    recorded (``max_overlap_nip``) and passes, as the nip's overlaps during a run do; the same pair
    on the bed behind the roller, or with no roller given, is refused by name."""
    import trimesh

    from analysis.config.fidelity import scene
    from analysis.dem.health import layer_health
    s = scene(config, "smoke")
    stl = tmp_path / "flat.stl"
    trimesh.Trimesh([[-0.05, -0.01, 0], [0.05, -0.01, 0], [0.05, 0.01, 0], [-0.05, 0.01, 0]],
                    [[0, 1, 2], [0, 2, 3]]).export(stl)
    r, axis = 100e-6, (0.013, 0.0153, s.roller_radius)

    def atoms(x_pair):
        """Two resting particles in the sampling region, and a pair stacked 60 % of a radius into each other."""
        x = [5.0e-3, 5.5e-3, x_pair, x_pair]
        z = [r, r, r, r + 2 * r - 0.6 * r]
        return pd.DataFrame({"id": range(1, 5), "x": x, "y": 5e-4, "z": z, "radius": r, "vx": 0.0, "vy": 0.0,
                             "vz": 0.0})

    nip = layer_health(atoms(axis[0]), s, stl, 4, roller=axis)
    assert nip["max_overlap_nip"] == pytest.approx(0.6) and nip["max_overlap_anywhere"] == 0.0
    assert nip["max_overlap_fraction"] == 0.0
    with pytest.raises(LiggghtsError, match=r"largest overlap 60.0% of a radius exceeds 50%"):
        layer_health(atoms(axis[0]), s, stl, 4)
    with pytest.raises(LiggghtsError, match=r"largest overlap 60.0% of a radius exceeds 50%"):
        layer_health(atoms(axis[0] - 10e-3), s, stl, 4, roller=axis)   # on the bed behind the roller


def test_blowup_watch_reads_only_complete_thermo_lines_of_a_growing_log(tmp_path):
    """The watch sees a row only once its line is complete, finds vmax by the header's name,
    and reports the first row past the limit (or not finite) with its step."""
    log = tmp_path / "spread.log"
    watch = BlowupWatch(log, limit=5.0)
    assert watch.scan() is None                                   # no log yet
    log.write_text("Step Atoms KinEng rke vmax CPU\n1000 10 1e-9 1e-9 0.4 0.1\n2000 10 1e-9 1e-9 7.")
    assert watch.scan() is None                                   # 7.x is half written
    with open(log, "a") as f:
        f.write("5 0.2\n3000 10 1e-9 1e-9 9.0 0.3\n")
    assert watch.scan() == (2000, 7.5)
    nan = BlowupWatch(log, limit=5.0)
    log.write_text("Step Atoms KinEng vmax\n1000 10 nan nan\n")
    step, speed = nan.scan()
    assert step == 1000 and np.isnan(speed)
