"""Figures 6-10: hybrid-index arithmetic, process-map lines, written files."""

import runpy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import synthetic_dataset, synthetic_metrics

from analysis.columns import METRICS
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, split_table, targets_of
from analysis.surrogate.intervals import CalibratedSurrogate
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.predict import hybrid_indices, metric_maxima, predict_grid
from analysis.viz.maps import render_maps
from analysis.viz.process_map import process_map_lines

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_hybrid_indices_on_a_hand_made_grid():
    frame = pd.DataFrame({"mass_g": [1.0, 2.0, 4.0], "throughput_mm2_s": [10.0, 5.0, 20.0],
                          "roughness_um": [3.0, 6.0, 6.0], "porosity_pct": [50.0, 25.0, 100.0]})
    assert metric_maxima(frame) == {"mass_g": 4.0, "throughput_mm2_s": 20.0,
                                    "roughness_um": 6.0, "porosity_pct": 100.0}
    throughput, defect = hybrid_indices(frame)
    assert throughput == pytest.approx([10 / 20 * 1 / 4, 5 / 20 * 2 / 4, 1.0])
    assert defect == pytest.approx([3 / 6 * 50 / 100, 6 / 6 * 25 / 100, 1.0])
    doubled = {m: 2 * v for m, v in metric_maxima(frame).items()}
    throughput2, defect2 = hybrid_indices(frame, doubled)
    assert throughput2 == pytest.approx(throughput / 4) and defect2 == pytest.approx(defect / 4)


def test_hybrid_indices_refuse_a_non_positive_maximum():
    frame = pd.DataFrame({m: [1.0, 2.0] for m in METRICS})
    frame["porosity_pct"] = [-1.0, 0.0]
    with pytest.raises(ValueError, match="porosity_pct"):
        hybrid_indices(frame)


def test_process_map_lines_meet_at_the_swept_runs(fitted):
    model = fitted[0]
    U_values, omega_values = [40, 55, 70, 85, 100], [-20, -15, -10, -5, 0, 5, 10, 15, 20]
    maxima = metric_maxima(predict_grid(model, (40, 100), (-20, 20), 41))
    lines = process_map_lines(model, U_values, omega_values, maxima, n=41)
    assert len(lines) == (5 + 9) * 41
    iso_U = lines[lines.family == "U"]
    assert (iso_U["U_mm_s"] == iso_U["value"]).all()
    assert iso_U.groupby("value")["omega_rad_s"].agg(["min", "max"]).values.tolist() == [[-20, 20]] * 5
    # The iso-U line U = 85 and the iso-omega line omega = -5 cross at (85, -5).
    a = iso_U[(iso_U.value == 85) & np.isclose(iso_U.omega_rad_s, -5)]
    iso_w = lines[lines.family == "omega"]
    b = iso_w[(iso_w.value == -5) & np.isclose(iso_w.U_mm_s, 85)]
    assert len(a) == len(b) == 1
    assert a[["throughput_index", "defect_index"]].values == pytest.approx(
        b[["throughput_index", "defect_index"]].values)
    # Normalised by the grid maxima, which the lines cannot exceed.
    assert lines["throughput_index"].max() <= 1 + 1e-9


def _check_figures(paths, outdir, window=False):
    expected = {f"{m}_{kind}.{ext}" for m in METRICS for kind in ("surface", "contour", "parity")
                for ext in ("png", "svg")} | {"process_map.png", "process_map.svg"}
    if window:
        expected |= {"operating_window.png", "operating_window.svg"}
    assert {p.name for p in paths} == expected
    assert {p.name for p in Path(outdir).iterdir()} == expected        # no temporaries
    for path in paths:
        data = path.read_bytes()
        if path.suffix == ".png":
            assert data.startswith(PNG_MAGIC) and len(data) > 20_000, path.name
        else:
            assert b"<svg" in data[:2000] and len(data) > 20_000, path.name


