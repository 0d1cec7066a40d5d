"""Deposit profiles: how much powder the roller left behind it, along its travel.

The layer a spreading run lays is in steady state where its mass per unit
length of travel no longer changes with x; the sampling region must lie
there (:func:`steady_state_start`). Units are SI inside; the profile table and
figure use mm and mg/mm^2 (layer mass per mm of travel per mm of strip width).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

#: Bin length of a deposit profile along the travel [m].
BIN_LENGTH = 0.5e-3


def deposit_profile(atoms, density: float, width: float, x_range: tuple, bin_length: float = BIN_LENGTH):
    """Areal mass of the layer along the travel.

    Parameters
    ----------
    atoms : pandas.DataFrame
        Final particles, columns ``x`` and ``radius`` [m] (the powder still ahead of
        the stopped roller is left out by the caller or removed by the run).
    density : float
        Particle density [kg/m^3].
    width : float
        Strip width [m] (the periodic length across the travel).
    x_range : (float, float)
        Bins cover ``x_range`` [m] in steps of ``bin_length`` [m].

    Returns
    -------
    pandas.DataFrame
        ``x_mm`` (bin centre) and ``areal_mass_mg_mm2`` (particle mass centred in the
        bin over its area).
    """
    edges = np.arange(x_range[0], x_range[1] + 0.5 * bin_length, bin_length)
    x, r = atoms["x"].to_numpy(float), atoms["radius"].to_numpy(float)
    mass = np.histogram(x, bins=edges, weights=density * 4 / 3 * np.pi * r**3)[0]
    return pd.DataFrame({"x_mm": 0.5 * (edges[:-1] + edges[1:]) * 1e3,
                         "areal_mass_mg_mm2": mass / (np.diff(edges) * width)})  # kg/m^2 = mg/mm^2


def steady_state_start(profiles: pd.DataFrame, plateau_mm: tuple, k: float = 2.0, window_mm: float = 1.0,
                       hold_mm: float = 2.0) -> float:
    """Where a deposit reaches steady state [mm], from the replicate profiles of one point.

    The plateau is the mean areal mass over ``plateau_mm`` (x from, to), taken as steady;
    its noise is the scatter of the replicate-mean bins there. Scanning from the left,
    the steady state starts at the first window of ``window_mm`` whose mean is within
    ``k`` standard errors of the plateau and stays so for every window over the next
    ``hold_mm``.

    Parameters
    ----------
    profiles : pandas.DataFrame
        Columns ``x_mm`` (equal bins), ``areal_mass_mg_mm2`` and ``replicate``.
    plateau_mm : (float, float)
        Part of the travel taken as steady [mm] (e.g. the far half of a long region).
    k : float
        Tolerance in standard errors of a window's mean.
    window_mm, hold_mm : float
        Window length, and how far past the start the windows must stay steady [mm].

    Returns
    -------
    float
        Left edge [mm] of the first steady window; the plateau's start if none before it.
    """
    mean = profiles.groupby("x_mm")["areal_mass_mg_mm2"].mean()
    xs = mean.index.to_numpy()
    step = xs[1] - xs[0]
    plateau = mean[(xs >= plateau_mm[0]) & (xs <= plateau_mm[1])]
    w = max(1, round(window_mm / step))
    windows = mean.rolling(w).mean().shift(-(w - 1))  # mean of bins i .. i+w-1
    steady = ((windows - plateau.mean()).abs() <= k * plateau.std(ddof=1) / np.sqrt(w)).to_numpy()
    hold = max(1, round(hold_mm / step))
    for i in range(len(xs)):
        if xs[i] >= plateau_mm[0]:
            break
        if steady[i:i + hold].all():
            return float(xs[i] - step / 2)
    return float(plateau_mm[0])


def run_profiles(dumps, runs, density: float, width: float, x_range: tuple) -> pd.DataFrame:
    """Deposit profiles of several runs: ``runs`` is a list of dicts (``U_mm_s``,
    ``omega_rad_s``, ``replicate``), one per dump path in ``dumps``."""
    from analysis.metrics.dump import read_dump
    tables = [deposit_profile(read_dump(path).atoms, density, width, x_range).assign(**run)
              for path, run in zip(dumps, runs, strict=True)]
    return pd.concat(tables, ignore_index=True)


def profile_figure(profiles: pd.DataFrame, region_mm: tuple, title: str = ""):
    """Areal mass against x for each (U, omega) (replicate mean, band: min to max), the
    sampling region shaded. Returns a matplotlib Figure."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(8.0, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.axvspan(*region_mm, color="0.9", label="sampling region")
    for (U, omega), group in profiles.groupby(["U_mm_s", "omega_rad_s"]):
        stats = group.groupby("x_mm")["areal_mass_mg_mm2"].agg(["mean", "min", "max"])
        line, = ax.plot(stats.index, stats["mean"], lw=1.5, label=f"U = {U:g} mm/s, ω = {omega:g} rad/s")
        if group["replicate"].nunique() > 1:
            ax.fill_between(stats.index, stats["min"], stats["max"], color=line.get_color(), alpha=0.2, lw=0)
    laid = profiles.loc[profiles["areal_mass_mg_mm2"] > 0, "x_mm"]
    if len(laid):
        ax.set_xlim(laid.min() - 0.5, profiles["x_mm"].max() + 0.5)
    ax.set_xlabel("x along the travel (mm)")
    ax.set_ylabel("layer mass per area (mg/mm$^2$)")
    ax.set_title(title or "Deposit profiles")
    ax.legend(fontsize=8)
    return fig


def profile_runs(points, replicates: int, targets=(-10.0, 0.0, 10.0)) -> list[tuple[float, float, int]]:
    """The (U, omega, replicate) runs a level's deposit-profile figure shows: at the
    middle U of the design, the omegas nearest ``targets`` [rad/s], every replicate."""
    Us = sorted({U for U, _ in points})
    U = Us[len(Us) // 2]
    omegas = sorted({w for u, w in points if u == U})
    chosen = sorted({min(omegas, key=lambda w: abs(w - t)) for t in targets})
    return [(U, w, r) for w in chosen for r in range(replicates)]


def pile_ahead(profile: pd.DataFrame, heap_mass_per_width: float) -> np.ndarray:
    """Powder still ahead of the roller when its axis passed each bin [mg/mm], by mass balance.

    Parameters
    ----------
    profile : pandas.DataFrame
        One run's :func:`deposit_profile` (``x_mm``, ``areal_mass_mg_mm2``), covering
        every bin behind the roller's final position.
    heap_mass_per_width : float
        The settled heap's mass per mm of strip width [mg/mm].

    Returns
    -------
    numpy.ndarray
        Heap mass per width less everything deposited up to each bin's far edge [mg/mm].
    """
    step = np.diff(profile["x_mm"].to_numpy()[:2])[0] if len(profile) > 1 else 0.0
    return heap_mass_per_width - np.cumsum(profile["areal_mass_mg_mm2"].to_numpy() * step)
