"""Figures of the surrogate: regressed surfaces, parity plots and the process map.

Reproduces the paper's Figures 6-9 (a: the regressed surface of each metric
over the spreader speeds with the training runs in blue and the test runs in
black; b, c: simulated against predicted values with the correlation
coefficient R) and Figure 10 (the spreading process map: the defect index
R_q/max(R_q) * Phi/max(Phi) against the throughput index
Q_s/max(Q_s) * M_s/max(M_s), with iso-U and iso-omega lines of the
surrogate).  Figures are drawn on matplotlib's Agg canvas (pyplot is never
imported, so no display is needed) and written as PNG and SVG.

Beyond the paper: with replicates the points drawn are the replicate means
(with their seed-to-seed range), and when the surrogate gives calibrated
intervals (:func:`analysis.surrogate.predict.provides_intervals`) each regressed
surface gets a companion map of the half-width of its single-run interval
(``<metric>_interval``) and the process map draws the indices' single-run
intervals as crosses along its iso-lines, the coverage level in each caption.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from analysis.config import variant_path
from analysis.io import atomic_path
from analysis.metrics.dataset import INPUTS, METRICS, input_columns, point_means
from analysis.surrogate.data import inputs_of
from analysis.surrogate.predict import (
    hybrid_indices,
    index_intervals,
    metric_maxima,
    predict_frame,
    predict_grid,
    provides_intervals,
)
from analysis.surrogate.scores import pearson_r

#: Axis labels with units (matplotlib mathtext).
LABELS = {
    "U_mm_s": "$U$ (mm/s)",
    "omega_rad_s": r"$\omega$ (rad/s)",
    "mass_g": "$M_s$ (g)",
    "throughput_mm2_s": "$Q_s$ (mm$^2$/s)",
    "roughness_um": r"$R_q$ ($\mu$m)",
    "porosity_pct": r"$\Phi$ (%)",
}


TITLES = {
    "mass_g": "Powder mass in the sampling region",
    "throughput_mm2_s": "Spread throughput",
    "roughness_um": "Spread layer roughness",
    "porosity_pct": "Spread layer porosity",
}


FORMATS = ("png", "svg")


_STYLE = {"font.size": 11, "axes.titlesize": 12, "axes.labelsize": 11, "savefig.dpi": 150}


_TRAIN, _TEST = "blue", "black"


def _figure(**kwargs):
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, outdir, stem):
    """Write ``fig`` as ``<outdir>/<stem>.png`` and ``.svg`` (atomically); return the paths."""
    paths = []
    for fmt in FORMATS:
        path = Path(outdir) / f"{stem}.{fmt}"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt)
        paths.append(path)
    return paths


def supply_limited(df):
    """Boolean mask of the runs whose heap ran dry before the region's end (kept only
    with ``keep_supply_limited_runs``): their M_s and Q_s are lower bounds."""
    if "heap_exhausted" not in df:
        return np.zeros(len(df), dtype=bool)
    return df["heap_exhausted"].astype(str).str.lower().eq("true").to_numpy()


def surface_figure(model, df, split, metric, n=41):
    """The regressed surface of one metric over (omega, U), as the paper's Figures 6-9 (a).

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    df : pandas.DataFrame
        The simulated runs (speeds and metrics).
    split : (array of int, array of int)
        Row positions of the training and test runs.
    metric : str
        One of :data:`analysis.surrogate.data.METRICS`.
    n : int
        Surface grid points per axis, over the runs' speed range.

    Returns
    -------
    matplotlib.figure.Figure
    """
    X = inputs_of(df)
    grid = predict_grid(model, (X[:, 0].min(), X[:, 0].max()), (X[:, 1].min(), X[:, 1].max()), n)
    shape = (n, n)
    U, omega, Z = (grid[c].to_numpy().reshape(shape) for c in ("U_mm_s", "omega_rad_s", metric))

    fig = _figure(figsize=(8.0, 6.5))
    ax = fig.add_subplot(projection="3d")
    ax.set_box_aspect(None, zoom=0.85)
    surf = ax.plot_surface(omega, U, Z, cmap="turbo", alpha=0.8, linewidth=0,
                           antialiased=True, rasterized=True)
    for rows, colour, label in ((split[0], _TRAIN, "training runs"), (split[1], _TEST, "test runs")):
        ax.scatter(X[rows, 1], X[rows, 0], df[metric].to_numpy(float)[rows], color=colour,
                   s=22, depthshade=False, label=f"{label} ({len(rows)})")
    limited = supply_limited(df)
    if limited.any():
        ax.scatter(X[limited, 1], X[limited, 0], df[metric].to_numpy(float)[limited], facecolor="none",
                   edgecolor="tab:red", s=90, linewidth=1.5, depthshade=False,
                   label=f"supply-limited: a lower bound ({limited.sum()})")
    _replicate_ranges(ax, df, metric)
    ax.set_xlabel(LABELS["omega_rad_s"], labelpad=8)
    ax.set_ylabel(LABELS["U_mm_s"], labelpad=8)
    ax.zaxis.set_rotate_label(False)
    ax.set_zlabel(LABELS[metric], labelpad=12, rotation=90)
    ax.view_init(elev=25, azim=-125)
    ax.set_title(f"{TITLES[metric]}: regressed surface")
    ax.legend(loc="upper left", fontsize=9)
    fig.colorbar(surf, ax=ax, shrink=0.6, pad=0.02, label=LABELS[metric])
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.04, top=0.94)
    return fig


def _replicate_ranges(ax, points, metric):
    """Vertical +-1 seed-to-seed std segments at replicated points (3-D axes)."""
    if f"{metric}_sd" not in points or not (points[f"{metric}_sd"] > 0).any():
        return
    rep = points[points[f"{metric}_sd"] > 0]
    mean, sd = rep[metric].to_numpy(float), rep[f"{metric}_sd"].to_numpy(float)
    for w, u, lo, hi in zip(rep["omega_rad_s"], rep["U_mm_s"], mean - sd, mean + sd):
        ax.plot([w, w], [u, u], [lo, hi], color="0.3", lw=1)


def interval_figure(model, df, split, metric, n=41):
    """Companion of the regressed surface: the half-width of the calibrated single-run interval.

    Parameters
    ----------
    model : estimator
        Fitted surrogate with calibrated intervals
        (:func:`analysis.surrogate.predict.provides_intervals`).
    df : pandas.DataFrame
        The simulated points (replicate means), for the range and the markers.
    split : (array of int, array of int)
        Positions of the training and test points in ``df``.
    metric : str
        One of METRICS.
    n : int
        Grid points per axis.

    Returns
    -------
    matplotlib.figure.Figure
        Filled contours over (omega, U) of half the width of the interval a single
        new run falls in at the model's confidence (metric units), the training
        (blue) and test (black) points on top; the caption names the level and method.
    """
    X = inputs_of(df)
    grid = predict_grid(model, (X[:, 0].min(), X[:, 0].max()), (X[:, 1].min(), X[:, 1].max()), n)
    U, omega = (grid[c].to_numpy().reshape(n, n) for c in ("U_mm_s", "omega_rad_s"))
    half = ((grid[f"{metric}_hi"] - grid[f"{metric}_lo"]) / 2).to_numpy().reshape(n, n)
    level = _level(model)
    fig = _figure(figsize=(7.5, 6.2), layout="constrained")
    ax = fig.add_subplot()
    if not np.isfinite(half).all():        # too few calibration runs for this level
        ax.text(0.5, 0.5, _too_few(model), ha="center", va="center", transform=ax.transAxes, wrap=True)
        ax.set(xlabel=LABELS["omega_rad_s"], ylabel=LABELS["U_mm_s"], title=f"{TITLES[metric]}: no {level} interval")
        return fig
    filled = ax.contourf(omega, U, half, levels=14, cmap="viridis")
    for rows, colour, marker, label in ((split[0], _TRAIN, "o", "training runs"),
                                        (split[1], _TEST, "s", "test runs")):
        ax.scatter(X[rows, 1], X[rows, 0], color=colour, edgecolor="white", marker=marker,
                   s=30, label=f"{label} ({len(rows)})")
    ax.set(xlabel=LABELS["omega_rad_s"], ylabel=LABELS["U_mm_s"],
           title=f"{TITLES[metric]}: {level} single-run interval")
    fig.colorbar(filled, ax=ax, label=f"half-width of the {level} interval of {LABELS[metric]}")
    ax.legend(loc="upper left", fontsize=8, framealpha=0.8)
    _caption(fig, f"{level} of new DEM runs fall within the prediction +- this (calibrated by grouped "
             "cross-conformal prediction on held-out runs; run-to-run noise included)")
    return fig


def _caption(fig, text, width=95):
    """A small caption under the axes, wrapped; the constrained layout makes room for it."""
    fig.supxlabel(textwrap.fill(text, width, break_on_hyphens=False), fontsize=8, ha="center")


def _too_few(model):
    return (f"{model.n_runs} held-out runs calibrate no finite {_level(model)} interval "
            f"(at least {model.runs_needed()} needed)")


def _level(model):
    """The model's interval coverage as text, e.g. '90 %'."""
    return f"{100 * model.confidence:g} %"


