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


def test_a_variant_is_judged_against_a_reference_variant_in_the_references_seed_sd_region_by_region():
    """Two points; the reference's seed sd is sqrt(2) at each (pooled the same), the variant's means lie
    +0.5 and -2 from the reference's 2 and 4: the largest distance is 2 / sqrt(2) reference sds, the mean
    change (+25 % - 50 %) / 2; without reference rows there is no such column."""
    runs = pd.DataFrame(
        rows("replicates", "6-9", [2.0, 3.0], (70.0, 0.0)) + rows("replicates", "6-9", [1.5, 2.5], (70.0, 10.0))
        + rows("against", "6-9", [1.0, 3.0], (70.0, 0.0)) + rows("against", "6-9", [3.0, 5.0], (70.0, 10.0))
        + rows("map", "6-9", [2.0], (40.0, 0.0)) + rows("map", "6-9", [4.0], (40.0, 10.0)))
    row = summarise(runs, own="6-9").set_index("region_mm").loc["6-9"]
    assert row["M_s_vs_ref_sd"] == pytest.approx(2.0 / np.sqrt(2))
    assert row["M_s_vs_ref_pct"] == pytest.approx((25.0 - 50.0) / 2)
    assert row["Phi_vs_ref_sd"] == pytest.approx(2.0 / np.sqrt(2))  # every metric scaled alike
    assert "M_s_vs_ref_sd" not in summarise(runs[runs["source"] != "against"], own="6-9")


def test_a_wider_variants_kept_layer_is_measured_over_its_own_strip_and_per_the_levels_area(tmp_path):
    """A kept layer of ``E1e8+strip2.5+pile40`` at the smoke level (a 2.5 mm strip; the level's is 1 mm):
    a square lattice of 100 um spheres covers only y = 1.2-2.4 mm, so the level's 1 mm region would hold
    none of it. Over the variant's strip, M_s per the level's region area is 1.2 / 2.5 of the lattice's
    areal mass (it covers that share of the strip), whatever the region's length. Its spheres past
    x = 6 mm carry ids above the variant's heap count: the feed's share of each region is theirs."""
    from analysis.dem.geometry import height_field_mesh
    from analysis.metrics.dump import write_dump
    from benchmarks import bench_region
    r, rho = 50e-6, 4430.0
    layer = tmp_path / "kept" / "E1e8+strip2.5+pile40_s0_U70_w-15"
    layer.mkdir(parents=True)
    x, y = np.meshgrid(np.arange(0.05e-3, 10e-3, 2 * r), 1.2e-3 + r + 2 * r * np.arange(12))
    ids = np.arange(1, x.size + 1) + np.where(x.ravel() > 6e-3, 100_000, 0)  # fed past x = 6 mm (heap: 7,580)
    atoms = pd.DataFrame({"id": ids, "x": x.ravel(), "y": y.ravel(), "z": r, "radius": r})
    write_dump(layer / "final.dump", atoms, [[-1e-3, 11e-3], [0.0, 2.5e-3], [-1e-3, 5e-3]])
    gx, gy = np.arange(-0.95e-3, 12e-3, 0.1e-3), np.linspace(-0.5e-3, 3e-3, 8)  # 0.1 mm facets
    height_field_mesh(gx, gy, np.where(gx[:, None] > 6e-3, 30e-6, 0.0) + 0 * gy).export(
        layer / "substrate.stl")  # 30 um higher past x = 6 mm (a ramp over 5.95-6.05 mm)
    assert bench_region.main(["--replicates", str(tmp_path / "kept"), "--level", "smoke",
                              "--variant", "E1e8+strip2.5+pile40", "--regions", "4.5-7.5", "--jobs", "1",
                              "--name", "wide", "--out", str(tmp_path)]) == 0
    measured = pd.read_csv(tmp_path / "wide.csv").set_index("region_mm")
    areal = rho * 4 / 3 * np.pi * r**3 / (2 * r) ** 2  # the lattice's mass per area [kg/m^2]
    level_area = 2e-3 * 1e-3                            # the smoke level's region, 2 x 1 mm
    for label in ("4.5-6.5", "4.5-7.5"):
        assert measured.loc[label, "mass_g"] * 1e-3 == pytest.approx(1.2 / 2.5 * areal * level_area, rel=1e-9)
    assert measured.loc["4.5-6.5", "roughness_um"] > 0  # bare bed beside the lattice: not a flat top
    # the feed's share: lattice columns at 6.05-6.45 of 4.55-6.45 mm, and 6.05-7.45 of 4.55-7.45 mm
    assert measured.loc["4.5-6.5", "fed_pct"] == pytest.approx(25.0)
    assert measured.loc["4.5-7.5", "fed_pct"] == pytest.approx(50.0)
    # the gap's datum is the substrate's mean plane under the level's region, 4.5-6.5 mm: a quarter of it
    # stands 30 um high, so the datum is 7.5 um up, and 4.5-7.5 mm (half of it high) 7.5 um above it
    # (to a facet's half-width at the regions' ends)
    assert measured.loc["4.5-6.5", "substrate_above_datum_um"] == pytest.approx(0.0, abs=1e-9)
    assert measured.loc["4.5-7.5", "substrate_above_datum_um"] == pytest.approx(7.5, abs=1.0)
    with pytest.raises(SystemExit):
        bench_region.main(["--replicates", str(tmp_path / "kept"), "--variant", "strip9"])
    with pytest.raises(SystemExit):
        bench_region.main(["--replicates", str(tmp_path / "kept"), "--variant", "default", "--against", "default"])


