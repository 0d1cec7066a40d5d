"""benchmarks/travel_time.py on a hand-made run: each thermo interval in the phase the roller's axis ends
it in, the thermo's CPU column restarting at each run segment (its smoke on a real LIGGGHTS run:
tests/test_bench_fidelity.py)."""
import pandas as pd
import pytest

from benchmarks import travel_time

THERMO = "Step Atoms KinEng CPU\n{rows}Loop time of 1 on 1 procs for 1 steps with 100 atoms\n"


def make_run(folder, blocks, header="# spreadmap: one spreading pass, U = 70 mm/s, omega = -15 rad/s (level default)."):
    folder.mkdir(parents=True)
    (folder / "spread.in").write_text(f"{header}\nvariable roller_stop_x equal -0.01+1e-06*step\n")
    (folder / "spread.log").write_text("".join(
        THERMO.format(rows="".join(f"{step} 100 0.0 {cpu}\n" for step, cpu in block)) for block in blocks))


def test_a_runs_time_is_split_by_where_the_rollers_axis_is(tmp_path):
    """The default's region is 6-9 mm and its laid checks begin at 11: the axis at -10 mm + 1 um per step
    is at 6 mm at step 16,000, 9 at 19,000, 11 at 21,000; three run segments, their CPU from 0 each."""
    make_run(tmp_path / "runs" / "U70_w-15_r0", [[(0, 0.0), (16000, 10.0)],
                                                 [(16000, 0.0), (19000, 3.0), (21000, 5.0)],
                                                 [(21000, 0.0), (23000, 4.0)]])
    make_run(tmp_path / "runs" / "U70_w10_r0", [[(0, 0.0), (16000, 4.0), (19000, 5.0), (21000, 6.0)]],
             header="# spreadmap: one spreading pass, U = 70 mm/s, omega = 10 rad/s (level default).")
    assert travel_time.main(["--runs", str(tmp_path / "runs"), "--name", "t", "--out", str(tmp_path)]) == 0
    runs = pd.read_csv(tmp_path / "t.csv")
    one = runs[runs["run"] == "U70_w-15_r0"].set_index("phase")
    assert one["time_s"].tolist() == pytest.approx([10.0, 3.0, 2.0, 4.0])
    assert one["travel_mm"].tolist() == pytest.approx([16.0, 3.0, 2.0, 2.0])
    assert one["particle_steps"].tolist() == pytest.approx([1.6e6, 3e5, 2e5, 2e5])
    table = travel_time.summarise(runs).set_index("runs")
    assert table.loc["forward rolling (omega < 0)", "run_in_time_pct"] == pytest.approx(100 * 10 / 19)
    assert table.loc["counter-rotating (omega > 0)", "laid_checks_time_pct"] == 0.0
    assert table.loc["all runs", "n"] == 2 and table.loc["all runs", "time_s"] == pytest.approx(25.0)
    assert table.loc["all runs", "region_s_per_mm"] == pytest.approx((3.0 + 1.0) / 6.0)
    assert "| forward rolling (omega < 0) " in (tmp_path / "t.md").read_text()


def test_a_run_without_the_rollers_position_or_a_bad_level_is_refused(tmp_path):
    make_run(tmp_path / "runs" / "r", [[(0, 0.0), (10, 1.0)]], header="# not a spread")
    with pytest.raises(ValueError, match="no roller_stop_x line or no 'U = .. mm/s"):
        travel_time.main(["--runs", str(tmp_path / "runs"), "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        travel_time.main(["--runs", str(tmp_path / "runs"), "--level", "huge"])
    with pytest.raises(SystemExit):
        travel_time.main(["--runs", str(tmp_path / "nothing")])


def write_dump(path, xs):
    rows = "".join(f"{i + 1} 1 {x:g} 0.0005 0.0001 0.0001 0 0 0\n" for i, x in enumerate(xs))
    path.write_text(f"ITEM: TIMESTEP\n23000\nITEM: NUMBER OF ATOMS\n{len(xs)}\nITEM: BOX BOUNDS ff pp ff\n"
                    f"-0.02 0.03\n0 0.001\n-0.001 0.03\nITEM: ATOMS id type x y z radius vx vy vz\n{rows}")


def test_the_layer_laid_before_the_region_is_counted_from_where_the_roller_passed_it(tmp_path):
    """The axis at -10 mm + 1 um per step stops at step 23,000 (13 mm); 100 particles integrated throughout
    (2.3e6 particle-steps). Of the final layer, the particles at 0 and 4 mm are laid before the region (6 mm,
    less 1 mm); 5.5 and 7 mm are not. With an 8 mm lag the axis passes 8 mm at step 18,000 and 12 mm at
    22,000: they would be deleted for 5,000 and 1,000 steps, 6,000 particle-steps, 0.26 % of the run's."""
    folder = tmp_path / "runs" / "U70_w-15_r0"
    make_run(folder, [[(0, 0.0), (23000, 10.0)]])
    write_dump(folder / "final.dump", [0.0, 0.004, 0.0055, 0.007])
    laid = travel_time.laid_before_region(travel_time.read_run(folder), 0.006, 0.008)
    assert laid["laid_before_region"] == 2
    assert laid["particle_steps"] == pytest.approx(2.3e6)
    assert laid["share_after_lag_pct"] == pytest.approx(100 * 6000 / 2.3e6)
    make_run(tmp_path / "runs" / "U70_w10_r0", [[(0, 0.0), (23000, 10.0)]],
             header="# spreadmap: one spreading pass, U = 70 mm/s, omega = 10 rad/s (level default).")
    write_dump(tmp_path / "runs" / "U70_w10_r0" / "final.dump", [0.0055])
    assert travel_time.main(["--runs", str(tmp_path / "runs"), "--name", "t", "--out", str(tmp_path)]) == 0
    table = travel_time.summarise_laid(pd.read_csv(tmp_path / "t_laid.csv")).set_index("runs")
    assert table.loc["counter-rotating (omega > 0)", "laid_before_region"] == 0
    assert table.loc["all runs", "share_after_lag_pct"] == pytest.approx(100 * 6000 / 4.6e6)
    assert "## The layer laid before the region" in (tmp_path / "t.md").read_text()
