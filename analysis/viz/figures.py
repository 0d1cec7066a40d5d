"""What every map figure shares: axis labels and titles, the view of a map over two inputs
(:class:`MapView`) and its panels side by side, the simulated runs' markers, captions, and
writing a figure as PNG and SVG.  Figures are drawn on matplotlib's Agg canvas (pyplot is never
imported, so no display is needed).
"""
from __future__ import annotations

import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from analysis.columns import INPUTS, input_columns, input_units
from analysis.io import atomic_path
from analysis.surrogate.predict import predict_frame, with_indices

#: Each mapped metric's symbol and unit (matplotlib mathtext).
MATH = {
    "mass_g": ("$M_s$", "g"),
    "throughput_mm2_s": ("$Q_s$", "mm$^2$/s"),
    "roughness_um": ("$R_q$", r"$\mu$m"),
    "porosity_pct": (r"$\Phi$", "%"),
    "void_fraction_pct": (r"$\varepsilon$", "%"),
    "coverage_pct": ("$C$", "%"),
}


#: Axis labels with units (matplotlib mathtext).
LABELS = {
    "U_mm_s": "$U$ (mm/s)",
    "omega_rad_s": r"$\omega$ (rad/s)",
    **{m: f"{symbol} ({unit})" for m, (symbol, unit) in MATH.items()},
}


#: Figure titles of the metrics.
TITLES = {
    "mass_g": "Powder mass in the sampling region",
    "throughput_mm2_s": "Spread throughput",
    "roughness_um": "Spread layer roughness",
    "porosity_pct": "Spread layer porosity (eq. 7)",
    "void_fraction_pct": "Spread layer void fraction, 1 - packing fraction",
    "coverage_pct": "Substrate covered by the spread layer",
}


#: The formats every figure is written in.
FORMATS = ("png", "svg")


#: Colours of the training and test runs (the paper's blue and black).
TRAIN_COLOUR, TEST_COLOUR = "blue", "black"


def new_figure(**kwargs):
    """A matplotlib Figure on the Agg canvas (``kwargs``: Figure's)."""
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
        (:func:`analysis.surrogate.predict.with_indices`); columns as
        :func:`analysis.surrogate.predict.predict_grid`'s."""
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


def single_panel(view, df, split):
    """A one-panel list (view, points, split) when called with a plain (U, omega) figure's arguments."""
    return [(view or MapView(inputs=tuple(input_columns(df))), df, split)]


def panel_grids(model, df, split, view, panels, n, metric):
    """The panels (:func:`single_panel` unless given), each one's n x n grid, and ``metric``'s range over all."""
    panels = panels or single_panel(view, df, split)
    grids = [v.grid(model, *v.ranges(pts), n) for v, pts, _ in panels]
    return panels, grids, (min(g[metric].min() for g in grids), max(g[metric].max() for g in grids))


def panel_figure(k, kind, **kwargs):
    """A figure of ``k`` panels side by side (3-D axes for ``kind`` '3d'); returns (fig, axes)."""
    width, height = kwargs.pop("size")
    fig = new_figure(figsize=(width * (1 + 0.85 * (k - 1)), height), **kwargs)
    axes = [fig.add_subplot(1, k, i + 1, **({"projection": "3d"} if kind == "3d" else {})) for i in range(k)]
    return fig, axes


def scatter_runs(ax, pts, part, axes):
    """The simulated runs on a 2-D map: training (blue circles), test (black squares), supply-limited (red rings)."""
    ya, xa = axes
    x, y = (pts[c].to_numpy(float) for c in (xa, ya))
    for rows, colour, marker, label in ((part[0], TRAIN_COLOUR, "o", "training runs"),
                                        (part[1], TEST_COLOUR, "s", "test runs")):
        ax.scatter(x[rows], y[rows], color=colour, edgecolor="white", marker=marker, s=30, zorder=4,
                   clip_on=False, label=f"simulated {label} ({len(rows)})")
    limited = supply_limited(pts)
    if limited.any():
        ax.scatter(x[limited], y[limited], facecolor="none", edgecolor="tab:red", s=90, linewidth=1.5, zorder=5,
                   clip_on=False, label=f"supply-limited: a lower bound ({limited.sum()})")


def add_caption(fig, text, width=95):
    """A small caption under the axes, wrapped; the constrained layout makes room for it."""
    fig.supxlabel(textwrap.fill(text, width, break_on_hyphens=False), fontsize=8, ha="center")


def too_few_runs(model):
    """Why ``model`` has no finite interval at its confidence, for a title or caption."""
    return (f"{model.n_runs} held-out runs calibrate no finite {coverage_text(model)} interval "
            f"(at least {model.runs_needed()} needed)")


def coverage_text(model):
    """The model's interval coverage as text, e.g. '90 %'."""
    return f"{100 * model.confidence:g} %"
