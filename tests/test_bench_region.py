"""benchmarks/bench_region.py: the noise, ceiling and bias of a region on hand-made layers (its smoke run
through real LIGGGHTS re-measures bench_fidelity.py's kept layer: tests/test_bench_fidelity.py)."""
import numpy as np
import pandas as pd
import pytest

from benchmarks.bench_region import METRICS, summarise


def rows(source, region, values, point=(70.0, 0.0)):
    """One row per value of ``mass_g`` (the other metrics follow it, x2, x3, x4) over one region."""
    start, end = (float(v) for v in region.split("-"))
    return [{"source": source, "seed": s, "U_mm_s": point[0], "omega_rad_s": point[1], "region_mm": region,
             "start_mm": start, "end_mm": end, "length_mm": end - start,
             **{k: v * (i + 1) for i, k in enumerate(METRICS)}} for s, v in enumerate(values)]


def test_a_region_is_scored_by_its_seed_sd_the_maps_spread_and_its_shift_from_the_levels_region():
    runs = pd.DataFrame(
        rows("replicates", "6-9", [1.0, 2.0, 3.0]) + rows("replicates", "6-12", [1.7, 2.2, 2.7])  # sd 1, 0.5
        + rows("map", "6-9", [2.0], (40.0, 0.0)) + rows("map", "6-9", [4.0], (40.0, 10.0))
        + rows("map", "6-9", [6.0], (40.0, 20.0))                                                # var 4
        + rows("map", "6-12", [2.5], (40.0, 0.0)) + rows("map", "6-12", [4.5], (40.0, 10.0))
        + rows("map", "6-12", [6.0], (40.0, 20.0)))                                              # +0.5, +0.5, 0
    table = summarise(runs, own="6-9").set_index("region_mm")
    assert list(table.index) == ["6-9", "6-12"]                      # by length
    assert table.loc["6-9", "M_s_sd_pct"] == pytest.approx(50.0)     # sd 1 over mean 2
    assert table.loc["6-12", "M_s_sd_pct"] == pytest.approx(100 * 0.5 / 2.2)
    assert table.loc["6-9", "M_s_R_max"] == pytest.approx(np.sqrt(1 - 1 / 4))
    assert table.loc["6-12", "M_s_R_max"] == pytest.approx(np.sqrt(1 - 0.25 / (37 / 12)))  # var of 2.5, 4.5, 6
    assert table.loc["6-12", "M_s_map_shift_sd"] == pytest.approx(0.5)  # the worst omega, in 6-9's sd (1)
    assert table.loc["6-12", "M_s_rep_shift_sd"] == pytest.approx(0.2)  # paired: +0.7, +0.2, -0.3
    assert table.loc["6-9", "M_s_map_shift_sd"] == 0.0
    assert table.loc["6-12", "Q_s_map_shift_sd"] == pytest.approx(0.5)  # every metric scaled alike here
