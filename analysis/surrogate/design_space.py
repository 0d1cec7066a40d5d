"""The adaptive design's space: its inputs, the box the sweep spans, the lattice points snap to,
and the space-filling initial design.

The box (:func:`sweep_bounds`) spans U and omega, and each extra axis of the sweep
(``roller.gap_um: [300, 400]``, docs/sweep.md) from its smallest to its largest listed value.
An extra axis with a single value is held at it (not a design dimension); U and omega must
span a range (:func:`check_design_box`).

Points are snapped to a lattice (``resolution_U_mm_s``, ``resolution_omega_rad_s``; an extra
axis: ``adaptive.resolution.<axis>``, by default the smallest spacing between its listed values,
so its lattice is its listed values when they are evenly spaced: :func:`sweep_resolution`) so
that run folders keep clean names and a point already simulated (by the grid or an earlier
design) is reused.  Units: U in mm/s, omega in rad/s, an extra axis in its config units (the
dataset's dotted column).
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.stats import qmc

from analysis.columns import SHORT_NAMES, input_units
from analysis.config.sweep import SPEED_AXES, sweep_axes


def design_inputs(config):
    """The adaptive design's inputs for the sweep in ``config``: ``U_mm_s``, ``omega_rad_s``,
    then its extra axes (:func:`analysis.config.sweep_axes`, dotted config keys, in sweep order)."""
    return [*SPEED_AXES, *sweep_axes(config)]


def sweep_bounds(config):
    """The design box of the sweep in ``config``: one (lo, hi) per input of :func:`design_inputs`.

    Each from the min and max of its listed sweep values (``sweep.U_mm_s``, ``sweep.omega_rad_s``,
    ``sweep.<axis>``): U in mm/s, omega in rad/s, an extra axis in its config units.  An extra
    axis with a single value gives (v, v): the design holds it at v.

    Returns
    -------
    tuple of (float, float)
    """
    sweep = config["sweep"]
    return tuple((float(min(sweep[a])), float(max(sweep[a]))) for a in design_inputs(config))


def settings_resolution(settings, axes=()):
    """Lattice spacing of every input, from the ``adaptive:`` settings.

    Parameters
    ----------
    settings : dict
        ``resolution_U_mm_s`` (mm/s), ``resolution_omega_rad_s`` (rad/s) and, for each extra
        axis, ``resolution[axis]`` (its config units).
    axes : sequence of str
        The extra axes (dotted config keys), in design order.

    Returns
    -------
    tuple of float
        U (mm/s), omega (rad/s), then each axis.
    """
    given = settings.get("resolution") or {}
    missing = [a for a in axes if a not in given]
    if missing:
        raise ValueError(f"adaptive.resolution.{missing[0]} is not given: each extra axis needs its lattice "
                         "spacing (sweep_resolution takes the smallest spacing of its sweep values)")
    return (float(settings["resolution_U_mm_s"]), float(settings["resolution_omega_rad_s"]),
            *(float(given[a]) for a in axes))


def sweep_resolution(config, settings):
    """Lattice spacing of every input of the sweep in ``config`` (:func:`design_inputs` order).

    U and omega: ``adaptive.resolution_U_mm_s`` (mm/s) and ``resolution_omega_rad_s`` (rad/s).
    An extra axis: ``adaptive.resolution.<axis>`` if given, else the smallest spacing between
    its listed sweep values (its config units; 1 for an axis with a single value, which is
    held and has no lattice).

    Returns
    -------
    tuple of float
    """
    axes = sweep_axes(config)
    spacing = {}
    for axis in axes:
        values = np.unique(np.asarray(config["sweep"][axis], float))
        spacing[axis] = float(np.diff(values).min()) if len(values) > 1 else 1.0
    given = settings.get("resolution") or {}
    return settings_resolution({**settings, "resolution": {**spacing, **given}}, axes)


def _input_names(k, names=None):
    """The names of k inputs: ``names``, or U_mm_s, omega_rad_s, input 3, ..."""
    return list(names) if names is not None else [*SPEED_AXES, *(f"input {j + 1}" for j in range(2, k))]


def _label(name):
    """How a message names an input: ``U (mm/s)``, ``omega (rad/s)``, ``roller.gap_um (um)``."""
    unit = input_units([name])[name]
    short = SHORT_NAMES.get(name, name)
    return f"{short} ({unit})" if unit else short


def check_design_box(bounds, resolution=None, names=None):
    """Raise ValueError naming the input whose range (or lattice spacing) cannot make a design.

    U and omega (the first two of ``bounds``) must span a range, hi > lo; an extra axis may be
    one value (lo == hi: held at it), not a reversed range.  Each spacing of ``resolution``
    must be positive, one per input.
    """
    names = _input_names(len(bounds), names)
    if len(bounds) < 2 or len(names) != len(bounds):
        raise ValueError(f"the design needs one range per input ({', '.join(names)}), got {len(bounds)}")
    for j, ((lo, hi), name) in enumerate(zip(bounds, names)):
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise ValueError(f"the {_label(name)} range {lo:g}..{hi:g} is not finite")
        if j < 2 and not hi > lo:
            raise ValueError(f"the {_label(name)} range {lo:g}..{hi:g} is empty: the sweep needs at "
                             "least two values of each speed to span a design space")
        if hi < lo:
            raise ValueError(f"the {_label(name)} range {lo:g}..{hi:g} is reversed")
    if resolution is not None:
        if len(resolution) != len(bounds):
            raise ValueError(f"{len(resolution)} lattice spacings for the {len(bounds)} inputs "
                             f"({', '.join(names)})")
        for r, name in zip(resolution, names):
            if not float(r) > 0:
                raise ValueError(f"the lattice spacing of {_label(name)} is {float(r):g}: it must be positive")


def _free(bounds):
    """Which inputs are design dimensions (hi > lo), boolean (k,); the others are held."""
    return np.array([hi > lo for lo, hi in bounds], bool)


def snap(points, bounds, resolution):
    """Round points to the lattice ``lo + i * resolution`` inside ``bounds``, per input.

    Parameters
    ----------
    points : array_like, shape (n, k)
        U (mm/s), omega (rad/s), then the extra axes (config units).
    bounds : sequence of k (lo, hi)
        Same units; an input with lo == hi is set to lo.
    resolution : sequence of k float
        Lattice spacing per input, same units.

    Returns
    -------
    numpy.ndarray, shape (n, k)
        Rounded to 6 decimals (the run folders' values).
    """
    points = np.atleast_2d(np.asarray(points, float))
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    res = np.asarray(resolution, float)
    k = np.round((np.clip(points, lo, hi) - lo) / res)
    k = np.minimum(k, np.floor((hi - lo) / res + 1e-9))
    return np.round(lo + k * res, 6)


def lattice(bounds, resolution):
    """Every lattice point of :func:`snap` in ``bounds``: the candidates of
    :func:`analysis.surrogate.acquisition.choose_batch`.

    Parameters
    ----------
    bounds, resolution
        As :func:`snap` (k inputs; U mm/s, omega rad/s, extra axes in config units).

    Returns
    -------
    numpy.ndarray, shape (m, k)
        The product of the inputs' lattices, the first input outermost.
    """
    axes = [np.round(lo + res * np.arange(int(np.floor((hi - lo) / res + 1e-9)) + 1), 6)
            for (lo, hi), res in zip(bounds, resolution)]
    return np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def _spacings(resolution, names, free):
    """The lattice in words for a message: ``0.5 mm/s x 0.25 rad/s x 50 um (roller.gap_um)``."""
    units = input_units(names)
    return " x ".join(f"{r:g} {units[n]}".strip() + ("" if n in SPEED_AXES else f" ({n})")
                      for r, n, f in zip(resolution, names, free) if f)


def initial_design(n, bounds, resolution, method="sobol", seed=0, names=None):
    """``n`` distinct space-filling points over ``bounds``, snapped to the lattice.

    A scrambled Sobol sequence (``method="sobol"``; nested: the first k
    points of a longer design with the same seed are this design) or a Latin
    hypercube (``"lhs"``), seeded, over the design dimensions (inputs with
    hi > lo); a held input (lo == hi) takes its value.  Points that coincide
    after snapping are dropped and later ones of the sequence used instead.

    Parameters
    ----------
    n : int
    bounds, resolution
        As :func:`snap`: k inputs, U (mm/s), omega (rad/s), then the extra axes (config units).
    method : {"sobol", "lhs"}
    seed : int
    names : sequence of str, optional
        The inputs' names, for messages (default U_mm_s, omega_rad_s, input 3, ...).

    Returns
    -------
    numpy.ndarray, shape (n, k)
        U (mm/s), omega (rad/s), then the extra axes.
    """
    names = _input_names(len(bounds), names)
    check_design_box(bounds, resolution, names)
    n = int(n)
    if n < 1:
        raise ValueError(f"initial design needs at least 1 point, got {n}")
    lo, hi = np.array([b[0] for b in bounds], float), np.array([b[1] for b in bounds], float)
    free = _free(bounds)
    if method == "sobol":
        sampler = qmc.Sobol(int(free.sum()), scramble=True, seed=int(seed))
    elif method == "lhs":
        sampler = qmc.LatinHypercube(int(free.sum()), seed=int(seed))
    else:
        raise ValueError(f"unknown initial design {method!r}; choose sobol or lhs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # Sobol: n not a power of 2
        raw = sampler.random(8 * n)
    points = np.tile(lo, (len(raw), 1))
    points[:, free] = qmc.scale(raw, lo[free], hi[free])
    points = snap(points, bounds, resolution)
    _, first = np.unique(points, axis=0, return_index=True)
    unique = points[np.sort(first)]
    if len(unique) < n:
        raise ValueError(f"the lattice ({_spacings(resolution, names, free)}) is too coarse for "
                         f"{n} distinct points")
    return unique[:n]


def among(points, others):
    """Which of ``points`` (n, k) are among ``others`` (m, k), to 1e-6: boolean (n,)."""
    P = np.round(np.atleast_2d(np.asarray(points, float)), 6) + 0.0        # + 0.0: no -0.0
    Q = np.round(np.asarray(others, float).reshape(-1, P.shape[1]), 6) + 0.0
    _, ids = np.unique(np.r_[P, Q], axis=0, return_inverse=True)
    ids = ids.ravel()
    return np.isin(ids[:len(P)], ids[len(P):])



def describe_box(bounds, names):
    """The design box in words: ``U 40..100 mm/s, omega -20..20 rad/s, roller.gap_um 300..400 um``
    (an input with lo == hi: ``... held at 400 um``)."""
    units = input_units(names)
    return ", ".join(f"{SHORT_NAMES.get(n, n)} " + (f"{lo:g}..{hi:g}" if hi > lo else f"held at {lo:g}")
                     + (f" {units[n]}" if units[n] else "") for (lo, hi), n in zip(bounds, names))