def parity_figure(df, predicted, split, metric):
    """Simulated against predicted values of one metric, training and test (Figures 6-9 b, c).

    Parameters
    ----------
    df : pandas.DataFrame
        The simulated runs.
    predicted : numpy.ndarray, shape (n, 4)
        Surrogate predictions for the runs, columns in METRICS order.
    split : (array of int, array of int)
        Row positions of the training and test runs.
    metric : str
        One of METRICS.

    Returns
    -------
    matplotlib.figure.Figure
        Two panels, each with the 1:1 line and R in its title.
    """
    j = list(METRICS).index(metric)
    sim, pred = df[metric].to_numpy(float), predicted[:, j]
    lo, hi = min(sim.min(), pred.min()), max(sim.max(), pred.max())
    pad = 0.05 * (hi - lo or 1.0)
    fig = _figure(figsize=(10.0, 4.8), layout="constrained")
    for ax, rows, colour, name in zip(fig.subplots(1, 2), split, (_TRAIN, _TEST),
                                      ("Training", "Test")):
        r = pearson_r(sim[rows, None], pred[rows, None])[0]
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.5", lw=1, label="1:1")
        ax.scatter(sim[rows], pred[rows], color=colour, s=25, label=f"{len(rows)} runs")
        if f"{metric}_sd" in df and (df[f"{metric}_sd"] > 0).any():
            ax.errorbar(sim[rows], pred[rows], xerr=df[f"{metric}_sd"].to_numpy(float)[rows],
                        fmt="none", ecolor=colour, alpha=0.5, lw=1)
        ax.set(xlim=(lo - pad, hi + pad), ylim=(lo - pad, hi + pad), aspect="equal",
               xlabel=f"simulated {LABELS[metric]}", ylabel=f"predicted {LABELS[metric]}",
               title=f"{name}: R = {r:.3f}")
        ax.legend(loc="upper left")
    fig.suptitle(TITLES[metric])
    return fig


