"""Adaptive Design of Simulations: fewer DEM runs for the same map.

The paper simulates a fixed 5 x 9 grid.  Here the design grows where the
surrogate is least sure:

1. a space-filling start: ``initial_points`` scrambled-Sobol (or Latin
   hypercube) points over the box spanned by the sweep
   (:func:`analysis.surrogate.design_space.sweep_bounds`):
   U and omega, and each extra axis of the sweep (``roller.gap_um: [300,
   400]``, docs/sweep.md) from its smallest to its largest listed value
   (:func:`~analysis.surrogate.design_space.initial_design`), seeded.  An extra axis with a single value is
   held at it (not a design dimension); U and omega must span a range;
2. each round, fit a Gaussian process per metric (:class:`~analysis.surrogate.candidates.GPSurrogate`)
   to every run so far and choose a batch of ``batch_size`` new points that
   maximise the expected squared prediction error
   (:func:`analysis.surrogate.acquisition.choose_batch`,
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
   :class:`analysis.adaptive_workflow.WorkflowEvaluator`), and repeat until the run budget
   ``max_runs`` is spent (the last batch is cut to fit it exactly) or the
   leave-one-out R^2, averaged over the metrics, reaches ``target_loo_r2``.

Points are snapped to a lattice (``resolution_U_mm_s``,
``resolution_omega_rad_s``; an extra axis: ``adaptive.resolution.<axis>``,
by default the smallest spacing between its listed values, so its lattice is
its listed values when they are evenly spaced:
:func:`~analysis.surrogate.design_space.sweep_resolution`) so
that run folders keep clean names and a point already simulated (by the grid
or an earlier design) is reused.  With (U, omega) alone the design, its
seeds and its points are those of the two-input design before extra axes.

:func:`run_adaptive` is the loop over any evaluator, :func:`write_result` writes what it did;
``python -m analysis.adaptive_workflow`` (:mod:`analysis.adaptive_workflow`) runs it through
the workflow.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.columns import METRICS, input_columns, input_units
from analysis.config.sweep import SPEED_AXES
from analysis.io import atomic_path
from analysis.surrogate.acquisition import ACQUISITIONS, choose_batch
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, targets_of
from analysis.surrogate.design_space import among, check_design_box, initial_design, lattice, settings_resolution
from analysis.surrogate.intervals import calibrated_from_predictions, relative_noise
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.selection import cross_validate_models


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
        The design box (:func:`~analysis.surrogate.design_space.sweep_bounds`): U (mm/s), omega (rad/s), then
        each extra axis; an extra axis with lo == hi is held at that value.
    settings : dict
        The ``adaptive:`` section of config.yaml.
    axes : sequence of str
        The extra axes (dotted config keys) of ``bounds[2:]``, in order.
    resolution : sequence of k float, optional
        Lattice spacing per input (:func:`~analysis.surrogate.design_space.sweep_resolution`); default
        :func:`~analysis.surrogate.design_space.settings_resolution` (an extra axis then needs
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
    check_design_box(bounds, resolution, names)
    budget = int(settings["max_runs"])
    target = settings.get("target_loo_r2")
    candidates = lattice(bounds, resolution)
    points = initial_design(settings["initial_points"], bounds, resolution,
                            settings["initial_design"], settings["seed"], names)
    if exclude is not None and len(exclude):
        clash = among(points, exclude)
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

