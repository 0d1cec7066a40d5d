"""Adaptive Design of Simulations: fewer DEM runs for the same map.

The paper simulates a fixed 5 x 9 grid.  Here the design grows where the
surrogate is least sure:

1. a space-filling start: ``initial_points`` scrambled-Sobol (or Latin
   hypercube) points over the box spanned by the sweep (:func:`sweep_bounds`):
   U and omega, and each extra axis of the sweep (``roller.gap_um: [300,
   400]``, docs/sweep.md) from its smallest to its largest listed value
   (:func:`initial_design`), seeded.  An extra axis with a single value is
   held at it (not a design dimension); U and omega must span a range;
2. each round, fit a Gaussian process per metric (:class:`~analysis.surrogate.candidates.GPSurrogate`)
   to every run so far and choose a batch of ``batch_size`` new points that
   maximise the expected squared prediction error (:func:`choose_batch`,
   after the MEPE criterion of Liu, Xu & Wang, 2017)::

       a(x) = w * e^2(nearest run to x) + (1 - w) * s^2(x)

   summed over the four standardised metrics: ``e`` is that run's
   leave-one-out error (large where the metrics vary faster than the GP's
   length scales expect, e.g. at the multi-layer jump), ``s^2`` the GP's
   posterior variance of the mean (large far from any run); ``w`` is
   ``error_weight``.  Within a batch the posterior variance is updated as if
   the chosen points had been run (kriging believer; the variance does not
   depend on the results) and a chosen point's own error counts as 0, so the
   batch spreads out;
3. run them (a Snakemake run that only simulates the new points:
   :class:`WorkflowEvaluator`), and repeat until the run budget
   ``max_runs`` is spent (the last batch is cut to fit it exactly) or the
   leave-one-out R^2, averaged over the metrics, reaches ``target_loo_r2``.

Points are snapped to a lattice (``resolution_U_mm_s``,
``resolution_omega_rad_s``; an extra axis: ``adaptive.resolution.<axis>``,
by default the smallest spacing between its listed values, so its lattice is
its listed values when they are evenly spaced: :func:`sweep_resolution`) so
that run folders keep clean names and a point already simulated (by the grid
or an earlier design) is reused.  With (U, omega) alone the design, its
seeds and its points are those of the two-input design before extra axes.

Command line (the loop through the workflow)::

    python -m analysis.surrogate.adaptive --level default --name adaptive --cores 2 [--max-runs 15]

writes ``results/<level>/adaptive/<name>/``: ``design.csv`` (points, round,
acquisition), ``rounds.csv`` (runs and leave-one-out scores per round),
``dataset.csv`` (the design's runs), ``model.joblib`` (the final GP, usable by
``python -m analysis.surrogate.recommend --model``) and ``round_<k>.yaml`` (the points
config each round's Snakemake run used: :func:`round_config`).  Units: U in mm/s,
omega in rad/s, an extra axis in its config units (the dataset's dotted column),
metrics as the dataset.
"""
from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.linalg import solve_triangular
from scipy.stats import qmc

from analysis.columns import METRICS, SHORT_NAMES, input_columns, input_units
from analysis.config import PROJECT_DIR, SPEED_AXES, load_config, runs_at, sweep_axes
from analysis.io import USER_ERRORS, atomic_path, error_line
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, targets_of
from analysis.surrogate.intervals import calibrated_from_predictions, relative_noise
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.selection import cross_validate_models

ROOT = PROJECT_DIR


#: acquisition functions of :func:`choose_batch` (``adaptive.acquisition``)
ACQUISITIONS = ("mepe", "imse")

#: points of the IMSE reference grid over the design box: 21 x 21 over (U, omega); with more
#: design dimensions about as many, ``round(441 ** (1 / d))`` per dimension
REFERENCE_POINTS = 441

#: entries of the largest (reference x candidate) block :func:`_variance_reduction` holds at once
_BLOCK = 20_000_000


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