def process_map_lines(model, U_values, omega_values, maxima, n=101):
    """Iso-U and iso-omega lines of the surrogate in hybrid-index space.

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    U_values, omega_values : sequence of float
        The swept speeds (mm/s, rad/s); one line per value, running over the
        range of the other speed.
    maxima : dict
        Metric maxima to normalise by (:func:`analysis.surrogate.predict.metric_maxima`).
    n : int
        Points per line.

    Returns
    -------
    pandas.DataFrame
        Columns ``family`` ('U' or 'omega'), ``value`` (the fixed speed),
        U_mm_s, omega_rad_s, the metrics, ``throughput_index``, ``defect_index``.
    """
    U_values, omega_values = np.asarray(U_values, float), np.asarray(omega_values, float)
    sweep_U = np.linspace(U_values.min(), U_values.max(), n)
    sweep_omega = np.linspace(omega_values.min(), omega_values.max(), n)
    U = np.r_[np.repeat(U_values, n), np.tile(sweep_U, omega_values.size)]
    omega = np.r_[np.tile(sweep_omega, U_values.size), np.repeat(omega_values, n)]
    lines = predict_frame(model, U, omega)
    lines.insert(0, "family", np.repeat(["U", "omega"], [U_values.size * n, omega_values.size * n]))
    lines.insert(1, "value", np.r_[np.repeat(U_values, n), np.repeat(omega_values, n)])
    lines["throughput_index"], lines["defect_index"] = hybrid_indices(lines, maxima)
    return lines


