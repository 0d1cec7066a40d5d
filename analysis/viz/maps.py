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

import itertools
import textwrap
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from analysis.columns import INPUTS, METRICS, SHORT_NAMES, input_columns, input_units
from analysis.config import variant_path
from analysis.io import atomic_path
from analysis.metrics.dataset import point_means
from analysis.surrogate.data import inputs_of
from analysis.surrogate.predict import (
    hybrid_indices,
    index_intervals,
    metric_maxima,
    predict_frame,
    provides_intervals,
    with_indices,
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



#: Short symbols of the speeds for the iso-line labels; a swept config key is named by its path.
SYMBOLS = {"U_mm_s": "U", "omega_rad_s": "ω"}


def axis_label(name):
    """Axis label of an input or metric with its unit: LABELS, else ``roller.gap_um (um)``."""
    if name in LABELS:
        return LABELS[name]
    unit = input_units([name])[name]
    return f"{name} ({unit})" if unit else name


@dataclass(frozen=True)
class MapView:
    """The two inputs a map spans and the values the model's other inputs are held at.

    Attributes
    ----------
    axes : (str, str)
        (y, x): the paper's ``("U_mm_s", "omega_rad_s")``: U along the surface's depth and the
        interval map's height, omega across; any two of ``inputs``.
    inputs : tuple of str
        The model's inputs in its order (:func:`analysis.columns.input_columns`).
    held : tuple of (str, float)
        The value of every other input, in its units.
    """
    axes: tuple = tuple(INPUTS)
    inputs: tuple = tuple(INPUTS)
    held: tuple = ()

    def frame(self, model, y, x, confidence=None):
        """Predictions (:func:`analysis.surrogate.predict.predict_frame`) at ``(y[i], x[i])``."""
        y = np.asarray(y, float)
        cols = {self.axes[0]: y, self.axes[1]: np.asarray(x, float),
                **{k: np.full(y.shape, float(v)) for k, v in self.held}}
        return predict_frame(model, cols["U_mm_s"], cols["omega_rad_s"], confidence,
                             {c: cols[c] for c in self.inputs[2:]})

    def grid(self, model, y_range, x_range, n):
        """An n x n grid over the two axes (y outer), the hybrid indices normalised over it
        (:func:`analysis.surrogate.predict.with_indices`); columns as :func:`predict_grid`'s."""
        y, x = (a.ravel() for a in np.meshgrid(np.linspace(*y_range, int(n)), np.linspace(*x_range, int(n)),
                                               indexing="ij"))
        return with_indices(model, self.frame(model, y, x))

    def ranges(self, points):
        """(y range, x range) of the two axes over ``points``."""
        return tuple((float(points[a].min()), float(points[a].max())) for a in self.axes)

    def title(self):
        """The held inputs as text ('' for none): 'roller.gap_um = 350 um'."""
        units = input_units([k for k, _ in self.held])
        return ", ".join(f"{SYMBOLS.get(k, k)} = {v:g} {units[k]}".rstrip() for k, v in self.held)


def _panels(view, df, split):
    """A one-panel list (view, points, split) when called with a plain (U, omega) figure's arguments."""
    return [(view or MapView(inputs=tuple(input_columns(df))), df, split)]


def _panel_grids(model, df, split, view, panels, n, metric):
    """The panels (:func:`_panels` unless given), each one's n x n grid, and ``metric``'s range over all."""
    panels = panels or _panels(view, df, split)
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    return panels, grids, (min(g[metric].min() for g in grids), max(g[metric].max() for g in grids))


def _grid_fig(k, kind, **kwargs):
    """A figure of ``k`` panels side by side (3-D axes for ``kind`` '3d'); returns (fig, axes)."""
    width, height = kwargs.pop("size")
    fig = _figure(figsize=(width * (1 + 0.85 * (k - 1)), height), **kwargs)
    axes = [fig.add_subplot(1, k, i + 1, **({"projection": "3d"} if kind == "3d" else {})) for i in range(k)]
    return fig, axes


def surface_figure(model, df, split, metric, n=41, view=None, panels=None):
    """The regressed surface of one metric over two inputs, as the paper's Figures 6-9 (a).

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    df : pandas.DataFrame
        The simulated points (inputs and metrics).
    split : (array of int, array of int)
        Row positions of the training and test points.
    metric : str
        One of :data:`analysis.surrogate.data.METRICS`.
    n : int
        Surface grid points per axis, over the points' range.
    view : MapView, optional
        The two inputs (default: U and omega) and the others' values.
    panels : list of (MapView, DataFrame, split), optional
        Side by side instead of ``view, df, split`` (small multiples; one colour scale).

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels, grids, (lo, hi) = _panel_grids(model, df, split, view, panels, n, metric)
    fig, axes = _grid_fig(len(panels), "3d", size=(8.0, 6.5))
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        (ya, xa), shape = v.axes, (n, n)
        Y, X, Z = (grid[c].to_numpy().reshape(shape) for c in (ya, xa, metric))
        ax.set_box_aspect(None, zoom=0.85)
        surf = ax.plot_surface(X, Y, Z, cmap="turbo", alpha=0.8, linewidth=0, antialiased=True, rasterized=True,
                               **({"vmin": lo, "vmax": hi} if len(panels) > 1 else {}))  # panels: one scale
        x, y, z = (pts[c].to_numpy(float) for c in (xa, ya, metric))
        for rows, colour, label in ((part[0], _TRAIN, "training runs"), (part[1], _TEST, "test runs")):
            ax.scatter(x[rows], y[rows], z[rows], color=colour, s=22, depthshade=False,
                       label=f"{label} ({len(rows)})")
        limited = supply_limited(pts)
        if limited.any():
            ax.scatter(x[limited], y[limited], z[limited], facecolor="none", edgecolor="tab:red", s=90,
                       linewidth=1.5, depthshade=False, label=f"supply-limited: a lower bound ({limited.sum()})")
        _replicate_ranges(ax, pts, metric, v.axes)
        ax.set_xlabel(axis_label(xa), labelpad=8)
        ax.set_ylabel(axis_label(ya), labelpad=8)
        ax.zaxis.set_rotate_label(False)
        ax.set_zlabel(LABELS[metric], labelpad=12, rotation=90)
        ax.view_init(elev=25, azim=-125)
        ax.set_title(f"{TITLES[metric]}: regressed surface" + (f"\n{v.title()}" if v.title() else ""))
        ax.legend(loc="upper left", fontsize=9)
    fig.colorbar(surf, ax=axes if len(axes) > 1 else axes[0], shrink=0.6, pad=0.02, label=LABELS[metric])
    if len(panels) == 1:
        fig.subplots_adjust(left=0.02, right=0.98, bottom=0.04, top=0.94)
    return fig


def _replicate_ranges(ax, points, metric, axes=tuple(INPUTS)):
    """Vertical +-1 seed-to-seed std segments at replicated points (3-D axes; ``axes`` = (y, x) inputs)."""
    if f"{metric}_sd" not in points or not (points[f"{metric}_sd"] > 0).any():
        return
    rep = points[points[f"{metric}_sd"] > 0]
    mean, sd = rep[metric].to_numpy(float), rep[f"{metric}_sd"].to_numpy(float)
    for x, y, lo, hi in zip(rep[axes[1]], rep[axes[0]], mean - sd, mean + sd):
        ax.plot([x, x], [y, y], [lo, hi], color="0.3", lw=1)


def interval_figure(model, df, split, metric, n=41, view=None, panels=None):
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
    view, panels
        As :func:`surface_figure`'s.

    Returns
    -------
    matplotlib.figure.Figure
        Filled contours over the two inputs (the paper's: omega across, U up) of half the width
        of the interval a single new run falls in at the model's confidence (metric units), the
        training (blue) and test (black) points on top; the caption names the level and method.
    """
    panels = panels or _panels(view, df, split)
    level = _level(model)
    fig, axes = _grid_fig(len(panels), "2d", size=(7.5, 6.2), layout="constrained")
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    halves = [((g[f"{metric}_hi"] - g[f"{metric}_lo"]) / 2).to_numpy().reshape(n, n) for g in grids]
    (ya, xa), titles = panels[0][0].axes, [v.title() for v, _, _ in panels]
    if not all(np.isfinite(h).all() for h in halves):      # too few calibration runs for this level
        ax = axes[0]
        ax.text(0.5, 0.5, _too_few(model), ha="center", va="center", transform=ax.transAxes, wrap=True)
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya), title=f"{TITLES[metric]}: no {level} interval")
        return fig
    levels = np.linspace(min(h.min() for h in halves), max(h.max() for h in halves), 15)
    for ax, (v, pts, part), grid, half, title in zip(axes, panels, grids, halves, titles):
        Y, X = (grid[c].to_numpy().reshape(n, n) for c in v.axes)
        filled = ax.contourf(X, Y, half, levels=levels if len(panels) > 1 else 14, cmap="viridis")
        x, y = (pts[c].to_numpy(float) for c in (xa, ya))
        for rows, colour, marker, label in ((part[0], _TRAIN, "o", "training runs"),
                                            (part[1], _TEST, "s", "test runs")):
            ax.scatter(x[rows], y[rows], color=colour, edgecolor="white", marker=marker,
                       s=30, label=f"{label} ({len(rows)})")
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya),
               title=f"{TITLES[metric]}: {level} single-run interval" + (f"\n{title}" if title else ""))
        ax.legend(loc="upper left", fontsize=8, framealpha=0.8)
    fig.colorbar(filled, ax=axes if len(axes) > 1 else axes[0],
                 label=f"half-width of the {level} interval of {LABELS[metric]}")
    _caption(fig, f"{level} of new DEM runs fall within the prediction +- this (calibrated by grouped "
             "cross-conformal prediction on held-out runs; run-to-run noise included)")
    return fig


