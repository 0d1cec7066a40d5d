"""Every figure of a study's maps (:func:`render_maps`): for each map set (:func:`map_views`) the
regressed surfaces and parity plots of the paper's Figures 6-9 (:mod:`analysis.viz.surfaces`), and
the same of the layer-structure metrics beside them (void fraction and coverage, when the model
has them), the contour and operating-window maps (:mod:`analysis.viz.contours`) and the process map of its
Figure 10 (:mod:`analysis.viz.process_map`), written as PNG and SVG.
"""
from __future__ import annotations

import itertools
from pathlib import Path

import matplotlib
import numpy as np

from analysis.columns import INPUTS, input_columns
from analysis.config.sweep import variant_path
from analysis.metrics.dataset import point_means, with_structure_metrics
from analysis.surrogate.data import inputs_of
from analysis.surrogate.intervals import metrics_of
from analysis.surrogate.predict import provides_intervals
from analysis.viz.contours import contour_figure, window_figure
from analysis.viz.figures import MapView, save_figure
from analysis.viz.process_map import process_map_figure
from analysis.viz.surfaces import interval_figure, parity_figure, surface_figure

#: The figures' matplotlib style.
_STYLE = {"font.size": 11, "axes.titlesize": 12, "axes.labelsize": 11, "savefig.dpi": 150}


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
        :func:`analysis.config.sweep.variant_path`) and per panel its view and the positions of the
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
        mean, :func:`analysis.metrics.dataset.point_means`; the layer-structure metrics
        derived from its ``packing_fraction`` and ``coverage``,
        :func:`analysis.metrics.dataset.with_structure_metrics`).
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
        The operating window's limits (config ``maps.operating_window``: ``max_porosity_pct``,
        ``max_roughness_um``, ``max_void_fraction_pct``, ``min_coverage_pct``; None: no limit;
        :data:`analysis.surrogate.recommend.LIMITS`); None: no window map.
    lines_model : estimator, optional
        Draws the process map instead of ``model`` (a smooth model's iso-lines when the chosen
        one is piecewise flat), ``lines_note`` saying so in its caption.

    Returns
    -------
    list of pathlib.Path
        For every metric the model predicts (:func:`analysis.surrogate.intervals.metrics_of`:
        the paper's four, then the layer-structure metrics ``void_fraction_pct`` and
        ``coverage_pct`` when it has them) ``<metric>_parity.{png,svg}`` (every point, once, in
        ``outdir``), and per map set ``<metric>_surface.{png,svg}``, ``<metric>_contour.{png,svg}``,
        when the model gives calibrated intervals ``<metric>_interval.{png,svg}`` (metric =
        dataset column, e.g. ``mass_g``), then ``process_map.{png,svg}`` and with ``window``
        ``operating_window.{png,svg}``.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    points, split = point_means(with_structure_metrics(df), tuple(np.asarray(rows, int) for rows in split))
    metrics = metrics_of(model)
    paths = []
    with matplotlib.rc_context(_STYLE):
        predicted = model.predict(inputs_of(points))
        for metric in metrics:
            paths += save_figure(parity_figure(points, predicted, split, metric, metrics), outdir,
                                 f"{metric}_parity")
        for values, views in map_views(points, axes, hold, panels):
            where = outdir / variant_path(values)
            where.mkdir(parents=True, exist_ok=True)
            drawn = [(view, points.iloc[rows].reset_index(drop=True),
                      tuple(np.flatnonzero(np.isin(rows, part)) for part in split)) for view, rows in views]
            for metric in metrics:
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
                paths += save_figure(window_figure(model, None, None, window, panels=drawn), where,
                                     "operating_window")
    return paths
