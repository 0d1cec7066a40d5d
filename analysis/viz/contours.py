"""The 2-D maps an operator reads: each metric as a contour map over two inputs with the
simulated runs, and the operating window (the settings whose single runs meet the limits of
``maps.operating_window``, the recommended one starred).
"""
from __future__ import annotations

import pandas as pd
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from analysis.columns import input_units
from analysis.surrogate.intervals import metrics_of
from analysis.surrogate.predict import provides_intervals
from analysis.surrogate.recommend import LIMITS, check_limits, check_model_has, meets_limits
from analysis.viz.figures import (
    LABELS,
    MATH,
    SYMBOLS,
    TITLES,
    add_caption,
    axis_label,
    coverage_text,
    panel_figure,
    panel_grids,
    scatter_runs,
    single_panel,
    too_few_runs,
)


def contour_figure(model, df, split, metric, n=61, view=None, panels=None):
    """A metric over the two inputs as a 2-D contour map (omega across, U up), the simulated runs on it.

    Beside each 3-D surface, the map on which an operator reads the predicted value at a
    setting: filled contours with labelled contour lines of the model's mean, the
    training and test runs as points. Arguments as
    :func:`~analysis.viz.surfaces.surface_figure`'s.

    Returns
    -------
    matplotlib.figure.Figure
    """
    panels, grids, (lo, hi) = panel_grids(model, df, split, view, panels, n, metric)
    levels = MaxNLocator(12).tick_values(lo, hi)
    fig, axes = panel_figure(len(panels), "2d", size=(7.5, 6.2), layout="constrained")
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        Y, X, Z = (grid[c].to_numpy().reshape(n, n) for c in (*v.axes, metric))
        filled = ax.contourf(X, Y, Z, levels=levels, cmap="viridis")
        lines = ax.contour(X, Y, Z, levels=levels[1:-1:2], colors="white", linewidths=0.7)
        ax.clabel(lines, fontsize=8, fmt="%.3g")
        scatter_runs(ax, pts, part, v.axes)
        ax.set(xlabel=axis_label(v.axes[1]), ylabel=axis_label(v.axes[0]),
               title=f"{TITLES[metric]} {LABELS[metric]}" + (f"\n{v.title()}" if v.title() else ""))
        ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.12), ncol=3, fontsize=8, frameon=False)
    fig.colorbar(filled, ax=axes if len(axes) > 1 else axes[0], label=f"predicted {LABELS[metric]}")
    return fig


#: How each limit's boundary is drawn on the operating window (line style).
_LIMIT_STYLES = {"max_porosity_pct": "--", "max_roughness_um": ":", "max_void_fraction_pct": "-.",
                 "min_coverage_pct": (0, (6, 2, 1, 2, 1, 2))}


def _limit_label(key, value):
    """A limit in mathtext: '$\\Phi$ ≤ 50 %', '$C$ ≥ 95 %'."""
    limit = LIMITS[key]
    symbol, unit = MATH[limit.column]
    return f"{symbol} {'≤' if limit.kind == 'max' else '≥'} {value:g} {unit}"