def test_render_maps_writes_every_figure(fitted, dataset, tmp_path):
    model, scores = fitted
    split = (scores["split"]["train"], scores["split"]["test"])
    paths = render_maps(model, dataset, split, tmp_path / "maps", n=21)
    _check_figures(paths, tmp_path / "maps")
    # Labels carry units.
    svg = (tmp_path / "maps" / "throughput_mm2_s_parity.svg").read_text()
    assert "Training: R = " in svg and "Test: R = " in svg


def test_render_maps_script(fitted, dataset, tmp_path, fake_snakemake):
    model, scores = fitted
    dataset.to_csv(tmp_path / "dataset.csv", index=False)
    save_surrogate(model, tmp_path / "model.joblib", scores)
    split_table(dataset, scores["split"]["train"], scores["split"]["test"]).to_csv(
        tmp_path / "split.csv", index=False)
    smk = fake_snakemake({"model": str(tmp_path / "model.joblib"),
                                  "dataset": str(tmp_path / "dataset.csv"),
                                  "split": str(tmp_path / "split.csv")},
                           {"maps": str(tmp_path / "maps")},
                           {"maps": {"axes": ["U_mm_s", "omega_rad_s"], "hold": {}, "panels": None,
                                     "operating_window": {"max_porosity_pct": 50, "max_roughness_um": None}}})
    runpy.run_path(str(smk.scriptdir / "render_maps.py"), init_globals={"snakemake": smk})
    paths = sorted((tmp_path / "maps").iterdir())
    _check_figures(paths, tmp_path / "maps", window=True)


def test_supply_limited_runs_are_ringed_on_the_surfaces_and_the_process_map(fitted, dataset):
    from analysis.viz.figures import supply_limited
    from analysis.viz.process_map import process_map_figure
    from analysis.viz.surfaces import surface_figure
    model, scores = fitted
    split = (np.arange(35), np.arange(35, 45))
    limited = dataset.assign(heap_exhausted=dataset["omega_rad_s"] <= -15)
    assert supply_limited(limited).sum() == 10 and not supply_limited(dataset).any()
    assert supply_limited(limited.astype({"heap_exhausted": str})).sum() == 10  # as read back from the CSV
    for fig in (surface_figure(model, limited, split, "mass_g", n=11), process_map_figure(model, limited, split, n=21)):
        labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        assert any("supply-limited" in label for label in labels), labels
    legend = surface_figure(model, dataset, split, "mass_g", n=11).axes[0].get_legend()
    labels = [t.get_text() for t in legend.get_texts()]
    assert not any("supply-limited" in label for label in labels)


# --- Figure 10 legible, the operating window ---------------------------------------------

def _shifted(U, omega):
    """The synthetic metrics with eq. 7's porosity pushed below 0 at positive omega (as a deep deposit does)."""
    metrics = synthetic_metrics(U, omega)
    return {**metrics, "porosity_pct": metrics["porosity_pct"] - 45}


@pytest.fixture(scope="module")
def calibrated_gp():
    """A GP on 45 runs (2 % noise) whose porosity goes negative, calibrated by hand; and its runs."""
    df = synthetic_dataset(1, noise=0.02, metrics=_shifted)
    gp = GPSurrogate(n_restarts=0).fit(inputs_of(df), targets_of(df))
    scores = np.abs(np.random.default_rng(0).standard_normal((45, 6)))
    return CalibratedSurrogate(gp, np.ones(6), np.full(6, 0.02), scores, 45, 0.9, "by hand"), df


