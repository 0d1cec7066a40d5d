"""The operator's question: which spreader speeds give the most throughput within limits?

Usage::

    python -m analysis.surrogate.recommend --max-porosity 45 [--max-roughness 60] [--confidence 0.9] \\
        [--model results/default/surrogate/model.joblib] [--grid-points 201]

Prints the (U, omega) inside the swept range (stored with the model) whose
predicted spread throughput Q_s is highest among the speeds that meet the
porosity (%) and, if given, roughness (um) limits, with the four predicted
metrics and the calibrated interval a single new run of each would fall in
(:mod:`analysis.surrogate.intervals`).  A setting qualifies when the upper end
of that interval meets each limit: with ``--confidence 0.9`` (default: the
model's level, config ``surrogate.confidence``) at most about 5 % of runs at
that setting exceed the limit (the interval is central: 5 % above, 5 % below).
A model without calibrated intervals (an old model file) is judged on its
mean, and says so.  Exit status: 0 found, 1 no speeds meet the limits (or
none at the confidence: the message says so), 2 bad input (the message names it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from analysis.io import USER_ERRORS, error_line
from analysis.metrics.dataset import METRICS
from analysis.surrogate.intervals import check_confidence
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.predict import predict_grid, provides_intervals

DEFAULT_MODEL = "results/default/surrogate/model.joblib"


def _check_limit(name, value):
    if value is not None and not value >= 0:    # also rejects NaN
        raise ValueError(f"{name} must be a non-negative number, got {value}")


def recommend(model, meta, max_porosity_pct, max_roughness_um=None, n=201, confidence=None):
    """Speeds of highest predicted throughput whose single-run interval meets porosity and roughness limits.

    Parameters
    ----------
    model : estimator
        Fitted surrogate; with calibrated intervals
        (:func:`analysis.surrogate.predict.provides_intervals`) the limits apply to
        the upper end of the single-run interval, otherwise to the mean.
    meta : dict
        Its metadata; ``meta["input_range"]`` gives the swept range
        ``{"U_mm_s": [min, max], "omega_rad_s": [min, max]}``.
    max_porosity_pct : float
        Highest acceptable porosity Phi of a run, %.
    max_roughness_um : float, optional
        Highest acceptable roughness R_q of a run, um.
    n : int
        Grid points per axis over the swept range (resolution
        (max - min)/(n - 1) per speed).
    confidence : float, optional
        Coverage of the central single-run interval, 0 < confidence < 1 (default:
        the model's level).  Ignored (reported as None) for a model without intervals.

    Returns
    -------
    dict or None
        None if no grid point meets the limits even on the mean prediction.
        Otherwise ``U_mm_s``, ``omega_rad_s``, the four predicted metrics
        (``mass_g``, ``throughput_mm2_s``, ``roughness_um``, ``porosity_pct``),
        their single-run interval ``<metric>_lo``, ``<metric>_hi`` (NaN without
        intervals), ``confidence`` (the level applied, or None), ``n_feasible``
        (grid points whose interval meets the limits), ``n_feasible_mean`` (on the
        mean alone), ``n_grid`` and ``meets_confidence``: False when no setting's
        interval meets the limits; the point returned is then the best on the mean alone.

    Raises
    ------
    ValueError
        A negative or NaN limit, a confidence outside (0, 1) or too high for the
        model's calibration runs, n < 2, or metadata without the swept range.
    """
    _check_limit("max porosity (%)", max_porosity_pct)
    _check_limit("max roughness (um)", max_roughness_um)
    with_intervals = provides_intervals(model)
    if confidence is not None:
        confidence = check_confidence(confidence)
    if with_intervals:
        confidence = model.confidence if confidence is None else confidence
        if not model.is_finite(confidence):
            raise ValueError(f"confidence {confidence:g} needs at least {model.runs_needed(confidence)} calibration "
                             f"runs for a finite interval; this model has {model.n_runs}: use a confidence of at "
                             f"most {model.n_runs / (model.n_runs + 1):.3g}, or more runs")
    else:
        confidence = None
    if "input_range" not in meta:
        raise ValueError("the model's metadata has no swept range (input_range); refit it")
    grid = predict_grid(model, meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"], n,
                        confidence)
    for m in METRICS:
        for end in ("lo", "hi"):
            if f"{m}_{end}" not in grid:
                grid[f"{m}_{end}"] = np.nan
    limits = {"porosity_pct": max_porosity_pct, "roughness_um": max_roughness_um}
    on_mean = np.ones(len(grid), bool)
    on_interval = np.ones(len(grid), bool)
    for m, limit in limits.items():
        if limit is not None:
            on_mean &= (grid[m] <= limit).to_numpy()
            upper = grid[f"{m}_hi"].to_numpy(float) if with_intervals else grid[m].to_numpy(float)
            on_interval &= upper <= limit
    if not on_mean.any():
        return None
    pool = on_interval if on_interval.any() else on_mean
    best = grid.loc[grid["throughput_mm2_s"].where(pool).idxmax()]
    return {**{c: float(best[c]) for c in ("U_mm_s", "omega_rad_s", *METRICS)},
            **{f"{m}_{end}": float(best[f"{m}_{end}"]) for m in METRICS for end in ("lo", "hi")},
            "confidence": confidence, "meets_confidence": bool(on_interval.any()),
            "n_feasible": int(on_interval.sum()), "n_feasible_mean": int(on_mean.sum()),
            "n_grid": len(grid)}


def _range_text(meta):
    (u0, u1), (w0, w1) = meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"]
    return f"U {u0:g}..{u1:g} mm/s, omega {w0:g}..{w1:g} rad/s"


def _value(found, m, unit, fmt=".4g"):
    lo, hi = found[f"{m}_lo"], found[f"{m}_hi"]
    interval = "" if not np.isfinite(lo) else f" (a run: {lo:{fmt}}..{hi:{fmt}})"
    return f"{found[m]:{fmt}} {unit}{interval}"


def _report(found, meta, limits):
    if found["confidence"] is not None:
        level = f"{100 * found['confidence']:g} %"
        rule = (f"the upper end of the {level} single-run interval within each limit; a run: the "
                f"calibrated interval that {level} of new DEM runs at that setting fall in")
    else:
        rule = "the limits met by the predicted mean (this model has no calibrated intervals: refit it)"
    return "\n".join([
        f"Highest predicted throughput with {limits}",
        f"(surrogate grid of {found['n_grid']} points over {_range_text(meta)}; "
        f"{found['n_feasible']} meet the limits; {rule}):",
        f"  U     = {found['U_mm_s']:.1f} mm/s",
        f"  omega = {found['omega_rad_s']:.2f} rad/s",
        f"  predicted: Q_s = {_value(found, 'throughput_mm2_s', 'mm^2/s')},",
        f"             M_s = {_value(found, 'mass_g', 'g')},",
        f"             R_q = {_value(found, 'roughness_um', 'um')},",
        f"             Phi = {_value(found, 'porosity_pct', '%')}",
    ])


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """Bad arguments: one line on stderr, exit 2."""
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv=None):
    """Command-line entry; returns the exit status."""
    parser = _Parser(prog="python -m analysis.surrogate.recommend", description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-porosity", type=float, required=True, metavar="PCT",
                        help="highest acceptable spread-layer porosity of a run, %%")
    parser.add_argument("--max-roughness", type=float, metavar="UM",
                        help="highest acceptable spread-layer roughness R_q of a run, um")
    parser.add_argument("--model", default=DEFAULT_MODEL, type=Path,
                        help=f"surrogate saved by the workflow (default {DEFAULT_MODEL})")
    parser.add_argument("--grid-points", type=int, default=201, metavar="N",
                        help="grid points per speed axis (default 201)")
    parser.add_argument("--confidence", type=float, default=None, metavar="C",
                        help="coverage of the central single-run interval whose upper end must meet "
                             "each limit, between 0 and 1 (default: the model's, config "
                             "surrogate.confidence, e.g. 0.9)")
    args = parser.parse_args(argv)
    try:
        _check_limit("--max-porosity", args.max_porosity)
        _check_limit("--max-roughness", args.max_roughness)
        if args.confidence is not None and not 0 < args.confidence < 1:
            raise ValueError(f"--confidence must be between 0 and 1 (e.g. 0.9), got {args.confidence:g}")
        if args.grid_points < 2:
            raise ValueError(f"--grid-points must be at least 2, got {args.grid_points}")
        if not args.model.is_file():
            raise ValueError(f"model file not found: {args.model} (run the workflow's surrogate rule first)")
        try:
            model, meta = load_surrogate(args.model)
        except Exception as err:  # a corrupt or foreign file fails in many ways
            raise ValueError(f"cannot load model {args.model}: {err}") from err
        found = recommend(model, meta, args.max_porosity, args.max_roughness, args.grid_points,
                          args.confidence)
    except USER_ERRORS as err:
        parser.error(error_line(err))
    limits = f"porosity <= {args.max_porosity:g} %" + (
        "" if args.max_roughness is None else f" and roughness <= {args.max_roughness:g} um")
    if found is None:
        grid = predict_grid(model, meta["input_range"]["U_mm_s"],
                            meta["input_range"]["omega_rad_s"], args.grid_points)
        print(f"No speeds in {_range_text(meta)} are predicted to meet {limits}; the lowest "
              f"predicted porosity there is {grid['porosity_pct'].min():.4g} % and the lowest "
              f"roughness {grid['roughness_um'].min():.4g} um.")
        return 1
    if not found["meets_confidence"]:
        level = f"{100 * found['confidence']:g} %"
        print(f"{found['n_feasible_mean']} speeds in {_range_text(meta)} are predicted to meet "
              f"{limits} on the mean, but at none does the {level} single-run interval stay within "
              "the limits: runs there would exceed them too often. The best on the mean alone "
              f"(U = {found['U_mm_s']:.1f} mm/s, omega = {found['omega_rad_s']:.2f} rad/s) has "
              f"Phi = {_value(found, 'porosity_pct', '%')}, "
              f"R_q = {_value(found, 'roughness_um', 'um')}, "
              f"Q_s = {_value(found, 'throughput_mm2_s', 'mm^2/s')}. Simulate near it, relax the "
              "limits, or lower --confidence.")
        return 1
    print(_report(found, meta, limits))
    return 0


if __name__ == "__main__":
    sys.exit(main())