def _run_points(ax, pts, part, axes):
    """The simulated runs on a 2-D map: training (blue circles), test (black squares), supply-limited (red rings)."""
    ya, xa = axes
    x, y = (pts[c].to_numpy(float) for c in (xa, ya))
    for rows, colour, marker, label in ((part[0], _TRAIN, "o", "training runs"), (part[1], _TEST, "s", "test runs")):
        ax.scatter(x[rows], y[rows], color=colour, edgecolor="white", marker=marker, s=30, zorder=4,
                   clip_on=False, label=f"simulated {label} ({len(rows)})")
    limited = supply_limited(pts)
    if limited.any():
        ax.scatter(x[limited], y[limited], facecolor="none", edgecolor="tab:red", s=90, linewidth=1.5, zorder=5,
                   clip_on=False, label=f"supply-limited: a lower bound ({limited.sum()})")


def contour_figure(model, df, split, metric, n=61, view=None, panels=None):
    """A metric over the two inputs as a 2-D contour map (omega across, U up), the simulated runs on it.

    Beside each 3-D surface, the map on which an operator reads the predicted value at a
    setting: filled contours with labelled contour lines of the model's mean, the
    training and test runs as points. Arguments as :func:`surface_figure`'s.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels, grids, (lo, hi) = _panel_grids(model, df, split, view, panels, n, metric)
    levels = MaxNLocator(12).tick_values(lo, hi)
    fig, axes = _grid_fig(len(panels), "2d", size=(7.5, 6.2), layout="constrained")
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        Y, X, Z = (grid[c].to_numpy().reshape(n, n) for c in (*v.axes, metric))
        filled = ax.contourf(X, Y, Z, levels=levels, cmap="viridis")
        lines = ax.contour(X, Y, Z, levels=levels[1:-1:2], colors="white", linewidths=0.7)
        ax.clabel(lines, fontsize=8, fmt="%.3g")
        _run_points(ax, pts, part, v.axes)
        ax.set(xlabel=axis_label(v.axes[1]), ylabel=axis_label(v.axes[0]),
               title=f"{TITLES[metric]} {LABELS[metric]}" + (f"\n{v.title()}" if v.title() else ""))
        ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.12), ncol=3, fontsize=8, frameon=False)
    fig.colorbar(filled, ax=axes if len(axes) > 1 else axes[0], label=f"predicted {LABELS[metric]}")
    return fig


def window_figure(model, df, split, max_porosity_pct=None, max_roughness_um=None, n=121, view=None, panels=None):
    """The operating window: the settings whose single runs meet the operator's limits, the best marked.

    A setting is in the window when the upper end of its calibrated single-run interval (at
    the model's confidence) meets every limit, the rule of :mod:`analysis.surrogate.recommend`;
    a model without finite intervals is judged on its mean, and the title says so. Over the
    window: contours of the predicted throughput Q_s, each limit's boundary, and the
    recommended setting (the highest Q_s in the window) starred with its values.

    Parameters
    ----------
    model : estimator
        Fitted surrogate, preferably with calibrated intervals.
    df, split, view, panels
        As :func:`surface_figure`'s.
    max_porosity_pct, max_roughness_um : float, optional
        The limits (%, um); None: no limit.
    n : int
        Grid points per axis.

    Returns
    -------
    matplotlib.figure.Figure
        With ``fig.recommended``: per panel the recommended setting (a dict of the inputs and
        the predicted metrics) or None when no setting meets the limits.
    """
    from analysis.surrogate.recommend import meets_limits

    panels = panels or _panels(view, df, split)
    with_intervals = provides_intervals(model) and model.is_finite()
    rule = (f"the upper end of the {_level(model)} single-run interval meets every limit" if with_intervals
            else "the predicted mean meets every limit (no finite interval: " + (
                _too_few(model) if provides_intervals(model) else "the model has no calibrated intervals") + ")")
    limits = ([] if max_porosity_pct is None else [f"$\\Phi$ ≤ {max_porosity_pct:g} %"]) + \
        ([] if max_roughness_um is None else [f"$R_q$ ≤ {max_roughness_um:g} $\\mu$m"])
    fig, axes = _grid_fig(len(panels), "2d", size=(7.8, 6.6), layout="constrained")
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    q_levels = MaxNLocator(10).tick_values(min(g["throughput_mm2_s"].min() for g in grids),
                                                              max(g["throughput_mm2_s"].max() for g in grids))
    fig.recommended = []
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        on_mean, on_interval = meets_limits(grid, max_porosity_pct, max_roughness_um, with_intervals)
        (ya, xa), shape, units = v.axes, (n, n), input_units(v.axes)
        Y, X = (grid[c].to_numpy().reshape(shape) for c in v.axes)
        inside = on_interval.reshape(shape).astype(float)
        ax.contourf(X, Y, inside, levels=[-0.5, 0.5, 1.5], colors=["0.82", "#b7e4a7"])
        q = ax.contour(X, Y, grid["throughput_mm2_s"].to_numpy().reshape(shape), levels=q_levels,
                       colors="0.35", linewidths=0.7)
        ax.clabel(q, fontsize=8, fmt="%.3g")
        for metric, limit, style in (("porosity_pct", max_porosity_pct, "--"), ("roughness_um", max_roughness_um, ":")):
            if limit is None:
                continue
            column = f"{metric}_hi" if with_intervals else metric
            edge = grid[column].to_numpy().reshape(shape)
            if edge.min() < limit < edge.max():
                ax.contour(X, Y, edge, levels=[limit], colors="k", linestyles=style, linewidths=1.4)
        handles = [Patch(color="#b7e4a7", label="operating window: " + " and ".join(limits)),
                   Patch(color="0.82", label="outside: a run there may exceed a limit" if with_intervals
                         else "outside: the predicted mean exceeds a limit"),
                   Line2D([], [], color="0.35", lw=0.7, label="predicted $Q_s$ (mm$^2$/s)")]
        handles += [Line2D([], [], color="k", ls=style, label=f"{name} limit")
                    for name, limit, style in (("porosity", max_porosity_pct, "--"),
                                               ("roughness", max_roughness_um, ":")) if limit is not None]
        best = None
        if on_interval.any():
            row = grid.loc[grid["throughput_mm2_s"].where(pd.Series(on_interval, index=grid.index)).idxmax()]
            best = {c: float(row[c]) for c in (*v.axes, *METRICS)}
            ax.scatter([best[xa]], [best[ya]], marker="*", s=260, color="gold", edgecolor="k", zorder=6, clip_on=False)
            handles.append(Line2D(
                [], [], marker="*", ms=14, color="gold", mec="k", ls="none",
                label=(f"recommended: {SYMBOLS.get(ya, ya)} = {best[ya]:.3g} {units[ya]}, "
                       f"{SYMBOLS.get(xa, xa)} = {best[xa]:.3g} {units[xa]}; "
                       f"$Q_s$ = {best['throughput_mm2_s']:.3g} mm$^2$/s, $\\Phi$ = {best['porosity_pct']:.3g} %, "
                       f"$R_q$ = {best['roughness_um']:.3g} $\\mu$m")))
        else:
            ax.text(0.5, 0.5, "no setting meets the limits\n" + ("at this confidence" if with_intervals else ""),
                    transform=ax.transAxes, ha="center", va="center", fontsize=12,
                    bbox={"facecolor": "white", "edgecolor": "0.5"})
        fig.recommended.append(best)
        _run_points(ax, pts, part, v.axes)
        run_handles, _ = ax.get_legend_handles_labels()
        ax.legend(handles=handles + run_handles, loc="upper left", bbox_to_anchor=(0.0, -0.1), fontsize=8,
                  frameon=False)
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya))
        ax.set_title(f"Operating window: {' and '.join(limits) or 'no limits'}"
                     + (f" in {_level(model)} of runs" if with_intervals else " on the mean")
                     + (f"\n{v.title()}" if v.title() else ""), pad=14)     # clear of a star on the top edge
    _caption(fig, f"In the window, {rule}: analysis.surrogate.recommend's rule ("
             "spreadmap-recommend prints the same setting from a finer grid). Limits: config maps.operating_window.")
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




def process_map_lines(model, U_values, omega_values, maxima, n=101, view=None):
    """Iso-lines of the surrogate's two map inputs in hybrid-index space.

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    U_values, omega_values : sequence of float
        The swept values of the view's two inputs (default U in mm/s and omega in rad/s); one
        line per value, running over the range of the other input.
    maxima : dict
        Metric maxima to normalise by (:func:`analysis.surrogate.predict.metric_maxima`).
    n : int
        Points per line.
    view : MapView, optional
        The two inputs and the others' values (default: U and omega).

    Returns
    -------
    pandas.DataFrame
        Columns ``family`` ('U' or 'omega' for the speeds, else the input's name), ``value``
        (the line's fixed value), the inputs, the metrics, ``throughput_index``, ``defect_index``.
    """
    view = view or MapView()
    a, b = np.asarray(U_values, float), np.asarray(omega_values, float)
    along_a, along_b = np.linspace(a.min(), a.max(), n), np.linspace(b.min(), b.max(), n)
    y = np.r_[np.repeat(a, n), np.tile(along_a, b.size)]
    x = np.r_[np.tile(along_b, a.size), np.repeat(b, n)]
    lines = view.frame(model, y, x)
    families = [SHORT_NAMES.get(c, c) for c in view.axes]
    lines.insert(0, "family", np.repeat(families, [a.size * n, b.size * n]))
    lines.insert(1, "value", np.r_[np.repeat(a, n), np.repeat(b, n)])
    lines["throughput_index"], lines["defect_index"] = hybrid_indices(lines, maxima)
    return lines


def iso_values(df, n_U=5, n_omega=9, axes=tuple(INPUTS)):
    """Values of the process map's iso-lines of the two ``axes`` (default U and omega): the points'
    own if they form a full grid over the two, else ``n_U`` and ``n_omega`` evenly spaced values over
    their range (the inputs' units)."""
    U, omega = (np.unique(df[c].to_numpy(float)) for c in axes)
    n_points = len(np.unique(df[list(axes)].to_numpy(float), axis=0))
    if U.size * omega.size == n_points and U.size <= 15 and omega.size <= 15:
        return U, omega
    return tuple(np.round(np.linspace(v.min(), v.max(), k), _DECIMALS.get(c, 4 - int(np.log10(np.ptp(v) or 1))))
                 for v, k, c in ((U, n_U, axes[0]), (omega, n_omega, axes[1])))


#: Decimals of the speeds' iso-line values off a full grid (others: 4 significant digits of their range).
_DECIMALS = {"U_mm_s": 1, "omega_rad_s": 2}


def process_map_figure(model, df, split, n=101, view=None, panels=None, note=None):
    """The spreading process map of the paper's Figure 10.

    The metric maxima are those of the surrogate on an n x n grid over the swept range (of
    every panel together, so that panels share one scale); the iso-lines and the simulated
    runs are normalised by them. Both indices start at 0 (the defect index is built from
    ``max(Phi, 0)``, :func:`analysis.surrogate.predict.hybrid_indices`); the single-run
    intervals are drawn at the simulated settings only, light and under the lines; every
    iso-line is labelled where its label overlaps no other label, no line and no run
    (:func:`place_labels`; a line with no such place keeps its colour's legend entry only).

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    df : pandas.DataFrame
        The simulated points; their distinct values of the two inputs are the iso-line values
        when they form a full grid (:func:`iso_values`).
    split : (array of int, array of int)
        Row positions of the training and test runs.
    n : int
        Grid points per axis and points per line.
    view, panels
        As :func:`surface_figure`'s.
    note : str, optional
        A sentence for the caption (e.g. which model draws the lines).

    Returns
    -------
    matplotlib.figure.Figure
        Its iso-line labels are listed in ``fig.line_labels`` (matplotlib Text artists).
    """
    panels = panels or _panels(view, df, split)
    iso = [iso_values(pts, axes=v.axes) for v, pts, _ in panels]
    grids = pd.concat([v.grid(model, (a.min(), a.max()), (b.min(), b.max()), n)
                       for (v, _, _), (a, b) in zip(panels, iso)])
    maxima = metric_maxima(grids)
    with_intervals = provides_intervals(model) and model.is_finite()
    fig, axes = _grid_fig(len(panels), "2d", size=(9.0, 6.5), layout="constrained")
    drawn = [_draw_process_map(ax, model, v, pts, part, a_values, b_values, maxima, n, with_intervals)
             for ax, (v, pts, part), (a_values, b_values) in zip(axes, panels, iso)]
    right, upper = (max(getattr(ax, get)()[1] for ax in axes) for get in ("get_xlim", "get_ylim"))
    for ax in axes:        # indices that cannot be negative start at 0; panels on one scale
        ax.set_xlim(0, right)
        ax.set_ylim(0, upper)
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0)
    caption = [note] if note else []
    if with_intervals:
        caption.append(f"Grey crosses: the {_level(model)} interval of the indices of a single new run at each "
                       "simulated setting (calibrated by grouped cross-conformal prediction on held-out runs; "
                       "run-to-run noise included)")
    elif provides_intervals(model):
        caption.append(f"No interval crosses: {_too_few(model)}")
    if caption:
        _caption(fig, ". ".join(caption))
    fig.canvas.draw()                  # the layout settles; then it is frozen, so labels placed stay put
    fig.set_layout_engine("none")
    fig.line_labels = [text for ax, (lines, runs) in zip(axes, drawn) for text in place_labels(ax, lines, runs)]
    return fig


def _draw_process_map(ax, model, view, df, split, a_values, b_values, maxima, n, with_intervals):
    """One process map into ``ax``: iso-lines of the view's two inputs, the runs, their intervals.

    Returns (the lines to label: (text, (k, 2) data points, colour), the runs' (m, 2) indices).
    """
    lines = process_map_lines(model, a_values, b_values, maxima, n, view)
    runs_t, runs_d = hybrid_indices(df, maxima)
    (ya, xa), units = view.axes, input_units(view.axes)
    label = {c: f"{SYMBOLS.get(c, c)}={{:g}}" for c in view.axes}
    legend = {c: f"iso-{SYMBOLS.get(c, c)} lines ({SYMBOLS.get(c, c)} in {units[c]})" if units[c]
              else f"iso-{SYMBOLS.get(c, c)} lines" for c in view.axes}
    first, second = lines["family"].iloc[0], lines["family"].iloc[-1]
    styles = {first: ("tab:blue", label[ya], legend[ya]), second: ("tab:red", label[xa], legend[xa])}
    labelled, to_label = set(), []
    for (family, value), line in lines.groupby(["family", "value"], sort=False):
        colour, fmt, entry = styles[family]
        ax.plot(line["throughput_index"], line["defect_index"], color=colour, lw=1.4, zorder=2,
                label=None if family in labelled else entry)
        labelled.add(family)
        to_label.append((fmt.format(value), line[["throughput_index", "defect_index"]].to_numpy(float), colour))
    if with_intervals and len(df):     # at the simulated settings only, under the lines
        at = view.frame(model, df[ya].to_numpy(float), df[xa].to_numpy(float))
        t, d = hybrid_indices(at, maxima)
        index_intervals(at, maxima)
        ax.errorbar(t, d, xerr=[t - at["throughput_index_lo"], at["throughput_index_hi"] - t],
                    yerr=[d - at["defect_index_lo"], at["defect_index_hi"] - d], fmt="none",
                    ecolor="0.6", alpha=0.45, lw=0.8, zorder=1, label=f"{_level(model)} single-run interval")
    ax.scatter(runs_t[split[0]], runs_d[split[0]], facecolor="white", edgecolor="k", s=22,
               zorder=3, label="simulated runs (training)")
    ax.scatter(runs_t[split[1]], runs_d[split[1]], color="k", s=22, zorder=3,
               label="simulated runs (test)")
    limited = supply_limited(df)
    if limited.any():
        ax.scatter(np.asarray(runs_t)[limited], np.asarray(runs_d)[limited], facecolor="none", edgecolor="tab:red",
                   s=80, linewidth=1.5, zorder=4, label="supply-limited run (heap ran dry)")
    ax.set_xlabel(r"throughput index  $Q_s/\max(Q_s)\cdot M_s/\max(M_s)$")
    ax.set_ylabel(r"defect index  $R_q/\max(R_q)\cdot \Phi^+/\max(\Phi)$,  $\Phi^+ = \max(\Phi, 0)$")
    ax.margins(x=0.12, y=0.08)   # room for the line labels
    ax.set_title("Spreading process map" + (f"\n{view.title()}" if view.title() else ""))
    ax.grid(alpha=0.3)
    return to_label, np.column_stack([runs_t, runs_d])


def _label_candidates(xy, crowd):
    """Anchor points along a line (its ends and 20 points between), the least crowded first.

    ``crowd(points)`` counts what lies near each anchor (display coordinates); at equal
    crowding an end comes first (the paper labels the lines' ends)."""
    k = len(xy) - 1
    at = np.unique(np.round(np.linspace(0, 1, 22) * k).astype(int))
    ends = (at == 0) | (at == k)
    order = np.lexsort((~ends, crowd(xy[at])))
    return [xy[i] for i in at[order]]


#: Offsets of a label from its anchor (points) and its alignment: right, left, above, below, diagonals.
_OFFSETS = [((d, 0), ("left", "center")) for d in (4, 9)] + [((-d, 0), ("right", "center")) for d in (4, 9)] \
    + [((0, d), ("center", "bottom")) for d in (4, 9, 14)] + [((0, -d), ("center", "top")) for d in (4, 9, 14)] \
    + [((sx * d, sy * d), ("left" if sx > 0 else "right", "bottom" if sy > 0 else "top"))
       for d in (3, 7, 12) for sx in (1, -1) for sy in (1, -1)]


def place_labels(ax, lines, points=(), fontsize=8, pad=1.5):
    """Label each line where the label overlaps no other label, no line and no point, inside the axes.

    Tries anchors along each line (:func:`_label_candidates`) and offsets around each
    (:data:`_OFFSETS`) in turn; the first free place wins. The figure's layout must be
    final (drawn, its layout engine off): places are judged in display coordinates.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    lines : list of (str, numpy.ndarray of shape (k, 2), colour)
        Label text, the line's points in data coordinates, its colour.
    points : array_like, shape (m, 2)
        Markers (data coordinates) a label must not cover.
    fontsize : float
    pad : float
        Clearance around a label, pixels.

    Returns
    -------
    list of matplotlib.text.Text
        The labels placed (a line with no free place gets none).
    """
    from matplotlib.path import Path as MplPath
    from matplotlib.transforms import Bbox

    renderer = ax.figure.canvas.get_renderer()
    to_display = ax.transData.transform
    paths = [MplPath(to_display(xy)) for _, xy, _ in lines]
    dots = to_display(np.asarray(points, float).reshape(-1, 2)) if len(points) else np.empty((0, 2))
    drawn = np.concatenate([path.vertices for path in paths] + [dots])
    near = 30 * ax.figure.dpi / 72                     # 30 points

    def crowd(anchors):
        d = np.linalg.norm(to_display(anchors)[:, None, :] - drawn[None, :, :], axis=2)
        return (d < near).sum(axis=1)

    frame = ax.get_window_extent(renderer)
    dot_r = 3.5 * ax.figure.dpi / 72          # a marker's radius (s = 22 points^2), pixels
    placed, texts = [], []
    for text, xy, colour in lines:
        label = ax.annotate(text, xy[0], xytext=(0, 0), textcoords="offset points", color=colour,
                            fontsize=fontsize, zorder=5, annotation_clip=False)
        for anchor in _label_candidates(xy, crowd):
            found = False
            for offset, (ha, va) in _OFFSETS:
                label.xy, label.xyann = tuple(anchor), offset
                label.set_horizontalalignment(ha)
                label.set_verticalalignment(va)
                box = label.get_window_extent(renderer)
                grown = Bbox.from_extents(box.x0 - pad, box.y0 - pad, box.x1 + pad, box.y1 + pad)
                if not (frame.x0 <= grown.x0 and grown.x1 <= frame.x1 and frame.y0 <= grown.y0
                        and grown.y1 <= frame.y1):
                    continue
                if any(grown.overlaps(other) for other in placed):
                    continue
                if any(path.intersects_bbox(grown, filled=False) for path in paths):
                    continue
                if len(dots) and ((dots[:, 0] > grown.x0 - dot_r) & (dots[:, 0] < grown.x1 + dot_r)
                                  & (dots[:, 1] > grown.y0 - dot_r) & (dots[:, 1] < grown.y1 + dot_r)).any():
                    continue
                found = True
                break
            if found:
                placed.append(grown)
                texts.append(label)
                break
        else:
            label.remove()
    return texts


def map_views(points, axes=tuple(INPUTS), hold=None, panels=None):
    """The map sets a study draws: for every combination of the swept values of the inputs that
    are neither mapped (``axes``), held (``hold``) nor the panel input (``panels``), the views of
    its panels and the points shown in each.

    Parameters
    ----------
    points : pandas.DataFrame
        The simulated points (:func:`analysis.metrics.dataset.point_means`), every input a column.
    axes : (str, str)
        The two inputs each map spans, (y, x) (config ``maps.axes``).
    hold : dict, optional
        ``{input: value}``: inputs held at a value (config ``maps.hold``, their units).
    panels : str, optional
        An input drawn side by side, one panel per swept value (config ``maps.panels``).

    Returns
    -------
    list of (dict, list of (MapView, numpy.ndarray))
        Per map set: the slice's values (``{input: value}``, its folder,
        :func:`analysis.config.variant_path`) and per panel its view and the positions of the
        points drawn in it (those at the view's held values).
    """
    inputs, hold = tuple(input_columns(points)), dict(hold or {})
    for name in (*axes, *hold, *([panels] if panels else [])):
        if name not in inputs:
            raise ValueError(f"maps: {name!r} is not an input of this study ({', '.join(inputs)})")
    sliced = [c for c in inputs if c not in (*axes, *hold, panels)]
    swept = {c: np.unique(points[c].to_numpy(float)) for c in inputs}
    combos = [dict(zip(sliced, v)) for v in itertools.product(*(swept[c] for c in sliced))]
    sets = []
    for values in combos:
        panel_values = swept[panels] if panels else [None]
        views = []
        for p in panel_values:
            held = {**values, **hold, **({panels: p} if panels else {})}
            view = MapView(tuple(axes), inputs, tuple((c, float(held[c])) for c in inputs if c in held))
            at = np.ones(len(points), dtype=bool)
            for c, v in view.held:
                at &= np.isclose(points[c].to_numpy(float), v)
            views.append((view, np.flatnonzero(at)))
        if any(len(rows) for _, rows in views):
            sets.append((values, views))
    return sets


def render_maps(model, df, split, outdir, n=41, axes=tuple(INPUTS), hold=None, panels=None, window=None,
                lines_model=None, lines_note=None):
    """Write every figure: surfaces, parity plots, process map (and uncertainty maps).

    The maps span two inputs (``axes``, default the paper's U and omega); the model's other
    inputs (a sweep's extra axes) are held at ``hold`` or, if not held, drawn once per swept
    value in ``<outdir>/<input>=<value>/...`` (:func:`map_views`); ``panels`` draws one input's
    values side by side in each figure instead (small multiples, one colour scale). The paper's
    study (inputs U and omega only) draws its figures straight into ``outdir``.

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
    axes, hold, panels
        As :func:`map_views` (config ``maps``).
    window : dict, optional
        ``max_porosity_pct`` and ``max_roughness_um`` (None: no limit) of the operating window
        (config ``maps.operating_window``); None: no window map.
    lines_model : estimator, optional
        Draws the process map instead of ``model`` (a smooth model's iso-lines when the chosen
        one is piecewise flat), ``lines_note`` saying so in its caption.

    Returns
    -------
    list of pathlib.Path
        ``<metric>_parity.{png,svg}`` (every point, once, in ``outdir``), and per map set
        ``<metric>_surface.{png,svg}``, ``<metric>_contour.{png,svg}``, when the model gives
        calibrated intervals ``<metric>_interval.{png,svg}`` (metric = dataset column, e.g.
        ``mass_g``), then ``process_map.{png,svg}`` and with ``window``
        ``operating_window.{png,svg}``.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    points, split = point_means(df, tuple(np.asarray(rows, int) for rows in split))
    paths = []
    with matplotlib.rc_context(_STYLE):
        predicted = model.predict(inputs_of(points))
        for metric in METRICS:
            paths += save_figure(parity_figure(points, predicted, split, metric), outdir, f"{metric}_parity")
        for values, views in map_views(points, axes, hold, panels):
            where = outdir / variant_path(values)
            where.mkdir(parents=True, exist_ok=True)
            drawn = [(view, points.iloc[rows].reset_index(drop=True),
                      tuple(np.flatnonzero(np.isin(rows, part)) for part in split)) for view, rows in views]
            for metric in METRICS:
                paths += save_figure(surface_figure(model, None, None, metric, n, panels=drawn), where,
                                     f"{metric}_surface")
                paths += save_figure(contour_figure(model, None, None, metric, max(n, 61), panels=drawn), where,
                                     f"{metric}_contour")
                if provides_intervals(model):
                    paths += save_figure(interval_figure(model, None, None, metric, n, panels=drawn), where,
                                         f"{metric}_interval")
            paths += save_figure(process_map_figure(lines_model or model, None, None, max(n, 101), panels=drawn,
                                                    note=lines_note), where, "process_map")
            if window is not None:
                paths += save_figure(window_figure(model, None, None, window.get("max_porosity_pct"),
                                                   window.get("max_roughness_um"), panels=drawn),
                                     where, "operating_window")
    return paths
