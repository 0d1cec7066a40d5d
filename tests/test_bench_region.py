"""benchmarks/bench_region.py: the noise, ceiling and bias of a region on hand-made layers (its smoke run
through real LIGGGHTS re-measures bench_fidelity.py's kept layer: tests/test_bench_fidelity.py)."""
import numpy as np
import pandas as pd
import pytest

from benchmarks.bench_region import METRICS, summarise


def rows(source, start, values, point=(70.0, 0.0), seeds=None):
    """One row per value of ``mass_g`` (the other metrics follow it) at one region start."""
    seeds = range(len(values)) if seeds is None else seeds
    return [{"source": source, "seed": s, "U_mm_s": point[0], "omega_rad_s": point[1], "start_mm": start,
             "length_mm": 9.0 - start, **{k: v * (i + 1) for i, k in enumerate(METRICS)}}
            for s, v in zip(seeds, values)]


def test_a_region_is_scored_by_its_seed_sd_the_maps_spread_and_its_shift_from_the_levels_region():
    runs = pd.DataFrame(
        rows("replicates", 6.0, [1.0, 2.0, 3.0]) + rows("replicates", 4.0, [1.5, 2.0, 2.5])  # sd 1 and 0.5
        + rows("map", 6.0, [2.0], (40.0, 0.0)) + rows("map", 6.0, [4.0], (40.0, 10.0))
        + rows("map", 6.0, [6.0], (40.0, 20.0))                                            # var 4
        + rows("map", 4.0, [2.5], (40.0, 0.0)) + rows("map", 4.0, [4.5], (40.0, 10.0))
        + rows("map", 4.0, [6.5], (40.0, 20.0)))                                           # each +0.5
    table = summarise(runs, own_start_mm=6.0).set_index("start_mm")
    assert table.loc[6.0, "M_s_sd_pct"] == pytest.approx(50.0)       # sd 1 over mean 2
    assert table.loc[4.0, "M_s_sd_pct"] == pytest.approx(25.0)
    assert table.loc[6.0, "M_s_R_max"] == pytest.approx(np.sqrt(1 - 1 / 4))
    assert table.loc[4.0, "M_s_R_max"] == pytest.approx(np.sqrt(1 - 0.25 / 4))
    assert table.loc[4.0, "M_s_bias_sd"] == pytest.approx(0.5)       # in the level region's sd (1), not its own
    assert table.loc[4.0, "M_s_worst_omega_sd"] == pytest.approx(0.5)
    assert table.loc[6.0, "M_s_bias_sd"] == 0.0
    assert table.loc[4.0, "Q_s_bias_sd"] == pytest.approx(0.5)       # every metric scaled alike here

