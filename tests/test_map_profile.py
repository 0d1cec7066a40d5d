"""benchmarks/map_profile.py on two hand-made map datasets: the groups' CPU, rate and loop shares,
and the before / after ratios over the points both ran."""
import pandas as pd
import pytest

from benchmarks import map_profile


def write_map(path, rows, frozen=None):
    data = pd.DataFrame(rows, columns=["U_mm_s", "omega_rad_s", "cpu_s", "particle_steps"])
    data = data.assign(time_pair_s=0.4 * data["cpu_s"], time_neigh_s=0.1 * data["cpu_s"], time_comm_s=0.0,
                       time_other_s=0.5 * data["cpu_s"], time_loop_s=data["cpu_s"])
    if frozen is not None:
        data["frozen_particles"] = frozen
    data.to_csv(path, index=False)
    return path


def test_two_maps_are_profiled_by_group_and_compared_over_their_common_points(tmp_path):
    before = write_map(tmp_path / "b.csv", [(70, -15, 300.0, 6e8), (70, 0, 100.0, 3e8), (70, 10, 120.0, 3e8),
                                             (40, -15, 500.0, 1e9)])
    after = write_map(tmp_path / "a.csv", [(70, -15, 200.0, 4e8), (70, 0, 100.0, 3e8), (70, 10, 120.0, 3e8)],
                      frozen=[2000, 300, 250])
    assert map_profile.main([str(before), str(after), "--labels", "old,new", "--name", "p",
                             "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "p.csv").set_index(["map", "runs"])
    old = table.loc[("old", "forward rolling (omega < 0)")]
    assert old["n"] == 2 and old["cpu_s"] == 800.0 and old["M_particle_steps_per_cpu_s"] == pytest.approx(2.0)
    assert old["pair_pct"] == pytest.approx(40.0) and old["output_pct"] == pytest.approx(0.0, abs=1e-9)
    assert table.loc[("new", "all runs"), "frozen_particles_mean"] == pytest.approx(850.0)
    text = (tmp_path / "p.md").read_text()
    ratio_rows = [line for line in text.splitlines() if line.startswith("| forward rolling") and "1.500" in line]
    assert len(ratio_rows) == 1  # 300 / 200 over (70, -15) only: (40, -15) is in one map
    assert "| all runs                     |        3 |       1.238 |" in text  # 520 / 420 s


def test_a_dataset_without_the_timing_columns_is_refused_naming_them(tmp_path):
    pd.DataFrame({"U_mm_s": [70], "omega_rad_s": [0], "cpu_s": [1.0]}).to_csv(tmp_path / "old.csv", index=False)
    good = write_map(tmp_path / "a.csv", [(70, 0, 1.0, 1e6)])
    with pytest.raises(SystemExit, match="lacks the columns particle_steps, time_loop_s"):
        map_profile.main([str(tmp_path / "old.csv"), str(good), "--out", str(tmp_path)])
    with pytest.raises(SystemExit, match="no such dataset"):
        map_profile.main([str(tmp_path / "none.csv"), str(good), "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        map_profile.main([str(good), str(good), "--labels", "one", "--out", str(tmp_path)])
    assert not (tmp_path / "spread_profile_maps.md").exists()
