"""Figures 6-10: hybrid-index arithmetic, process-map lines, the written files, and the figures' content
(axes' ranges, the runs plotted, colour bars) against the model's predictions computed here."""

import runpy
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import structured_dataset, synthetic_dataset, synthetic_metrics

from analysis.columns import METRICS, STRUCTURE_METRICS
from analysis.metrics.dataset import with_structure_metrics
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, split_runs, split_table, targets_of
from analysis.surrogate.intervals import CalibratedStack, CalibratedSurrogate
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


#: Figure sizes (inches) of each kind at the maps' 150 dpi: the PNGs' pixel sizes.
_SIZES = {"surface": (8.0, 6.5), "contour": (7.5, 6.2), "parity": (10.0, 4.8), "process_map": (9.0, 6.5),
          "operating_window": (7.8, 6.6)}


def _check_figures(paths, outdir, window=False):
    """Every figure written once, in both formats, nothing else left; each PNG an image of its
    figure's size at 150 dpi with something drawn (not one flat colour); each SVG a drawing."""
    from matplotlib.image import imread
    expected = {f"{m}_{kind}.{ext}" for m in METRICS for kind in ("surface", "contour", "parity")
                for ext in ("png", "svg")} | {"process_map.png", "process_map.svg"}
    if window:
        expected |= {"operating_window.png", "operating_window.svg"}
    assert {p.name for p in paths} == expected
    assert {p.name for p in Path(outdir).iterdir()} == expected        # no temporaries
    for path in paths:
        if path.suffix == ".png":
            assert path.read_bytes().startswith(PNG_MAGIC), path.name
            kind = next(k for k in _SIZES if path.stem.endswith(k))
            image = imread(path)
            assert image.shape[:2] == (round(150 * _SIZES[kind][1]), round(150 * _SIZES[kind][0])), path.name
            rgb = (255 * image[::3, ::3, :3]).astype(np.uint32)
            assert len(np.unique(rgb[..., 0] << 16 | rgb[..., 1] << 8 | rgb[..., 2])) > 50, path.name
        else:
            assert b"<svg" in path.read_bytes()[:2000], path.name


def test_render_maps_writes_every_figure(fitted, dataset, tmp_path):
    model, scores = fitted
    split = (scores["split"]["train"], scores["split"]["test"])
    paths = render_maps(model, dataset, split, tmp_path / "maps", n=21)
    _check_figures(paths, tmp_path / "maps")
    # the parity plot's titles state R of the runs, recomputed here from the model's predictions
    svg = (tmp_path / "maps" / "throughput_mm2_s_parity.svg").read_text()
    sim, pred = dataset["throughput_mm2_s"].to_numpy(), model.predict(inputs_of(dataset))[:, 1]
    for name, rows in zip(("Training", "Test"), split):
        assert f"{name}: R = {np.corrcoef(sim[rows], pred[rows])[0, 1]:.3f}" in svg


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


# --- the figures' content, against the model's predictions computed here ------------------

def _hand_grid(model, n, U=(40, 100), omega=(-20, 20)):
    """The model's predictions on the n x n (U, omega) grid: {metric: (n, n) array}, U outer."""
    UU, WW = np.meshgrid(np.linspace(*U, n), np.linspace(*omega, n), indexing="ij")
    pred = model.predict(np.column_stack([UU.ravel(), WW.ravel()]))
    return {m: pred[:, j].reshape(n, n) for j, m in enumerate(METRICS)}


def _runs(ax, label):
    """The points of the scatter whose legend label starts with ``label`` ((k, 2) offsets)."""
    found = [c for c in ax.collections if c.get_label().startswith(label)]
    assert len(found) == 1, [c.get_label() for c in ax.collections]
    return np.asarray(found[0].get_offsets())


def _colour_bar(fig):
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1
    return bars[0].get_ylim()


