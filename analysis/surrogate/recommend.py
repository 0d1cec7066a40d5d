"""The operator's question: which spreader speeds give the most throughput within limits?

Usage::

    python -m analysis.surrogate.recommend --max-porosity 45 [--max-roughness 60] [--margin 1] \\
        [--model results/default/surrogate/model.joblib] [--grid-points 201]

Prints the (U, omega) inside the swept range (stored with the model) whose
predicted spread throughput Q_s is highest among the speeds whose predicted
porosity (%) and, if given, roughness (um) are within the limits, with the
four predicted metrics and their predictive standard deviation.  When the
model gives one (:func:`analysis.surrogate.predict.provides_std`), a setting must meet
the limits with a margin: predicted mean + K x std <= limit (``--margin K``,
default 1), so the answer prefers settings the surrogate is sure of.  Exit
status: 0 found, 1 no speeds meet the limits (or none with the margin: the
message says so), 2 bad input (the message names it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from analysis.io import USER_ERRORS, error_line
from analysis.metrics.dataset import METRICS
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.predict import predict_grid, provides_std

DEFAULT_MODEL = "results/default/surrogate/model.joblib"


def _check_limit(name, value):
    if value is not None and not value >= 0:    # also rejects NaN
        raise ValueError(f"{name} must be a non-negative number, got {value}")


def recommend(model, meta, max_porosity_pct, max_roughness_um=None, n=201, margin=1.0):
    """Speeds of highest predicted throughput that meet porosity and roughness limits.

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    meta : dict
        Its metadata; ``meta["input_range"]`` gives the swept range
        ``{"U_mm_s": [min, max], "omega_rad_s": [min, max]}``.
    max_porosity_pct : float
        Highest acceptable predicted porosity Phi, %.
    max_roughness_um : float, optional
        Highest acceptable predicted roughness R_q, um.
    n : int
        Grid points per axis over the swept range (resolution
        (max - min)/(n - 1) per speed).
    margin : float
        K: with a model that gives a predictive std, a setting qualifies when
        ``mean + K * std`` of each limited metric is within its limit
        (0: the mean alone).  Ignored (reported as 0) for a model without std.

    Returns
    -------
    dict or None
        None if no grid point meets the limits even on the mean prediction.
        Otherwise ``U_mm_s``, ``omega_rad_s``, the four predicted metrics
        (``mass_g``, ``throughput_mm2_s``, ``roughness_um``, ``porosity_pct``),
        their ``<metric>_std`` (NaN without std), ``margin`` (the K applied),
        ``n_feasible`` (grid points meeting the limits with the margin),
        ``n_feasible_mean`` (on the mean alone), ``n_grid`` and
        ``meets_margin``: False when the margin rules out every setting; the
        point returned is then the best on the mean alone.

    Raises
    ------
    ValueError
        A negative or NaN limit or margin, n < 2, or metadata without the swept range.
    """
    _check_limit("max porosity (%)", max_porosity_pct)
    _check_limit("max roughness (um)", max_roughness_um)
    _check_limit("margin (std)", margin)
    if "input_range" not in meta:
        raise ValueError("the model's metadata has no swept range (input_range); refit it")
    grid = predict_grid(model, meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"], n)
    k = float(margin) if provides_std(model) else 0.0
    for m in METRICS:
        if f"{m}_std" not in grid:
            grid[f"{m}_std"] = np.nan
    limits = {"porosity_pct": max_porosity_pct, "roughness_um": max_roughness_um}
    on_mean = np.ones(len(grid), bool)
    with_margin = np.ones(len(grid), bool)
    for m, limit in limits.items():
        if limit is not None:
            on_mean &= (grid[m] <= limit).to_numpy()
            with_margin &= (grid[m] + k * grid[f"{m}_std"].fillna(0.0) <= limit).to_numpy()
    if not on_mean.any():
        return None
    pool = with_margin if with_margin.any() else on_mean
    best = grid.loc[grid["throughput_mm2_s"].where(pool).idxmax()]
    return {**{c: float(best[c]) for c in ("U_mm_s", "omega_rad_s", *METRICS)},
            **{f"{m}_std": float(best[f"{m}_std"]) for m in METRICS},
            "margin": k, "meets_margin": bool(with_margin.any()),
            "n_feasible": int(with_margin.sum()), "n_feasible_mean": int(on_mean.sum()),
            "n_grid": len(grid)}


def _range_text(meta):
    (u0, u1), (w0, w1) = meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"]
    return f"U {u0:g}..{u1:g} mm/s, omega {w0:g}..{w1:g} rad/s"


def _value(found, m, unit, fmt=".4g"):
    sd = found[f"{m}_std"]
    return f"{found[m]:{fmt}}" + ("" if not np.isfinite(sd) else f" +- {sd:.2g}") + f" {unit}"


def _report(found, meta, limits):
    if found["margin"] > 0:
        confidence = (f"the limits met by the predicted mean + {found['margin']:g} predictive "
                      "std (+- values: predictive std of the surrogate's mean)")
    else:
        confidence = ("the limits met by the predicted mean (this model gives no predictive std: "
                      "no margin)" if not np.isfinite(found["porosity_pct_std"])
                      else "the limits met by the predicted mean (--margin 0)")
    return "\n".join([
        f"Highest predicted throughput with {limits}",
        f"(surrogate grid of {found['n_grid']} points over {_range_text(meta)}; "
        f"{found['n_feasible']} meet the limits; {confidence}):",
        f"  U     = {found['U_mm_s']:.1f} mm/s",
        f"  omega = {found['omega_rad_s']:.2f} rad/s",
        f"  predicted: Q_s = {_value(found, 'throughput_mm2_s', 'mm^2/s')}, "
        f"M_s = {_value(found, 'mass_g', 'g')}, R_q = {_value(found, 'roughness_um', 'um')}, "
        f"Phi = {_value(found, 'porosity_pct', '%')}",
    ])


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """Bad arguments: one line on stderr, exit 2."""
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv=None):
    """Command-line entry; returns the exit status."""
    parser = _Parser(prog="python -m analysis.surrogate.recommend", description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-porosity", type=float, required=True, metavar="PCT",
                        help="highest acceptable spread-layer porosity, %%")
    parser.add_argument("--max-roughness", type=float, metavar="UM",
                        help="highest acceptable spread-layer roughness R_q, um")
    parser.add_argument("--model", default=DEFAULT_MODEL, type=Path,
                        help=f"surrogate saved by the workflow (default {DEFAULT_MODEL})")
    parser.add_argument("--grid-points", type=int, default=201, metavar="N",
                        help="grid points per speed axis (default 201)")
    parser.add_argument("--margin", type=float, default=1.0, metavar="K",
                        help="require predicted mean + K x predictive std within the limits "
                             "(default 1; 0: the mean alone)")
    args = parser.parse_args(argv)
    try:
        _check_limit("--max-porosity", args.max_porosity)
        _check_limit("--max-roughness", args.max_roughness)
        _check_limit("--margin", args.margin)
        if args.grid_points < 2:
            raise ValueError(f"--grid-points must be at least 2, got {args.grid_points}")
        if not args.model.is_file():
            raise ValueError(f"model file not found: {args.model} (run the workflow's surrogate rule first)")
        try:
            model, meta = load_surrogate(args.model)
        except Exception as err:  # a corrupt or foreign file fails in many ways
            raise ValueError(f"cannot load model {args.model}: {err}") from err
        found = recommend(model, meta, args.max_porosity, args.max_roughness, args.grid_points,
                          args.margin)
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
    if not found["meets_margin"]:
        print(f"{found['n_feasible_mean']} speeds in {_range_text(meta)} are predicted to meet "
              f"{limits} on the mean, but none by a margin of {found['margin']:g} predictive std: "
              "the surrogate is not sure enough of any of them. The best on the mean alone "
              f"(U = {found['U_mm_s']:.1f} mm/s, omega = {found['omega_rad_s']:.2f} rad/s) has "
              f"Phi = {_value(found, 'porosity_pct', '%')}, "
              f"R_q = {_value(found, 'roughness_um', 'um')}, "
              f"Q_s = {_value(found, 'throughput_mm2_s', 'mm^2/s')}. Simulate near it, or lower "
              "--margin.")
        return 1
    print(_report(found, meta, limits))
    return 0


if __name__ == "__main__":
    sys.exit(main())