def _check_bounds(bounds, resolution=None, names=None):
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
    """Every lattice point of :func:`snap` in ``bounds``: the candidates of :func:`choose_batch`.

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
    _check_bounds(bounds, resolution, names)
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


def _is_in(points, others):
    """Which of ``points`` (n, k) are among ``others`` (m, k), to 1e-6: boolean (n,)."""
    P = np.round(np.atleast_2d(np.asarray(points, float)), 6) + 0.0        # + 0.0: no -0.0
    Q = np.round(np.asarray(others, float).reshape(-1, P.shape[1]), 6) + 0.0
    _, ids = np.unique(np.r_[P, Q], axis=0, return_inverse=True)
    ids = ids.ravel()
    return np.isin(ids[:len(P)], ids[len(P):])


def _scaled_nearest(gp, X_query, X_points):
    """Index of the nearest of ``X_points`` (m, k) to each query (n, k), in standardised input units."""
    a, b = gp.x_scaler_.transform(X_query), gp.x_scaler_.transform(X_points)
    d2 = (a * a).sum(1)[:, None] - 2 * a @ b.T + (b * b).sum(1)[None, :]
    return np.argmin(d2, axis=1)


def _reference(bounds_scaled, n=None):
    """A regular grid over the standardised design box: where the integrated variance is summed.

    Parameters
    ----------
    bounds_scaled : sequence of k (lo, hi)
        The box in standardised input units; an input with lo == hi (held) is one value.
    n : int, optional
        Points per design dimension (default: ``round(REFERENCE_POINTS ** (1 / d))`` over d
        dimensions, at least 2: 21 for (U, omega)).

    Returns
    -------
    numpy.ndarray, shape (n ** d, k)
    """
    free = [hi > lo for lo, hi in bounds_scaled]
    if n is None:
        n = max(2, int(round(REFERENCE_POINTS ** (1.0 / max(sum(free), 1)))))
    axes = [np.linspace(lo, hi, n) if f else np.array([lo], float)
            for (lo, hi), f in zip(bounds_scaled, free)]
    return np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def _variance_reduction(gp, Xs_cand, Xs_train, Xs_ref, weight_ref):
    """Drop of the (weighted) mean posterior variance over ``Xs_ref`` if each candidate were run.

    For one metric with signal kernel k, noise variance s_n^2 and posterior
    covariance c(x, x') given the runs ``Xs_train``, running candidate x_c
    lowers the variance at x by ``c(x, x_c)^2 / (c(x_c, x_c) + s_n^2)``; this
    is averaged over the reference points (weights ``weight_ref``) and summed
    over the metrics (standardised units), shape (m,).  Hyperparameters are
    kept and the result does not depend on targets (kriging believer).  All
    inputs are (., k) arrays in standardised units; candidates are taken in
    blocks of at most ``_BLOCK / len(Xs_ref)`` (one block for the (U, omega)
    lattice).
    """
    out = np.zeros(len(Xs_cand))
    w = weight_ref / weight_ref.sum()
    block = max(1, _BLOCK // len(Xs_ref))
    for gp_j in gp.gps_:
        signal, noise = gp_j.kernel_.k1, gp_j.kernel_.k2.noise_level
        L = np.linalg.cholesky(gp_j.kernel_(Xs_train) + 1e-10 * np.eye(len(Xs_train)))
        Vr = solve_triangular(L, signal(Xs_train, Xs_ref), lower=True)        # (n, r)
        for start in range(0, len(Xs_cand), block):                           # blocks of candidates
            C = Xs_cand[start:start + block]
            Vc = solve_triangular(L, signal(Xs_train, C), lower=True)         # (n, b)
            cov = signal(Xs_ref, C) - Vr.T @ Vc                                # (r, b)
            var_c = np.clip(signal.diag(C) - np.sum(Vc * Vc, axis=0), 0.0, None)
            out[start:start + block] += (w @ (cov * cov)) / (var_c + noise)
    return out


def choose_batch(gp, X, candidates, batch_size, error_weight=0.5, exclude=None,
                 acquisition="mepe", bounds=None):
    """Choose ``batch_size`` new points by expected prediction error or integrated variance.

    Parameters
    ----------
    gp : analysis.surrogate.candidates.GPSurrogate
        Fitted on the runs X (all replicates).
    X : numpy.ndarray, shape (n, k)
        Inputs of the runs it was fitted on: U (mm/s), omega (rad/s), then the
        extra axes (config units), in the GP's input order.
    candidates : numpy.ndarray, shape (m, k)
        Where new points may go (a lattice, :func:`lattice`).
    batch_size : int
    error_weight : float
        w in [0, 1]: weight of the nearest run's leave-one-out error.
    exclude : numpy.ndarray, shape (e, k), optional
        Points never to choose (e.g. a held-out test set); existing points
        are never chosen again.
    acquisition : {"mepe", "imse"}
        ``"mepe"``: a(x) = w e^2(nearest run) + (1 - w) s^2(x), the point
        where the map is least sure (module docstring).  ``"imse"``: the
        point whose run would most lower the posterior variance averaged
        over the whole design box (integrated mean squared error, Cohn's
        active learning), each place of the box weighted by
        ``(1 - w) + w e^2(nearest run) / mean(e^2)``.  Maximum variance
        tends to pick the box's edges and corners; IMSE picks points that
        serve the most of the map, which is what the map error measures.
    bounds : sequence of k (lo, hi), optional
        The design box for ``"imse"``, in the inputs' units (default: the
        candidates' extent); an input with lo == hi is held.

    Returns
    -------
    points : numpy.ndarray, shape (b, k)
    acquisition : numpy.ndarray, shape (b,)
        a(x) of each chosen point when it was chosen (standardised units).
    """
    if acquisition not in ACQUISITIONS:
        raise ValueError(f"unknown acquisition {acquisition!r}; choose one of {ACQUISITIONS}")
    X = np.asarray(X, float)
    points, inverse = np.unique(X, axis=0, return_inverse=True)
    # leave-one-out squared error per run, standardised and summed over metrics;
    # averaged over the replicates of each point
    e2_run = np.sum((gp.loo_residuals() / gp.y_scale_) ** 2, axis=1)
    e2 = np.bincount(inverse.ravel(), weights=e2_run) / np.bincount(inverse.ravel())
    taken = points if exclude is None else np.r_[points, np.asarray(exclude, float).reshape(-1, X.shape[1])]
    keep = ~_is_in(candidates, taken)
    cand = candidates[keep]
    if len(cand) < batch_size:
        raise ValueError(f"only {len(cand)} candidate points left for a batch of {batch_size}")
    Xs_train = gp.x_scaler_.transform(X)
    Xs_cand = gp.x_scaler_.transform(cand)
    if acquisition == "imse":
        if bounds is None:
            bounds = tuple((float(lo), float(hi)) for lo, hi in zip(candidates.min(0),
                                                                   candidates.max(0)))
        corners = gp.x_scaler_.transform(np.array(bounds, float).T)
        ref = _reference(tuple(zip(corners[0], corners[1])))
        ref_e2 = e2[_scaled_nearest(gp, gp.x_scaler_.inverse_transform(ref), points)]
        weight_ref = (1.0 - error_weight) + error_weight * ref_e2 / max(e2.mean(), 1e-12)
    chosen, values = [], []
    for _ in range(int(batch_size)):          # batch slots, each a vectorised sweep of candidates
        if acquisition == "imse":
            acq = _variance_reduction(gp, Xs_cand, Xs_train, ref, weight_ref)
        else:
            var = gp._latent_var(Xs_cand, Xs_train).sum(axis=1)
            design = np.r_[points, cand[chosen]] if chosen else points
            err = np.r_[e2, np.zeros(len(chosen))][_scaled_nearest(gp, cand, design)]
            acq = error_weight * err + (1.0 - error_weight) * var
        acq[chosen] = -np.inf
        best = int(np.argmax(acq))
        chosen.append(best)
        values.append(float(acq[best]))
        Xs_train = np.r_[Xs_train, Xs_cand[best:best + 1]]
    return cand[chosen], np.array(values)


def loo_r2(gp, Y):
    """Leave-one-out R^2 per metric of a GP fitted on Y (n, 4), from its closed-form residuals."""
    r = gp.loo_residuals()
    Y = np.asarray(Y, float)
    ss = ((Y - Y.mean(axis=0)) ** 2).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ss > 0, 1.0 - (r * r).sum(axis=0) / ss, np.nan)


@dataclass
class AdaptiveResult:
    """What :func:`run_adaptive` did.

    Attributes
    ----------
    design : pandas.DataFrame
        One row per point: ``U_mm_s``, ``omega_rad_s``, the extra axes (dotted
        config keys, config units), ``round`` (0: initial design),
        ``acquisition`` (NaN for the initial design).
    data : pandas.DataFrame
        Every run (rows returned by the evaluator).
    rounds : pandas.DataFrame
        One row per round: ``round``, ``n_points``, ``n_runs``,
        ``loo_R2_<metric>``, ``loo_R2_mean``, ``wall_s``.
    model : GPSurrogate
        The GP fitted on all runs.
    stop : str
        ``"budget"`` or ``"target"``.
    """
    design: pd.DataFrame
    data: pd.DataFrame
    rounds: pd.DataFrame
    model: GPSurrogate
    stop: str
    history: list = field(default_factory=list)


def check_settings(settings, replicates=1, axes=()):
    """Raise ValueError naming the bad ``adaptive:`` value.

    ``axes`` are the sweep's extra axes: the only keys ``adaptive.resolution`` may give
    a (positive) lattice spacing for.
    """
    for axis, value in (settings.get("resolution") or {}).items():
        if axis not in axes:
            raise ValueError(f"adaptive.resolution.{axis}: not an extra axis of the sweep ("
                             + (", ".join(axes) or "it has none")
                             + "); U and omega take adaptive.resolution_U_mm_s and resolution_omega_rad_s")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise ValueError(f"adaptive.resolution.{axis} = {value!r}: the lattice spacing must be a "
                             "positive number")
    if settings.get("acquisition", "mepe") not in ACQUISITIONS:
        raise ValueError(f"adaptive.acquisition = {settings['acquisition']!r}: choose one of "
                         f"{ACQUISITIONS}")
    budget_points = int(settings["max_runs"]) // int(replicates)
    if int(settings["initial_points"]) > budget_points:
        raise ValueError(f"adaptive.initial_points = {settings['initial_points']} x "
                         f"{replicates} replicate(s) exceeds the run budget adaptive.max_runs = "
                         f"{settings['max_runs']}")
    if int(settings["initial_points"]) < 4:
        raise ValueError(f"adaptive.initial_points = {settings['initial_points']}: at least 4 "
                         "points are needed to fit the first surrogate")


def _design_rows(points, names, round_, acquisition):
    """Rows of ``design.csv``: the points (b, k) under the inputs' ``names``, ``round``, ``acquisition``."""
    rows = pd.DataFrame(np.asarray(points, float), columns=list(names))
    rows["round"] = round_
    rows["acquisition"] = acquisition
    return rows


def _evaluated(evaluate, points, names):
    """``evaluate(points)``, checked to return rows over the design's inputs, in order."""
    data = evaluate(points)
    if input_columns(data) != list(names):
        raise ValueError(f"the evaluator returned runs over {', '.join(input_columns(data))}; the design's "
                         f"inputs are {', '.join(names)}")
    return data


def run_adaptive(evaluate, bounds, settings, *, axes=(), resolution=None, replicates=1, exclude=None,
                 gp_params=None, on_round=None, log=print):
    """The adaptive loop: initial design, then batches by expected error until the budget.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(points)`` with points (b, k): U (mm/s), omega (rad/s), then
        the extra axes (config units), returns a DataFrame of their runs:
        ``U_mm_s``, ``omega_rad_s``, a column per extra axis (named by it, in
        that order) and the four metrics, ``replicates`` rows per point.
    bounds : sequence of k (lo, hi)
        The design box (:func:`sweep_bounds`): U (mm/s), omega (rad/s), then
        each extra axis; an extra axis with lo == hi is held at that value.
    settings : dict
        The ``adaptive:`` section of config.yaml.
    axes : sequence of str
        The extra axes (dotted config keys) of ``bounds[2:]``, in order.
    resolution : sequence of k float, optional
        Lattice spacing per input (:func:`sweep_resolution`); default
        :func:`settings_resolution` (an extra axis then needs
        ``settings["resolution"][axis]``).
    replicates : int
        Runs per point (counts against ``max_runs``).
    exclude : array (e, k), optional
        Points never chosen (a held-out test set).
    gp_params : dict, optional
        Keyword arguments of :class:`~analysis.surrogate.candidates.GPSurrogate`.
    on_round : callable, optional
        ``on_round(round_index, data, gp)`` after each fit (e.g. to score
        against held-out runs).
    log : callable
        Receives one progress line per round.

    Returns
    -------
    AdaptiveResult
    """
    names = [*SPEED_AXES, *axes]
    check_settings(settings, replicates, tuple(axes))
    resolution = settings_resolution(settings, axes) if resolution is None else tuple(map(float, resolution))
    _check_bounds(bounds, resolution, names)
    budget = int(settings["max_runs"])
    target = settings.get("target_loo_r2")
    candidates = lattice(bounds, resolution)
    points = initial_design(settings["initial_points"], bounds, resolution,
                            settings["initial_design"], settings["seed"], names)
    if exclude is not None and len(exclude):
        clash = _is_in(points, exclude)
        if clash.any():
            raise ValueError(f"initial design points {points[clash].tolist()} are in the "
                             "excluded (held-out) set; change adaptive.seed")
    design = _design_rows(points, names, 0, np.nan)
    t0 = time.perf_counter()
    data = _evaluated(evaluate, points, names)
    rounds = []
    k = 0
    while True:
        gp = GPSurrogate(**(gp_params or {})).fit(inputs_of(data), targets_of(data))
        r2 = loo_r2(gp, targets_of(data))
        row = {"round": k, "n_points": len(design), "n_runs": len(data),
               **{f"loo_R2_{m}": float(v) for m, v in zip(METRICS, r2)},
               "loo_R2_mean": float(np.nanmean(r2)), "wall_s": round(time.perf_counter() - t0, 1)}
        rounds.append(row)
        if on_round:
            on_round(k, data, gp)
        new = design[design["round"] == k]
        log(f"round {k}: {len(new)} new point(s) "
            + ", ".join("(" + ", ".join(f"{v:g}" for v in p) + ")" for p in new[names].to_numpy())
            + f"; {len(data)} runs in all; leave-one-out R^2 "
            + " / ".join(f"{v:.3f}" for v in r2) + f" (mean {row['loo_R2_mean']:.3f})")
        if target is not None and row["loo_R2_mean"] >= float(target):
            stop = "target"
            break
        room = (budget - len(data)) // int(replicates)
        if room <= 0:
            stop = "budget"
            break
        k += 1
        batch, acq = choose_batch(gp, inputs_of(data), candidates,
                                  min(int(settings["batch_size"]), room),
                                  float(settings["error_weight"]), exclude,
                                  settings.get("acquisition", "mepe"), bounds)
        design = pd.concat([design, _design_rows(batch, names, k, acq)], ignore_index=True)
        data = pd.concat([data, _evaluated(evaluate, batch, names)], ignore_index=True)
    log(f"stopped at round {k}: {'run budget' if stop == 'budget' else 'target accuracy'} "
        f"({len(data)} runs of {budget})")
    return AdaptiveResult(design, data, pd.DataFrame(rounds), gp, stop)


def round_config(level, points, axes=(), replicates=1, n_test=1, cv_folds=None):
    """The config a round's Snakemake run adds to the base config (``--configfile base round``).

    Parameters
    ----------
    level : str
        Fidelity level.
    points : array_like, shape (n, k)
        Every design point so far: U (mm/s), omega (rad/s), then the extra axes (config units).
    axes : sequence of str
        The sweep's extra axes (dotted config keys), the columns ``points[:, 2:]``.
    replicates : int
    n_test : int
        ``surrogate.n_test`` (the workflow's surrogate checks it against the points).
    cv_folds : int, optional
        ``surrogate.cv_folds``, at most the points (the config check refuses more); default: the base's.

    Returns
    -------
    dict
        ``level``, ``sweep`` and ``surrogate``.  The points are ``sweep.points`` over every
        axis, or ``sweep.points_mm_s_rad_s`` (U, omega pairs) when there are no extra axes;
        the base config's axis lists stay and give the range.
    """
    P = np.atleast_2d(np.asarray(points, float))
    names = [*SPEED_AXES, *axes]
    if P.shape[1] != len(names):
        raise ValueError(f"points have {P.shape[1]} columns for the {len(names)} inputs {', '.join(names)}")
    listed = ({"points": [dict(zip(names, map(float, p))) for p in P]} if len(axes) else
              {"points_mm_s_rad_s": [[float(u), float(w)] for u, w in P]})
    return {"level": level, "sweep": {**listed, "replicates": int(replicates)},
            "surrogate": {"n_test": int(n_test), **({} if cv_folds is None else
                                                    {"cv_folds": int(min(cv_folds, max(2, len(P))))})}}


class WorkflowEvaluator:
    """Run design points through the Snakemake workflow; return their dataset rows.

    Each call writes ``<outdir>/round_<k>.yaml`` (:func:`round_config`: every
    point so far), asks Snakemake for those runs' ``metrics.json`` (so only
    runs not yet done are simulated: runs of the grid or of other designs at
    the same point are reused) and gathers the requested points' runs with
    :func:`analysis.metrics.dataset.build_dataset` (the workflow's own
    ``results/<level>/dataset.csv`` is left alone).  The run folders are the
    round config's own (:func:`analysis.config.runs_at` over the base config
    merged with the round's, as Snakemake merges them), so they follow the
    workflow's naming.  The extra axes are the base config's
    (:func:`analysis.config.sweep_axes`); points are (b, k): U (mm/s),
    omega (rad/s), then each axis (config units).

    Parameters
    ----------
    level : str
        Fidelity level.
    outdir : pathlib.Path
        Where the round configs and datasets go.
    workdir : pathlib.Path
        Snakemake's working directory (its ``results/`` holds the runs).
    cores : int
        ``snakemake --cores``.
    replicates : int
    configfile : pathlib.Path
        The base config (default: the repository's config.yaml).
    log : callable
    """

    def __init__(self, level, outdir, workdir=ROOT, cores=2, replicates=1, configfile=None,
                 log=print):
        self.level, self.outdir, self.workdir = level, Path(outdir), Path(workdir)
        self.cores, self.replicates, self.log = int(cores), int(replicates), log
        self.configfile = Path(configfile or ROOT / "config.yaml")
        self.base = yaml.safe_load(self.configfile.read_text())
        self.axes = sweep_axes(self.base)
        self.points = []
        self.calls = 0

    def resolved(self, round_cfg):
        """The config Snakemake runs the round with: the base updated by ``round_cfg``
        (Snakemake's ``update_config``), loaded and checked (:func:`analysis.config.load_config`)."""
        from snakemake.utils import update_config
        merged = copy.deepcopy(self.base)
        update_config(merged, round_cfg)
        return load_config(merged, base_dir=ROOT)

    def run_table(self, points, config):
        """The runs (:class:`analysis.config.Run`) of the points (b, k), every replicate, in ``config``."""
        names = [*SPEED_AXES, *self.axes]
        return runs_at(config, [dict(zip(names, p)) for p in np.atleast_2d(points).tolist()])

    def runs(self, points, config):
        """Run folder names (under ``runs/``) of the points (b, k), every replicate, in ``config``."""
        return [run.name for run in self.run_table(points, config)]

    def __call__(self, points):
        from analysis.metrics.dataset import build_dataset
        points = np.atleast_2d(np.asarray(points, float))
        known = {tuple(p) for p in self.points}
        self.points += [tuple(p) for p in points if tuple(p) not in known]
        self.outdir.mkdir(parents=True, exist_ok=True)
        round_path = self.outdir / f"round_{self.calls}.yaml"
        cfg = round_config(self.level, self.points, self.axes, self.replicates,
                           n_test=max(1, min(2, len(self.points) - 3)),
                           cv_folds=self.base["surrogate"]["cv_folds"])
        with atomic_path(round_path) as tmp:
            tmp.write_text(yaml.safe_dump(cfg, sort_keys=False))
        table = self.run_table(points, self.resolved(cfg))
        runs = [run.name for run in table]
        out = f"results/{self.level}"
        targets = [f"{out}/runs/{run}/metrics.json" for run in runs]
        log_path = self.workdir / f"results/logs/{self.level}/adaptive/{self.outdir.name}_round{self.calls}.log"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "snakemake", *targets, "-s", str(ROOT / "Snakefile"),
               "-d", str(self.workdir), "--configfile", str(self.configfile), str(round_path),
               "--cores", str(self.cores), "--rerun-incomplete"]
        t0 = time.perf_counter()
        with open(log_path, "w") as f:
            proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
        if proc.returncode != 0:
            tail = "".join(log_path.read_text().splitlines(keepends=True)[-25:])
            raise RuntimeError(f"snakemake failed for round {self.calls} (log {log_path}):\n{tail}")
        done = log_path.read_text().count("rule spread:")
        self.log(f"  snakemake: {len(runs)} run(s) requested, {done} simulated, "
                 f"{time.perf_counter() - t0:.0f} s (config {round_path.name})")
        bench = f"results/benchmarks/{self.level}"
        base = self.workdir
        data = build_dataset([base / f"{out}/runs/{r}/metrics.json" for r in runs],
                             [base / f"{out}/runs/{r}/health.json" for r in runs],
                             [base / f"{bench}/spread/{r}.tsv" for r in runs],
                             self.outdir / f"runs_round{self.calls}.csv", points=[run.point for run in table])
        self.calls += 1
        return data