@pytest.mark.parametrize("metric", list(METRICS))
def test_surface_and_contour_figures_show_the_model_and_the_runs(fitted, dataset, metric):
    """Figures 6-9 (a) and the contour map: the speeds' ranges on the axes, 35 training and 10
    test runs plotted where they were run, the colour bar spanning the model's predictions over
    the grid (the surface: its faces', each coloured by its corners' mean; the contours: to within
    one contour level)."""
    from analysis.viz.maps import contour_figure, surface_figure
    model, scores = fitted
    split = (np.array(scores["split"]["train"]), np.array(scores["split"]["test"]))
    Z = _hand_grid(model, 11)[metric]
    runs = dataset[["omega_rad_s", "U_mm_s"]].to_numpy()

    surface = surface_figure(model, dataset, split, metric, n=11)
    ax = surface.axes[0]
    assert -24 < ax.get_xlim()[0] <= -20 and 20 <= ax.get_xlim()[1] < 24      # omega across (3-D margins)
    assert 34 < ax.get_ylim()[0] <= 40 and 100 <= ax.get_ylim()[1] < 106      # U along the depth
    assert ax.get_zlim()[0] <= min(Z.min(), dataset[metric].min())
    assert ax.get_zlim()[1] >= max(Z.max(), dataset[metric].max())
    assert len(_runs(ax, "training runs")) == 35 and len(_runs(ax, "test runs")) == 10
    faces = (Z[:-1, :-1] + Z[1:, :-1] + Z[:-1, 1:] + Z[1:, 1:]) / 4      # a face is coloured by its corners' mean
    assert _colour_bar(surface) == pytest.approx((faces.min(), faces.max()), rel=1e-9)

    contour = contour_figure(model, dataset, split, metric, n=11)
    ax = contour.axes[0]
    assert ax.get_xlim() == (-20, 20) and ax.get_ylim() == (40, 100)
    assert np.array_equal(_runs(ax, "simulated training runs"), runs[split[0]])
    assert np.array_equal(_runs(ax, "simulated test runs"), runs[split[1]])
    levels = next(c for c in ax.collections if c.get_label() != "_nolegend_"
                  and hasattr(c, "levels")).levels
    assert _colour_bar(contour) == pytest.approx((levels[0], levels[-1]))
    assert levels[0] <= Z.min() < levels[1] and levels[-2] < Z.max() <= levels[-1]


def test_parity_figure_plots_each_run_at_its_simulated_and_predicted_values(fitted, dataset):
    from analysis.viz.maps import parity_figure
    model, scores = fitted
    split = (np.array(scores["split"]["train"]), np.array(scores["split"]["test"]))
    predicted = model.predict(inputs_of(dataset))
    fig = parity_figure(dataset, predicted, split, "roughness_um")
    sim, pred = dataset["roughness_um"].to_numpy(), predicted[:, 2]
    lo, hi = min(sim.min(), pred.min()), max(sim.max(), pred.max())
    assert len(fig.axes) == 2
    for ax, rows, name in zip(fig.axes, split, ("Training", "Test")):
        assert np.allclose(_runs(ax, f"{len(rows)} runs"), np.column_stack([sim[rows], pred[rows]]))
        assert ax.get_title() == f"{name}: R = {np.corrcoef(sim[rows], pred[rows])[0, 1]:.3f}"
        assert ax.get_xlim() == ax.get_ylim() == pytest.approx((lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)))


def test_process_map_figure_draws_the_runs_and_lines_at_hand_computed_indices(fitted, dataset):
    """Figure 10: the runs at their simulated metrics normalised by the model's maxima over the
    101 x 101 grid, the iso-U line of 70 mm/s at the model's indices along omega, both axes from 0."""
    from analysis.viz.maps import process_map_figure
    model, scores = fitted
    split = (np.array(scores["split"]["train"]), np.array(scores["split"]["test"]))
    fig = process_map_figure(model, dataset, split, n=101)
    ax = fig.axes[0]
    top = {m: z.max() for m, z in _hand_grid(model, 101).items()}
    t = dataset["throughput_mm2_s"] / top["throughput_mm2_s"] * dataset["mass_g"] / top["mass_g"]
    d = dataset["roughness_um"] / top["roughness_um"] * dataset["porosity_pct"].clip(lower=0) / top["porosity_pct"]
    runs = np.column_stack([t, d])
    assert np.allclose(_runs(ax, "simulated runs (training)"), runs[split[0]])
    assert np.allclose(_runs(ax, "simulated runs (test)"), runs[split[1]])
    lines = [line.get_xydata() for line in ax.get_lines() if len(line.get_xydata()) > 2]
    assert len(lines) == 5 + 9
    omega = np.linspace(-20, 20, 101)
    pred = model.predict(np.column_stack([np.full(101, 70.0), omega]))
    iso_70 = np.column_stack([pred[:, 1] / top["throughput_mm2_s"] * pred[:, 0] / top["mass_g"],
                              pred[:, 2] / top["roughness_um"] * np.clip(pred[:, 3], 0, None) / top["porosity_pct"]])
    assert sum(np.allclose(line, iso_70) for line in lines) == 1
    assert ax.get_xlim()[0] == 0 and ax.get_xlim()[1] >= max(runs[:, 0].max(), max(li[:, 0].max() for li in lines))
    assert ax.get_ylim()[0] == 0 and ax.get_ylim()[1] >= max(runs[:, 1].max(), max(li[:, 1].max() for li in lines))


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
    fig = window_figure(model, df, split, {"max_porosity_pct": 8, "max_roughness_um": 60}, n=121)
    best = fig.recommended[0]
    assert (best["U_mm_s"], best["omega_rad_s"]) == pytest.approx((found["U_mm_s"], found["omega_rad_s"]))
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert any(label.startswith("recommended: U = ") for label in labels)
    assert "90 % of runs" in fig.axes[0].get_title()
    none = window_figure(model, df, split, {"max_roughness_um": 1.0}, n=21)      # R_q <= 1 um: nowhere
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