def test_a_swapped_layer_is_said_to_follow_the_realisation_its_profile_is_nearer_to(tmp_path):
    """profile_swap: powder 0 on substrate 1 whose profile is substrate 1's layer's (but for 0.1 mg) follows
    the substrate, at RMS 0.1 mg from it and 2 mg from its powder's; an unknown variant is refused."""
    from benchmarks import profile_swap

    def table(path, variant, profiles):
        rows = [{"seed": seed, "start_mm": x, "length_mm": 1.0, "mass_g": m * 1e-3}
                for seed, profile in profiles.items() for x, m in enumerate(profile)]
        pd.DataFrame(rows).to_csv(path, index=False)
        return f"{variant}={path}"

    own = table(tmp_path / "default.csv", "default", {0: [6.0] * 10, 1: [8.0] * 10})
    swapped = table(tmp_path / "swap.csv", "substrate+1", {0: [8.1] * 10})
    assert profile_swap.main([own, swapped, "--out", str(tmp_path)]) == 0
    text = (tmp_path / "profile_swap.md").read_text()
    assert "| powder 0 on substrate 1 (substrate+1) | flat bed 0-5 mm     |                        0.1 |" \
           "                     2.1 | same substrate |" in text
    with pytest.raises(SystemExit):  # the default's own layers alone: nothing swapped to judge
        profile_swap.main([own, "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        profile_swap.main([own, swapped.replace("substrate+1", "substrate+2"), "--out", str(tmp_path)])


def test_a_change_along_the_travel_is_split_into_the_substrates_height_and_the_rest(tmp_path):
    """substrate_height: two layers (levels 5 and 7 mg) of six 1 mm bins whose M_s loses 0.02 mg per um
    of substrate height and, past 9 mm, 0.3 mg more: the fit gives both back exactly, the far bins standing
    9 um higher on average make the change as measured 0.18 mg larger; a table without heights is refused."""
    from benchmarks import substrate_height
    heights = {0: [0, -10, 5, 12, 8, 10], 1: [-5, 3, -4, 9, 1, 3]}
    rows = []
    for seed, level in ((0, 5.0), (1, 7.0)):
        for i, h in enumerate(heights[seed]):
            far = i >= 3
            rows.append({"seed": seed, "U_mm_s": 70.0, "omega_rad_s": 0.0, "start_mm": 6.0 + i, "end_mm": 7.0 + i,
                         "length_mm": 1.0, "substrate_above_datum_um": h,
                         "mass_g": 1e-3 * (level - 0.02 * h - 0.3 * far)})
    bins = pd.DataFrame(rows)
    fit = substrate_height.fit_height(bins, (6.0, 9.0), (9.0, 12.0))
    near = bins["mass_g"][bins["start_mm"] < 9].mean() * 1e3
    mean = bins["mass_g"].mean() * 1e3
    assert fit["mass_pct_per_um"] == pytest.approx(-100 * 0.02 / mean)
    assert fit["far_pct"] == pytest.approx(-100 * 0.3 / near)
    assert fit["far_height_um"] == pytest.approx((30 + 13) / 6 - (-5 - 6) / 6)  # 9 um
    assert fit["far_raw_pct"] == pytest.approx(-100 * (0.3 + 0.02 * 9.0) / near)
    assert fit["corr_within_layers"] < -0.9
    assert (fit["layers"], fit["bins"]) == (2, 12)
    bins.to_csv(tmp_path / "bins.csv", index=False)
    assert substrate_height.main([f"default={tmp_path / 'bins.csv'}", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "substrate_height.csv").exists()
    bins.drop(columns="substrate_above_datum_um").to_csv(tmp_path / "old.csv", index=False)
    with pytest.raises(SystemExit):
        substrate_height.main([f"default={tmp_path / 'old.csv'}", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        substrate_height.main([f"default={tmp_path / 'bins.csv'}", "--far", "9", "--out", str(tmp_path)])