def _overlaps(a, b):
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.mark.parametrize("which", ["network", "negative porosity"])
def test_process_map_labels_overlap_no_label_and_no_line(which, fitted, dataset, calibrated_gp):
    from matplotlib.path import Path as MplPath

    from analysis.viz.process_map import process_map_figure
    model, df = (fitted[0], dataset) if which == "network" else calibrated_gp
    fig = process_map_figure(model, df, (np.arange(35), np.arange(35, 45)), n=61)
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in fig.line_labels]
    assert len(boxes) >= (14 if which == "network" else 10)       # 5 iso-U + 9 iso-omega lines
    assert {t.get_text() for t in fig.line_labels} <= {f"U={u}" for u in (40, 55, 70, 85, 100)} | {
        f"ω={w}" for w in range(-20, 21, 5)}
    for i, a in enumerate(boxes):
        assert not any(_overlaps(a, b) for b in boxes[i + 1:]), fig.line_labels[i].get_text()
        assert frame_contains(ax.get_window_extent(renderer), a)
    lines = [line for line in ax.get_lines() if len(line.get_xydata()) > 2]
    assert len(lines) == 14
    for line in lines:
        path = MplPath(ax.transData.transform(line.get_xydata()))
        assert not any(path.intersects_bbox(box, filled=False) for box in boxes)
        assert (line.get_xydata()[:, 1] >= 0).all()                # the defect index, from max(Phi, 0)
    assert ax.get_xlim()[0] == 0 and ax.get_ylim()[0] == 0
    assert "max(\\Phi, 0)" in ax.get_ylabel()
    if which == "negative porosity":
        assert (model.predict(inputs_of(df))[:, 3] < 0).any()       # eq. 7's Phi is negative somewhere


def frame_contains(frame, box):
    return frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1


def test_operating_window_marks_the_recommended_setting(calibrated_gp):
    from analysis.surrogate.recommend import recommend
    from analysis.viz.contours import window_figure
    model, df = calibrated_gp
    split = (np.arange(35), np.arange(35, 45))
    meta = {"input_range": {"U_mm_s": [40.0, 100.0], "omega_rad_s": [-20.0, 20.0]}}
    found = recommend(model, meta, 8, 60, n=121)
    fig = window_figure(model, df, split, 8, 60, n=121)
    best = fig.recommended[0]
    assert (best["U_mm_s"], best["omega_rad_s"]) == pytest.approx((found["U_mm_s"], found["omega_rad_s"]))
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert any(label.startswith("recommended: U = ") for label in labels)
    assert "90 % of runs" in fig.axes[0].get_title()
    none = window_figure(model, df, split, None, 1.0, n=21)      # R_q <= 1 um: nowhere
    assert none.recommended == [None]
    assert any("no setting meets the limits" in t.get_text() for t in none.axes[0].texts)


def test_contour_map_shows_the_runs(calibrated_gp):
    from analysis.viz.contours import contour_figure
    model, df = calibrated_gp
    fig = contour_figure(model, df, (np.arange(35), np.arange(35, 45)), "roughness_um", n=21)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["simulated training runs (35)", "simulated test runs (10)"]
    assert fig.axes[0].get_xlabel().startswith(r"$\omega$") and fig.axes[0].get_ylabel().startswith("$U$")


def test_a_smooth_model_draws_the_lines_when_the_trees_are_chosen(fit_params):
    from analysis.surrogate.selection import cross_validate_models, smooth_stand_in
    from analysis.viz.process_map import process_map_figure
    df = synthetic_dataset(2, noise=0.03)
    params = {**fit_params, "models": ["trees", "gp"], "cv_repeats": 1, "cv_loo": False, "gp_restarts": 0,
              "tree_count": 20}
    _, held_out = cross_validate_models(df, params, return_predictions=True)
    train = np.arange(35)
    assert smooth_stand_in(df, params, "gp", train, held_out) == (None, None)
    smooth, name = smooth_stand_in(df, params, "trees", train, held_out)
    assert name == "gp" and isinstance(smooth.model, GPSurrogate) and smooth.is_finite()
    fig = process_map_figure(smooth, df, (train, np.arange(35, 45)), n=31, note="Iso-lines of the gp")
    assert fig._supxlabel.get_text().startswith("Iso-lines of the gp. Grey crosses")