def describe_box(bounds, names):
    """The design box in words: ``U 40..100 mm/s, omega -20..20 rad/s, roller.gap_um 300..400 um``
    (an input with lo == hi: ``... held at 400 um``)."""
    units = input_units(names)
    return ", ".join(f"{SHORT_NAMES.get(n, n)} " + (f"{lo:g}..{hi:g}" if hi > lo else f"held at {lo:g}")
                     + (f" {units[n]}" if units[n] else "") for (lo, hi), n in zip(bounds, names))


def write_result(result, outdir, level, extra_meta=None, surrogate_params=None):
    """Write design.csv, rounds.csv, dataset.csv and model.joblib of a run into ``outdir``.

    With ``surrogate_params`` (config's ``surrogate:``) the GP is saved with its intervals
    calibrated on its grouped k-fold held-out predictions over the design's runs
    (:mod:`analysis.surrogate.intervals`), so ``spreadmap-recommend`` can use them.
    """
    outdir = Path(outdir)
    for name, frame in (("design", result.design), ("rounds", result.rounds),
                        ("dataset", result.data)):
        with atomic_path(outdir / f"{name}.csv") as tmp:
            frame.to_csv(tmp, index=False)
    X, inputs = inputs_of(result.data), input_columns(result.data)
    meta = {"level": level, "kind": "adaptive design GP", "stop": result.stop,
            "n_runs": len(result.data), "inputs": input_units(inputs),
            "input_range": {c: [float(X[:, j].min()), float(X[:, j].max())]
                            for j, c in enumerate(inputs)},
            "model": {"name": "gp", "length_scale": result.model.length_scales_.tolist(),
                      "noise_std": result.model.noise_std_.tolist()},
            **(extra_meta or {})}
    model = result.model
    if surrogate_params is not None:
        params = {**surrogate_params, "models": ["gp"], "cv_loo": False}
        _, held_out = cross_validate_models(result.data, params, return_predictions=True)
        rho, source = relative_noise(result.data, random_state=int(params["random_state"]))
        model = calibrated_from_predictions(model, held_out[held_out.scheme == "kfold"], result.data, rho,
                                            params["confidence"], source)
        meta["model"]["intervals"] = model.summary()
    save_surrogate(model, outdir / "model.joblib", meta)


