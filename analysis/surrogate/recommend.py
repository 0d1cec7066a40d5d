"""The operator's question: which spreader speeds give the most throughput within limits?

Usage::

    python -m analysis.surrogate.recommend --max-porosity 45 [--max-roughness 60] [--confidence 0.9] \\
        [--model results/default/surrogate/model.joblib] [--grid-points 201] [--fix roller.gap_um=300] \\
        [--axis-points 11]

Prints the (U, omega), and the value of every other swept axis (e.g. the gap,
``roller.gap_um``), inside the swept range (stored with the model) whose
predicted spread throughput Q_s is highest among the settings that meet the
porosity (%) and, if given, roughness (um) limits, with the four predicted
metrics and the calibrated interval a single new run of each would fall in
(:mod:`analysis.surrogate.intervals`).  A setting qualifies when the upper end
of that interval meets each limit: with ``--confidence 0.9`` (default: the
model's level, config ``surrogate.confidence``) at most about 5 % of runs at
that setting exceed the limit (the interval is central: 5 % above, 5 % below).
A model without calibrated intervals (an old model file) is judged on its
mean, and says so.  ``--fix roller.gap_um=300`` holds an axis at a value (the gap
the job needs; any input, within its swept range).  Exit status: 0 found, 1 no speeds meet the limits (or
none at the confidence: the message says so), 2 bad input (the message names it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from analysis.columns import METRICS, SHORT_NAMES, input_units
from analysis.config.reading import load_schema
from analysis.io import USER_ERRORS, error_line
from analysis.surrogate.intervals import check_confidence
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.predict import predict_frame, provides_intervals

DEFAULT_MODEL = "results/default/surrogate/model.joblib"


def _check_limit(name, value):
    if value is not None and not value >= 0:    # also rejects NaN
        raise ValueError(f"{name} must be a non-negative number, got {value}")


def search_grid(meta, n=201, fixed=None, axis_points=11):
    """The settings a recommendation searches: every input's values over its swept range.

    Parameters
    ----------
    meta : dict
        The model's metadata: ``inputs`` (names and units, the model's order) and
        ``input_range`` (``{input: [min, max]}``).
    n : int
        Points over the range of U and of omega (>= 2).
    fixed : dict, optional
        ``{input: value}`` held at that value (in the input's units; within its range).
    axis_points : int
        Points over the range of each other input (>= 2).

    Returns
    -------
    dict
        ``{input: 1-D array}`` in the model's input order (a regular grid's axes).

    Raises
    ------
    ValueError
        n or axis_points < 2, an unknown input, or a fixed value outside the swept range.
    """
    if "input_range" not in meta:
        raise ValueError("the model's metadata has no swept range (input_range); refit it")
    if int(n) < 2 or int(axis_points) < 2:
        raise ValueError(f"grid needs at least 2 points per axis, got {n} and {axis_points}")
    names = list(meta.get("inputs") or meta["input_range"])
    fixed = dict(fixed or {})
    unknown = sorted(set(fixed) - set(names))
    if unknown:
        raise ValueError(f"cannot fix {', '.join(unknown)}: the model's inputs are {', '.join(names)}")
    axes = {}
    for name in names:
        lo, hi = meta["input_range"][name]
        if name in fixed:
            value = float(fixed[name])
            if not lo - 1e-9 * max(1.0, abs(lo)) <= value <= hi + 1e-9 * max(1.0, abs(hi)):
                raise ValueError(f"{name} = {value:g} lies outside the swept range {lo:g}..{hi:g}: "
                                 "the surrogate would extrapolate")
            axes[name] = np.array([value])
        else:
            axes[name] = np.linspace(lo, hi, int(n) if name in ("U_mm_s", "omega_rad_s") else int(axis_points))
    return axes


def recommend(model, meta, max_porosity_pct, max_roughness_um=None, n=201, confidence=None, fixed=None,
              axis_points=11):
    """Setting of highest predicted throughput whose single-run interval meets porosity and roughness limits.

    Searches every swept input: U and omega, and any other axis the model has (e.g.
    ``roller.gap_um``), each over its swept range, or held at a value (``fixed``).

    Parameters
    ----------
    model : estimator
        Fitted surrogate; with calibrated intervals
        (:func:`analysis.surrogate.predict.provides_intervals`) the limits apply to
        the upper end of the single-run interval, otherwise to the mean.
    meta : dict
        Its metadata; ``meta["input_range"]`` gives the swept range
        ``{"U_mm_s": [min, max], "omega_rad_s": [min, max], ...}``, ``meta["inputs"]``
        the inputs in the model's order (default: the speeds).
    max_porosity_pct : float
        Highest acceptable porosity Phi of a run, %.
    max_roughness_um : float, optional
        Highest acceptable roughness R_q of a run, um.
    n : int
        Grid points per speed axis over the swept range (resolution
        (max - min)/(n - 1) per speed).
    confidence : float, optional
        Coverage of the central single-run interval, 0 < confidence < 1 (default:
        the model's level).  Ignored (reported as None) for a model without intervals.
    fixed : dict, optional
        ``{input: value}`` held fixed (the input's units), e.g. ``{"roller.gap_um": 300}``.
    axis_points : int
        Grid points over the range of each input other than the speeds.

    Returns
    -------
    dict or None
        None if no grid point meets the limits even on the mean prediction.
        Otherwise every input (``U_mm_s``, ``omega_rad_s``, and the other axes), the four predicted metrics
        (``mass_g``, ``throughput_mm2_s``, ``roughness_um``, ``porosity_pct``),
        their single-run interval ``<metric>_lo``, ``<metric>_hi`` (NaN without
        intervals), ``confidence`` (the level applied, or None), ``n_feasible``
        (grid points whose interval meets the limits), ``n_feasible_mean`` (on the
        mean alone), ``n_grid``, ``inputs`` (the input names) and ``meets_confidence``: False when no
        setting's interval meets the limits; the point returned is then the best on the mean alone.

    Raises
    ------
    ValueError
        A negative or NaN limit, a confidence outside (0, 1) or too high for the
        model's calibration runs, n < 2, metadata without the swept range, or a fixed
        value that is not an input or lies outside its range.
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
    grid = _predict_search_grid(model, meta, n, fixed, axis_points, confidence)
    names = list(search_grid(meta, 2, fixed, 2))
    for m in METRICS:
        for end in ("lo", "hi"):
            if f"{m}_{end}" not in grid:
                grid[f"{m}_{end}"] = np.nan
    on_mean, on_interval = meets_limits(grid, max_porosity_pct, max_roughness_um, with_intervals)
    if not on_mean.any():
        return None
    pool = on_interval if on_interval.any() else on_mean
    best = grid.loc[grid["throughput_mm2_s"].where(pool).idxmax()]
    return {**{c: float(best[c]) for c in (*names, *METRICS)},
            **{f"{m}_{end}": float(best[f"{m}_{end}"]) for m in METRICS for end in ("lo", "hi")},
            "confidence": confidence, "meets_confidence": bool(on_interval.any()),
            "n_feasible": int(on_interval.sum()), "n_feasible_mean": int(on_mean.sum()),
            "n_grid": len(grid), "inputs": names}


def meets_limits(grid, max_porosity_pct, max_roughness_um=None, with_intervals=True):
    """Which rows of a prediction frame meet the porosity (%) and roughness (um) limits (None: no limit).

    Returns
    -------
    on_mean, on_interval : numpy.ndarray of bool
        The predicted mean within every limit; the upper end of the single-run interval
        (``<metric>_hi``) within every limit (the mean, when ``with_intervals`` is False).
    """
    on_mean = np.ones(len(grid), bool)
    on_interval = np.ones(len(grid), bool)
    for m, limit in {"porosity_pct": max_porosity_pct, "roughness_um": max_roughness_um}.items():
        if limit is not None:
            on_mean &= (grid[m] <= limit).to_numpy()
            upper = grid[f"{m}_hi"].to_numpy(float) if with_intervals else grid[m].to_numpy(float)
            on_interval &= upper <= limit
    return on_mean, on_interval


def _predict_search_grid(model, meta, n, fixed, axis_points, confidence=None):
    """Predictions over :func:`search_grid` (the other inputs outer, then U, then omega)."""
    axes = search_grid(meta, n, fixed, axis_points)
    speeds, others = ("U_mm_s", "omega_rad_s"), [a for a in axes if a not in ("U_mm_s", "omega_rad_s")]
    mesh = np.meshgrid(*(axes[a] for a in (*others, *speeds)), indexing="ij")
    flat = dict(zip((*others, *speeds), (m.ravel() for m in mesh)))
    return predict_frame(model, flat["U_mm_s"], flat["omega_rad_s"], confidence, {a: flat[a] for a in others})


def _range_text(meta, fixed=None):
    fixed, units = fixed or {}, meta.get("inputs") or {}
    parts = []
    for name, (lo, hi) in meta["input_range"].items():
        unit = units.get(name) or input_units([name])[name]
        text = f"{fixed[name]:g}" if name in fixed else f"{lo:g}..{hi:g}"
        parts.append(f"{SHORT_NAMES.get(name, name)} {text} {unit}".rstrip())
    return ", ".join(parts)


def _value(found, m, unit, fmt=".4g"):
    lo, hi = found[f"{m}_lo"], found[f"{m}_hi"]
    interval = "" if not np.isfinite(lo) else f" (a run: {lo:{fmt}}..{hi:{fmt}})"
    return f"{found[m]:{fmt}} {unit}{interval}"


def _setting_lines(found, meta):
    """One line per input of the found setting."""
    units = meta.get("inputs") or {}
    lines = [f"  U     = {found['U_mm_s']:.1f} mm/s", f"  omega = {found['omega_rad_s']:.2f} rad/s"]
    return lines + [f"  {name} = {found[name]:.4g} {units.get(name, '')}".rstrip()
                    for name in found["inputs"] if name not in ("U_mm_s", "omega_rad_s")]


def _report(found, meta, limits, fixed=None):
    if found["confidence"] is not None:
        level = f"{100 * found['confidence']:g} %"
        rule = (f"the upper end of the {level} single-run interval within each limit; a run: the "
                f"calibrated interval that {level} of new DEM runs at that setting fall in")
    else:
        rule = "the limits met by the predicted mean (this model has no calibrated intervals: refit it)"
    return "\n".join([
        f"Highest predicted throughput with {limits}",
        f"(surrogate grid of {found['n_grid']} points over {_range_text(meta, fixed)}; "
        f"{found['n_feasible']} meet the limits; {rule}):",
        *_setting_lines(found, meta),
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
    parser.add_argument("--fix", action="append", default=[], metavar="AXIS=VALUE",
                        help="hold an input at a value in its units, e.g. roller.gap_um=300 (the gap the job "
                             "needs) or U_mm_s=70; repeatable; default: every input over its swept range")
    parser.add_argument("--axis-points", type=int, default=11, metavar="N",
                        help="grid points over the range of each input other than the speeds (default 11)")
    args = parser.parse_args(argv)
    try:
        fixed = _parse_fixed(args.fix)
        _check_limit("--max-porosity", args.max_porosity)
        _check_limit("--max-roughness", args.max_roughness)
        if args.confidence is not None and not 0 < args.confidence < 1:
            raise ValueError(f"--confidence must be between 0 and 1 (e.g. 0.9), got {args.confidence:g}")
        most = load_schema()["properties"]["surrogate"]["properties"]["grid_points"]["maximum"]
        if not 2 <= args.grid_points <= most:
            raise ValueError(f"--grid-points must be 2 to {most} (config surrogate.grid_points' bound: memory), "
                             f"got {args.grid_points}")
        if not 2 <= args.axis_points <= MAX_AXIS_POINTS:
            raise ValueError(f"--axis-points must be 2 to {MAX_AXIS_POINTS} (memory), got {args.axis_points}")
        if not args.model.is_file():
            raise ValueError(f"model file not found: {args.model} (run the workflow's surrogate rule first)")
        try:
            model, meta = load_surrogate(args.model)
        except Exception as err:  # a corrupt or foreign file fails in many ways
            raise ValueError(f"cannot load model {args.model}: {err}") from err
        found = recommend(model, meta, args.max_porosity, args.max_roughness, args.grid_points,
                          args.confidence, fixed, args.axis_points)
    except USER_ERRORS as err:
        parser.error(error_line(err))
    limits = f"porosity <= {args.max_porosity:g} %" + (
        "" if args.max_roughness is None else f" and roughness <= {args.max_roughness:g} um")
    if found is None:
        grid = _predict_search_grid(model, meta, args.grid_points, fixed, args.axis_points)
        print(f"No speeds in {_range_text(meta, fixed)} are predicted to meet {limits}; the lowest "
              f"predicted porosity there is {grid['porosity_pct'].min():.4g} % and the lowest "
              f"roughness {grid['roughness_um'].min():.4g} um.")
        return 1
    if not found["meets_confidence"]:
        level = f"{100 * found['confidence']:g} %"
        setting = ", ".join(line.strip() for line in _setting_lines(found, meta))
        print(f"{found['n_feasible_mean']} settings in {_range_text(meta, fixed)} are predicted to meet "
              f"{limits} on the mean, but at none does the {level} single-run interval stay within "
              "the limits: runs there would exceed them too often. The best on the mean alone "
              f"({setting}) has "
              f"Phi = {_value(found, 'porosity_pct', '%')}, "
              f"R_q = {_value(found, 'roughness_um', 'um')}, "
              f"Q_s = {_value(found, 'throughput_mm2_s', 'mm^2/s')}. Simulate near it, relax the "
              "limits, or lower --confidence.")
        return 1
    print(_report(found, meta, limits, fixed))
    return 0


#: Grid points over the range of an input other than the speeds, at most (memory).
MAX_AXIS_POINTS = 101


def _parse_fixed(items):
    """``["roller.gap_um=300", ...]`` as ``{"roller.gap_um": 300.0}``."""
    fixed = {}
    for item in items:
        name, sep, value = item.partition("=")
        if name.strip() in fixed:
            raise ValueError(f"--fix {item!r}: {name.strip()} is fixed twice (at {fixed[name.strip()]:g} too): "
                             "give each input once")
        try:
            fixed[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not np.isfinite(fixed[name.strip()]):
            raise ValueError(f"--fix {item!r}: give AXIS=VALUE with a finite number, e.g. roller.gap_um=300")
    return fixed


if __name__ == "__main__":
    sys.exit(main())