def window_figure(model, df, split, limits=None, n=121, view=None, panels=None):
    """The operating window: the settings whose single runs meet the operator's limits, the best marked.

    A setting is in the window when the end of its calibrated single-run interval (at the
    model's confidence) meets every limit (the upper end an upper limit, the lower end a lower
    one), the rule of :mod:`analysis.surrogate.recommend`; a model without finite intervals is
    judged on its mean, and the title says so. Over the window: contours of the predicted
    throughput Q_s, each limit's boundary, and the recommended setting (the highest Q_s in the
    window) starred with its values.

    Parameters
    ----------
    model : estimator
        Fitted surrogate, preferably with calibrated intervals; with the layer-structure
        metrics when a limit is on them.
    df, split, view, panels
        As :func:`~analysis.viz.surfaces.surface_figure`'s.
    limits : dict, optional
        ``{key of analysis.surrogate.recommend.LIMITS: value or None}`` (config
        ``maps.operating_window``: ``max_porosity_pct`` %, ``max_roughness_um`` um,
        ``max_void_fraction_pct`` %, ``min_coverage_pct`` %); None: no limit.
    n : int
        Grid points per axis.

    Returns
    -------
    matplotlib.figure.Figure
        With ``fig.recommended``: per panel the recommended setting (a dict of the inputs and
        the predicted metrics) or None when no setting meets the limits.
    """
    panels = panels or single_panel(view, df, split)
    limits = check_limits(limits or {})
    check_model_has(model, limits)
    with_intervals = provides_intervals(model) and model.is_finite()
    lower = " (its lower end a least value)" if any(LIMITS[k].kind == "min" for k in limits) else ""
    rule = (f"the upper end of the {coverage_text(model)} single-run interval meets every limit{lower}"
            if with_intervals
            else "the predicted mean meets every limit (no finite interval: " + (
                too_few_runs(model) if provides_intervals(model) else "the model has no calibrated intervals") + ")")
    labels = [_limit_label(k, v) for k, v in limits.items()]
    fig, axes = panel_figure(len(panels), "2d", size=(7.8, 6.6), layout="constrained")
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    q_levels = MaxNLocator(10).tick_values(min(g["throughput_mm2_s"].min() for g in grids),
                                           max(g["throughput_mm2_s"].max() for g in grids))
    shown = [*dict.fromkeys(["porosity_pct", "roughness_um", *(LIMITS[k].column for k in limits)])]
    fig.recommended = []
    for ax, (v, pts, part), grid in zip(axes, panels, grids):
        on_mean, on_interval = meets_limits(grid, limits, with_intervals)
        (ya, xa), shape, units = v.axes, (n, n), input_units(v.axes)
        Y, X = (grid[c].to_numpy().reshape(shape) for c in v.axes)
        inside = on_interval.reshape(shape).astype(float)
        ax.contourf(X, Y, inside, levels=[-0.5, 0.5, 1.5], colors=["0.82", "#b7e4a7"])
        q = ax.contour(X, Y, grid["throughput_mm2_s"].to_numpy().reshape(shape), levels=q_levels,
                       colors="0.35", linewidths=0.7)
        ax.clabel(q, fontsize=8, fmt="%.3g")
        for key, value in limits.items():
            limit = LIMITS[key]
            end = "_hi" if limit.kind == "max" else "_lo"
            edge = grid[limit.column + end if with_intervals else limit.column].to_numpy().reshape(shape)
            if edge.min() < value < edge.max():
                ax.contour(X, Y, edge, levels=[value], colors="k", linestyles=[_LIMIT_STYLES[key]], linewidths=1.4)
        handles = [Patch(color="#b7e4a7", label="operating window: " + " and ".join(labels)),
                   Patch(color="0.82", label="outside: a run there may miss a limit" if with_intervals
                         else "outside: the predicted mean misses a limit"),
                   Line2D([], [], color="0.35", lw=0.7, label="predicted $Q_s$ (mm$^2$/s)")]
        handles += [Line2D([], [], color="k", ls=_LIMIT_STYLES[k], label=f"{LIMITS[k].name} limit") for k in limits]
        best = None
        if on_interval.any():
            row = grid.loc[grid["throughput_mm2_s"].where(pd.Series(on_interval, index=grid.index)).idxmax()]
            best = {c: float(row[c]) for c in (*v.axes, *metrics_of(model))}
            ax.scatter([best[xa]], [best[ya]], marker="*", s=260, color="gold", edgecolor="k", zorder=6, clip_on=False)
            values = ", ".join(f"{MATH[m][0]} = {best[m]:.3g} {MATH[m][1]}" for m in shown)
            handles.append(Line2D(
                [], [], marker="*", ms=14, color="gold", mec="k", ls="none",
                label=(f"recommended: {SYMBOLS.get(ya, ya)} = {best[ya]:.3g} {units[ya]}, "
                       f"{SYMBOLS.get(xa, xa)} = {best[xa]:.3g} {units[xa]}; "
                       f"$Q_s$ = {best['throughput_mm2_s']:.3g} mm$^2$/s, {values}")))
        else:
            ax.text(0.5, 0.5, "no setting meets the limits\n" + ("at this confidence" if with_intervals else ""),
                    transform=ax.transAxes, ha="center", va="center", fontsize=12,
                    bbox={"facecolor": "white", "edgecolor": "0.5"})
        fig.recommended.append(best)
        scatter_runs(ax, pts, part, v.axes)
        run_handles, _ = ax.get_legend_handles_labels()
        ax.legend(handles=handles + run_handles, loc="upper left", bbox_to_anchor=(0.0, -0.1), fontsize=8,
                  frameon=False)
        ax.set(xlabel=axis_label(xa), ylabel=axis_label(ya))
        ax.set_title(f"Operating window: {' and '.join(labels) or 'no limits'}"
                     + (f" in {coverage_text(model)} of runs" if with_intervals else " on the mean")
                     + (f"\n{v.title()}" if v.title() else ""), pad=14)     # clear of a star on the top edge
    add_caption(fig, f"In the window, {rule}: analysis.surrogate.recommend's rule ("
             "spreadmap-recommend prints the same setting from a finer grid). Limits: config maps.operating_window"
             + ("; porosity is eq. 7's (4 R_q taken as the layer's thickness), the void fraction is 1 - packing "
                "fraction" if "max_void_fraction_pct" in limits else "") + ".")
    return fig