# --- the layer-structure metrics beside the four ------------------------------------------------

@pytest.fixture(scope="module")
def layered():
    """GPs of the four metrics and of the void fraction and coverage (2 % noise), calibrated by hand and
    stacked as the surrogate rule stacks them; and their runs."""
    df = structured_dataset(1, noise=0.02)
    X, rng = inputs_of(df), np.random.default_rng(0)
    four = CalibratedSurrogate(GPSurrogate(n_restarts=0).fit(X, targets_of(df)), np.ones(6), np.full(6, 0.02),
                               np.abs(rng.standard_normal((45, 6))), 45, 0.9, "by hand")
    layer = with_structure_metrics(df)[list(STRUCTURE_METRICS)].to_numpy()
    structure = CalibratedSurrogate(GPSurrogate(n_restarts=0).fit(X, layer), np.ones(2), np.full(2, 0.02),
                                    np.abs(rng.standard_normal((45, 2))), 45, 0.9, "by hand", list(STRUCTURE_METRICS))
    return CalibratedStack([four, structure]), df


def test_render_maps_draws_the_structure_metrics_like_the_four(layered, tmp_path):
    from matplotlib.image import imread
    model, df = layered
    split = split_runs(df, 10, 0)
    window = {"max_porosity_pct": None, "max_roughness_um": None, "max_void_fraction_pct": 33.0,
              "min_coverage_pct": 80.0}
    paths = render_maps(model, df, split, tmp_path, n=11, window=window)
    names = {p.name for p in paths}
    for m in (*METRICS, *STRUCTURE_METRICS):
        assert {f"{m}_{kind}.png" for kind in ("surface", "contour", "interval", "parity")} <= names
    assert imread(tmp_path / "void_fraction_pct_surface.png").shape[:2] == (975, 1200)
    # the void fraction's parity plot: R of the test runs from the stacked model's fifth column
    sim = with_structure_metrics(df)["void_fraction_pct"].to_numpy()
    pred = model.predict(inputs_of(df))[:, 4]
    svg = (tmp_path / "void_fraction_pct_parity.svg").read_text()
    assert f"Test: R = {np.corrcoef(sim[split[1]], pred[split[1]])[0, 1]:.3f}" in svg


def test_structure_surface_spans_its_own_predictions(layered):
    from analysis.viz.maps import surface_figure
    model, df = layered
    points = with_structure_metrics(df)
    fig = surface_figure(model, points, split_runs(df, 10, 0), "coverage_pct", n=11)
    ax = fig.axes[0]
    assert ax.get_zlabel() == "$C$ (%)" and ax.get_title().startswith("Substrate covered by the spread layer")
    UU, WW = np.meshgrid(np.linspace(40, 100, 11), np.linspace(-20, 20, 11), indexing="ij")
    Z = model.predict(np.column_stack([UU.ravel(), WW.ravel()]))[:, 5]
    assert ax.get_zlim()[0] <= min(Z.min(), points["coverage_pct"].min())
    assert ax.get_zlim()[1] >= max(Z.max(), points["coverage_pct"].max())


def test_operating_window_with_a_coverage_and_a_void_fraction_limit(layered):
    from analysis.surrogate.recommend import recommend
    from analysis.viz.contours import window_figure
    model, df = layered
    split = split_runs(df, 10, 0)
    meta = {"input_range": {"U_mm_s": [40.0, 100.0], "omega_rad_s": [-20.0, 20.0]}}
    limits = {"max_void_fraction_pct": 36.0, "min_coverage_pct": 80.0}
    found = recommend(model, meta, n=121, **limits)
    fig = window_figure(model, df, split, limits, n=121)
    best = fig.recommended[0]
    assert (best["U_mm_s"], best["omega_rad_s"]) == pytest.approx((found["U_mm_s"], found["omega_rad_s"]))
    assert found["coverage_pct_lo"] >= 80.0 and found["void_fraction_pct_hi"] <= 36.0
    # coverage 1 - 0.5 / (1 + exp(-(omega - 5)/4)) >= 0.8 only below omega = 5 - 4 ln(1.5) = 3.4 rad/s
    assert found["omega_rad_s"] < 3.4
    title = fig.axes[0].get_title()
    assert r"$\varepsilon$ ≤ 36 %" in title and "$C$ ≥ 80 %" in title
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "coverage limit" in labels and any(r"$\varepsilon$ = " in label for label in labels)
