"""The paper's Figure 10, the spreading process map: the defect index
R_q/max(R_q) * Phi/max(Phi) against the throughput index Q_s/max(Q_s) * M_s/max(M_s), with
labelled iso-U and iso-omega lines of the surrogate (or of any two inputs it maps) and the
simulated runs; with calibrated intervals, the indices' single-run intervals as crosses at the
simulated settings, the coverage level in the caption.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.columns import INPUTS, SHORT_NAMES, input_units
from analysis.surrogate.predict import hybrid_indices, index_intervals, metric_maxima, provides_intervals
from analysis.viz.figures import (
    SYMBOLS,
    MapView,
    add_caption,
    coverage_text,
    panel_figure,
    single_panel,
    supply_limited,
    too_few_runs,
)


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
        As :func:`~analysis.viz.surfaces.surface_figure`'s.
    note : str, optional
        A sentence for the caption (e.g. which model draws the lines).

    Returns
    -------
    matplotlib.figure.Figure
        Its iso-line labels are listed in ``fig.line_labels`` (matplotlib Text artists).
    """
    panels = panels or single_panel(view, df, split)
    iso = [iso_values(pts, axes=v.axes) for v, pts, _ in panels]
    grids = pd.concat([v.grid(model, (a.min(), a.max()), (b.min(), b.max()), n)
                       for (v, _, _), (a, b) in zip(panels, iso)])
    maxima = metric_maxima(grids)
    with_intervals = provides_intervals(model) and model.is_finite()
    fig, axes = panel_figure(len(panels), "2d", size=(9.0, 6.5), layout="constrained")
    drawn = [_draw_process_map(ax, model, v, pts, part, a_values, b_values, maxima, n, with_intervals)
             for ax, (v, pts, part), (a_values, b_values) in zip(axes, panels, iso)]
    right, upper = (max(getattr(ax, get)()[1] for ax in axes) for get in ("get_xlim", "get_ylim"))
    for ax in axes:        # indices that cannot be negative start at 0; panels on one scale
        ax.set_xlim(0, right)
        ax.set_ylim(0, upper)
    axes[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, borderaxespad=0)
    caption = [note] if note else []
    if with_intervals:
        caption.append(f"Grey crosses: the {coverage_text(model)} interval of the indices of a single new run at each "
                       "simulated setting (calibrated by grouped cross-conformal prediction on held-out runs; "
                       "run-to-run noise included)")
    elif provides_intervals(model):
        caption.append(f"No interval crosses: {too_few_runs(model)}")
    if caption:
        add_caption(fig, ". ".join(caption))
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
                    ecolor="0.6", alpha=0.45, lw=0.8, zorder=1, label=f"{coverage_text(model)} single-run interval")
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