def iso_values(df, n_U=5, n_omega=9):
    """Speeds of the process map's iso-lines: the design's own if it is a full grid, else
    ``n_U`` and ``n_omega`` evenly spaced values over its range (mm/s, rad/s)."""
    U, omega = (np.unique(df[c].to_numpy(float)) for c in INPUTS)
    n_points = len(np.unique(df[list(INPUTS)].to_numpy(float), axis=0))
    if U.size * omega.size == n_points and U.size <= 15 and omega.size <= 15:
        return U, omega
    return (np.round(np.linspace(U.min(), U.max(), n_U), 1),
            np.round(np.linspace(omega.min(), omega.max(), n_omega), 2))


def process_map_figure(model, df, split, n=101):
    """The spreading process map of the paper's Figure 10.

    The metric maxima are those of the surrogate on an n x n grid over the
    swept range; the iso-lines and the simulated runs are normalised by them.

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    df : pandas.DataFrame
        The simulated points; its distinct U and omega are the iso-line values
        when they form a full grid (:func:`iso_values`).
    split : (array of int, array of int)
        Row positions of the training and test runs.
    n : int
        Grid points per axis and points per line.

    Returns
    -------
    matplotlib.figure.Figure
    """
    U_values, omega_values = iso_values(df)
    maxima = metric_maxima(predict_grid(model, (U_values.min(), U_values.max()),
                                        (omega_values.min(), omega_values.max()), n))
    lines = process_map_lines(model, U_values, omega_values, maxima, n)
    runs_t, runs_d = hybrid_indices(df, maxima)
    with_intervals = provides_intervals(model) and model.is_finite()
    if with_intervals:
        index_intervals(lines, maxima)

    fig = _figure(figsize=(8.0, 6.5), layout="constrained")
    ax = fig.add_subplot()
    # colour, label, where it goes (above the line's end with the least omega /
    # right of the end with the greatest U), legend entry
    styles = {"U": ("tab:blue", "U = {:g} mm/s", "omega_rad_s", -1,
                    dict(xytext=(0, 6), ha="center", va="bottom"), "iso-U lines"),
              "omega": ("tab:red", "ω = {:g} rad/s", "U_mm_s", 1,
                        dict(xytext=(6, 0), ha="left", va="center"), "iso-ω lines")}
    labelled = set()
    for (family, value), line in lines.groupby(["family", "value"], sort=False):
        colour, fmt, along, sign, place, legend = styles[family]
        ax.plot(line["throughput_index"], line["defect_index"], color=colour, lw=1.2,
                label=None if family in labelled else legend)
        labelled.add(family)
        if with_intervals:     # single-run interval crosses at every 10th point of the line
            every = line.iloc[::10]
            t, d = every["throughput_index"], every["defect_index"]
            ax.errorbar(t, d, xerr=[t - every["throughput_index_lo"], every["throughput_index_hi"] - t],
                        yerr=[d - every["defect_index_lo"], every["defect_index_hi"] - d],
                        fmt="none", ecolor=colour, alpha=0.35, lw=1,
                        label=None if "interval" in labelled else f"{_level(model)} single-run interval")
            labelled.add("interval")
        end = line.loc[(sign * line[along]).idxmax()]
        ax.annotate(fmt.format(value), (end["throughput_index"], end["defect_index"]),
                    textcoords="offset points", color=colour, fontsize=8, **place)
    ax.scatter(runs_t[split[0]], runs_d[split[0]], facecolor="white", edgecolor="k", s=28,
               zorder=3, label="simulated runs (training)")
    ax.scatter(runs_t[split[1]], runs_d[split[1]], color="k", s=28, zorder=3,
               label="simulated runs (test)")
    limited = supply_limited(df)
    if limited.any():
        ax.scatter(np.asarray(runs_t)[limited], np.asarray(runs_d)[limited], facecolor="none", edgecolor="tab:red",
                   s=80, linewidth=1.5, zorder=4, label="supply-limited run (heap ran dry)")
    ax.set_xlabel(r"throughput index  $Q_s/\max(Q_s)\cdot M_s/\max(M_s)$")
    ax.set_ylabel(r"defect index  $R_q/\max(R_q)\cdot \Phi/\max(\Phi)$")
    ax.margins(x=0.15, y=0.06)   # room for the line labels
    ax.set_title("Spreading process map")
    ax.legend(loc="best", fontsize=9)
    ax.grid(alpha=0.3)
    if with_intervals:
        _caption(fig, f"Crosses: the {_level(model)} interval of the indices of a single new run "
                 "(calibrated by grouped cross-conformal prediction on held-out runs; run-to-run noise included)")
    elif provides_intervals(model):
        _caption(fig, f"No interval crosses: {_too_few(model)}")
    return fig