def main(argv=None):
    """Command line: the adaptive loop through the workflow (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m analysis.surrogate.adaptive",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "config.yaml",
                        help="base config (default: the repository's config.yaml)")
    parser.add_argument("--level", help="fidelity level (default: the config's)")
    parser.add_argument("--name", default="adaptive", help="results/<level>/adaptive/<NAME>/")
    parser.add_argument("--cores", type=int, default=2, help="snakemake --cores (default 2)")
    parser.add_argument("--workdir", type=Path, default=ROOT, help="Snakemake working directory")
    for key, kind in (("initial_points", int), ("batch_size", int), ("max_runs", int),
                      ("target_loo_r2", float), ("acquisition", str), ("error_weight", float),
                      ("seed", int)):
        parser.add_argument("--" + key.replace("_", "-"), dest=key, type=kind,
                            help=f"overrides adaptive.{key}")
    args = parser.parse_args(argv)
    try:
        config = load_config(args.config)
        level = args.level or config["level"]
        if level not in config["fidelity"]:
            raise ValueError(f"--level {level}: no such fidelity level; choose one of "
                             f"{sorted(config['fidelity'])}")
        settings = {**config["adaptive"], **{k: v for k, v in vars(args).items()
                                               if k in config["adaptive"] and v is not None}}
        replicates = int(config["sweep"]["replicates"])
        axes = sweep_axes(config)
        check_settings(settings, replicates, axes)
        bounds, resolution = sweep_bounds(config), sweep_resolution(config, settings)
        _check_bounds(bounds, resolution, design_inputs(config))
        if args.cores < 1:
            raise ValueError(f"--cores must be at least 1, got {args.cores}")
    except USER_ERRORS as err:  # ConfigError is a ValueError
        parser.exit(2, f"{parser.prog}: error: {error_line(err)}\n")
    outdir = args.workdir / f"results/{level}/adaptive/{args.name}"
    print(f"adaptive design at level {level}: {describe_box(bounds, design_inputs(config))}; "
          f"{settings['initial_points']} initial "
          f"points, batches of {settings['batch_size']}, budget {settings['max_runs']} runs; "
          f"writing {outdir}", flush=True)
    evaluator = WorkflowEvaluator(level, outdir, args.workdir, args.cores, replicates, args.config,
                                  log=lambda line: print(line, flush=True))
    try:
        result = run_adaptive(evaluator, bounds, settings, axes=axes, resolution=resolution,
                              replicates=replicates, log=lambda line: print(line, flush=True))
        write_result(result, outdir, level, surrogate_params=config["surrogate"])
    except USER_ERRORS as err:
        print(f"{parser.prog}: error: {error_line(err)}", file=sys.stderr)
        return 1
    print(f"wrote {outdir}/design.csv, rounds.csv, dataset.csv, model.joblib")
    return 0


if __name__ == "__main__":
    sys.exit(main())
