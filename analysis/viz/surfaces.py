"""The paper's Figures 6-9: the regressed surface of each metric over two inputs with the
training runs in blue and the test runs in black (a), simulated against predicted values with
the correlation coefficient R (b, c); with replicates the points drawn are the replicate means
with their seed-to-seed range.  Beyond the paper, when the surrogate gives calibrated intervals
(:func:`analysis.surrogate.predict.provides_intervals`), each surface's companion map of the
half-width of its single-run interval (``<metric>_interval``).
"""
from __future__ import annotations

import numpy as np

from analysis.columns import INPUTS, METRICS
from analysis.surrogate.scores import pearson_r
from analysis.viz.figures import (
    LABELS,
    TEST_COLOUR,
    TITLES,
    TRAIN_COLOUR,
    add_caption,
    axis_label,
    coverage_text,
    new_figure,
    panel_figure,
    panel_grids,
    single_panel,
    supply_limited,
    too_few_runs,
)


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
        One of the model's metrics (:func:`analysis.surrogate.intervals.metrics_of`: the paper's
        four of :data:`analysis.columns.METRICS`, then any layer-structure metrics).
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
    panels, grids, (lo, hi) = panel_grids(model, df, split, view, panels, n, metric)
    fig, axes = panel_figure(len(panels), "3d", size=(8.0, 6.5))
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        (ya, xa), shape = v.axes, (n, n)
        Y, X, Z = (grid[c].to_numpy().reshape(shape) for c in (ya, xa, metric))
        ax.set_box_aspect(None, zoom=0.85)
        surf = ax.plot_surface(X, Y, Z, cmap="turbo", alpha=0.8, linewidth=0, antialiased=True, rasterized=True,
                               **({"vmin": lo, "vmax": hi} if len(panels) > 1 else {}))  # panels: one scale
        x, y, z = (pts[c].to_numpy(float) for c in (xa, ya, metric))
        for rows, colour, label in ((part[0], TRAIN_COLOUR, "training runs"), (part[1], TEST_COLOUR, "test runs")):
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
        One of the model's metrics, as :func:`surface_figure`'s.
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
    panels = panels or single_panel(view, df, split)
    level = coverage_text(model)
    fig, axes = panel_figure(len(panels), "2d", size=(7.5, 6.2), layout="constrained")
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    halves = [((g[f"{metric}_hi"] - g[f"{metric}_lo"]) / 2).to_numpy().reshape(n, n) for g in grids]
    (ya, xa), titles = panels[0][0].axes, [v.title() for v, _, _ in panels]
    if not all(np.isfinite(h).all() for h in halves):      # too few calibration runs for this level
        ax = axes[0]
        ax.text(0.5, 0.5, too_few_runs(model), ha="center", va="center", transform=ax.transAxes, wrap=True)
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya), title=f"{TITLES[metric]}: no {level} interval")
        return fig
    levels = np.linspace(min(h.min() for h in halves), max(h.max() for h in halves), 15)
    for ax, (v, pts, part), grid, half, title in zip(axes, panels, grids, halves, titles):
        Y, X = (grid[c].to_numpy().reshape(n, n) for c in v.axes)
        filled = ax.contourf(X, Y, half, levels=levels if len(panels) > 1 else 14, cmap="viridis")
        x, y = (pts[c].to_numpy(float) for c in (xa, ya))
        for rows, colour, marker, label in ((part[0], TRAIN_COLOUR, "o", "training runs"),
                                            (part[1], TEST_COLOUR, "s", "test runs")):
            ax.scatter(x[rows], y[rows], color=colour, edgecolor="white", marker=marker,
                       s=30, label=f"{label} ({len(rows)})")
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya),
               title=f"{TITLES[metric]}: {level} single-run interval" + (f"\n{title}" if title else ""))
        ax.legend(loc="upper left", fontsize=8, framealpha=0.8)
    fig.colorbar(filled, ax=axes if len(axes) > 1 else axes[0],
                 label=f"half-width of the {level} interval of {LABELS[metric]}")
    add_caption(fig, f"{level} of new DEM runs fall within the prediction +- this (calibrated by grouped "
             "cross-conformal prediction on held-out runs; run-to-run noise included)")
    return fig


def parity_figure(df, predicted, split, metric, metrics=METRICS):
    """Simulated against predicted values of one metric, training and test (Figures 6-9 b, c).

    Parameters
    ----------
    df : pandas.DataFrame
        The simulated runs.
    predicted : numpy.ndarray, shape (n, k)
        Surrogate predictions for the runs, columns in ``metrics`` order.
    split : (array of int, array of int)
        Row positions of the training and test runs.
    metric : str
        One of ``metrics``.
    metrics : sequence of str
        The columns of ``predicted`` (default the paper's four, METRICS; a model's own:
        :func:`analysis.surrogate.intervals.metrics_of`).

    Returns
    -------
    matplotlib.figure.Figure
        Two panels, each with the 1:1 line and R in its title.
    """
    j = list(metrics).index(metric)
    sim, pred = df[metric].to_numpy(float), predicted[:, j]
    lo, hi = min(sim.min(), pred.min()), max(sim.max(), pred.max())
    pad = 0.05 * (hi - lo or 1.0)
    fig = new_figure(figsize=(10.0, 4.8), layout="constrained")
    for ax, rows, colour, name in zip(fig.subplots(1, 2), split, (TRAIN_COLOUR, TEST_COLOUR),
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