class HeldInputs:
    """A fitted surrogate of more inputs than the speeds, seen over (U, omega) alone: its other
    inputs (swept config keys) held at ``values`` (``{input: value}``, the model's order, config units).

    ``predict``, ``half_widths`` and ``predict_interval`` take (n, 2) speeds; everything else
    (``confidence``, ``is_finite``, ...) is the model's.
    """

    def __init__(self, model, values):
        self.model, self.values = model, dict(values)

    def _full(self, X):
        X = np.asarray(X, float)
        return np.column_stack([X, *(np.full(len(X), float(v)) for v in self.values.values())])

    def predict(self, X, return_std=False):
        return self.model.predict(self._full(X), return_std=True) if return_std else self.model.predict(self._full(X))

    def __getattr__(self, name):
        attr = getattr(self.model, name)    # half_widths, predict_interval: only if the model has intervals
        if name in ("half_widths", "predict_interval"):
            return lambda X, *args, **kwargs: attr(self._full(X), *args, **kwargs)
        return attr


def render_maps(model, df, split, outdir, n=41):
    """Write every figure: surfaces, parity plots, process map (and uncertainty maps); with
    inputs beyond the speeds (a sweep's extra axes), one set per combination of their swept
    values, in ``<outdir>/<axis>=<value>/...`` (:func:`analysis.config.variant_path`), the
    other inputs held there (:class:`HeldInputs`).

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    df : pandas.DataFrame
        The simulated runs it was fitted on (replicates are drawn as their
        mean, :func:`analysis.surrogate.data.point_means`).
    split : (array of int, array of int)
        Row positions of the training and test runs.
    outdir : str or pathlib.Path
        Created if missing.
    n : int
        Grid points per axis of the surfaces (the process map uses
        ``max(n, 101)`` points per line).

    Returns
    -------
    list of pathlib.Path
        ``<metric>_surface.{png,svg}``, ``<metric>_parity.{png,svg}`` (with extra axes: once,
        over every point, in ``outdir``; the rest per slice) and,
        when the model gives calibrated intervals, ``<metric>_interval.{png,svg}`` per
        metric (metric = dataset column, e.g. ``mass_g``), then
        ``process_map.{png,svg}``.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    points, split = point_means(df, tuple(np.asarray(rows, int) for rows in split))
    extra = input_columns(df)[len(INPUTS):]
    if not extra:
        return _render_slice(model, points, split, outdir, n, parity=model.predict(inputs_of(points)))
    paths = []
    with matplotlib.rc_context(_STYLE):     # parity plots: every point, once
        predicted = model.predict(inputs_of(points))
        for metric in METRICS:
            paths += save_figure(parity_figure(points, predicted, split, metric), outdir, f"{metric}_parity")
    for values, rows in points.groupby(extra, sort=True).indices.items():
        values = dict(zip(extra, np.atleast_1d(values)))
        in_slice = np.isin(np.arange(len(points)), rows)
        sub_split = tuple(np.flatnonzero(np.isin(np.flatnonzero(in_slice), part)) for part in split)
        sub = points[in_slice].reset_index(drop=True)
        paths += _render_slice(HeldInputs(model, values), sub, sub_split, outdir / variant_path(values), n)
    return paths


def _render_slice(model, points, split, outdir, n, parity=None):
    """The figures of :func:`render_maps` over (U, omega) for ``points`` into ``outdir``; the
    parity plots too when given the predictions at the points (``parity``, shape (n, 4))."""
    Path(outdir).mkdir(parents=True, exist_ok=True)
    paths = []
    with matplotlib.rc_context(_STYLE):
        for metric in METRICS:
            paths += save_figure(surface_figure(model, points, split, metric, n), outdir,
                                 f"{metric}_surface")
            if parity is not None:
                paths += save_figure(parity_figure(points, parity, split, metric), outdir,
                                     f"{metric}_parity")
            if provides_intervals(model):
                paths += save_figure(interval_figure(model, points, split, metric, n), outdir,
                                     f"{metric}_interval")
        paths += save_figure(process_map_figure(model, points, split, max(n, 101)), outdir,
                             "process_map")
    return paths
