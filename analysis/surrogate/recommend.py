"""The operator's question: which spreader speeds give the most throughput within limits?

Usage::

    python -m analysis.surrogate.recommend --max-porosity 45 [--max-roughness 60] \\
        [--max-void-fraction 35] [--min-coverage 95] [--confidence 0.9] \\
        [--model results/default/surrogate/model.joblib] [--grid-points 201] [--fix roller.gap_um=300] \\
        [--axis-points 11]

Prints the (U, omega), and the value of every other swept axis (e.g. the gap,
``roller.gap_um``), inside the swept range (stored with the model) whose
predicted spread throughput Q_s is highest among the settings that meet the
limits given (at least one, :data:`LIMITS`): eq. 7's porosity Phi (%), the
roughness R_q (um), the void fraction ``100 (1 - packing fraction)`` (%) and the
coverage of the substrate (%, a least value), with every predicted metric and
the calibrated interval a single new run of each would fall in
(:mod:`analysis.surrogate.intervals`).  A setting qualifies when the upper end
of that interval meets each upper limit (the lower end each lower limit): with
``--confidence 0.9`` (default: the model's level, config ``surrogate.confidence``)
at most about 5 % of runs at that setting exceed the limit (the interval is
central: 5 % above, 5 % below).  The void fraction and the coverage need a model
fitted with them (the workflow's surrogate rule fits them beside the four metrics).
A model without calibrated intervals (an old model file) is judged on its
mean, and says so.  ``--fix roller.gap_um=300`` holds an axis at a value (the gap
the job needs; any input, within its swept range).  Exit status: 0 found, 1 no speeds meet the limits (or
none at the confidence: the message says so), 2 bad input (the message names it).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from analysis.columns import ALL_METRICS, SHORT_NAMES, input_units
from analysis.config.reading import load_schema
from analysis.io import USER_ERRORS, error_line
from analysis.surrogate.intervals import check_confidence, metrics_of
from analysis.surrogate.persistence import load_surrogate
from analysis.surrogate.predict import predict_frame, provides_intervals

DEFAULT_MODEL = "results/default/surrogate/model.joblib"


class Limit(NamedTuple):
    """An operator's limit on one metric of a run."""

    column: str     #: the metric it bounds (a dataset column, :data:`analysis.columns.ALL_METRICS`)
    kind: str       #: "max": the run interval's upper end at most the limit; "min": its lower end at least
    option: str     #: spreadmap-recommend's option
    name: str       #: how text names the metric
    most: float     #: the largest value the limit may take (a share: 100 %)
    help: str       #: what the option means (spreadmap-recommend --help)


#: The operator's limits by their key in config ``maps.operating_window`` (units in the names; the
#: same keys as :func:`recommend`'s arguments). Porosity is eq. 7's Phi; the void fraction is
#: ``100 (1 - packing fraction)``, which does not take 4 R_q as the layer's thickness.
LIMITS = {
    "max_porosity_pct": Limit("porosity_pct", "max", "--max-porosity", "porosity", math.inf,
                              "highest acceptable spread-layer porosity Phi of a run, % (the paper's eq. 7, which "
                              "takes 4 R_q as the layer's thickness: low, even negative, where a deposit is deeper)"),
    "max_roughness_um": Limit("roughness_um", "max", "--max-roughness", "roughness R_q", math.inf,
                              "highest acceptable spread-layer roughness R_q of a run, um"),
    "max_void_fraction_pct": Limit("void_fraction_pct", "max", "--max-void-fraction", "void fraction", 100.0,
                                   "highest acceptable void fraction of a run's layer, 100 (1 - packing fraction), "
                                   "% (0-100): the void share of the volume under the measured layer top"),
    "min_coverage_pct": Limit("coverage_pct", "min", "--min-coverage", "coverage", 100.0,
                              "least acceptable coverage of the substrate by a run's layer, % (0-100): the share "
                              "of profilometer probes that hit powder"),
}


def check_limits(limits):
    """The limits that are set (not None), as floats, checked.

    Parameters
    ----------
    limits : dict
        ``{key of LIMITS: value or None}`` in the key's unit.

    Returns
    -------
    dict
        ``{key: float}`` of the set limits, in :data:`LIMITS` order.

    Raises
    ------
    ValueError
        An unknown key, or a value that is negative, NaN or above the limit's ``most``
        (100 % for a share), naming its option and the value.
    """
    unknown = sorted(set(limits) - set(LIMITS))
    if unknown:
        raise ValueError(f"unknown limit(s) {', '.join(unknown)}; known: {', '.join(LIMITS)}")
    out = {}
    for key, limit in LIMITS.items():
        value = limits.get(key)
        if value is None:
            continue
        unit = ALL_METRICS[limit.column][1]
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{limit.option} must be a number ({unit}), got {value!r}") from None
        if not value >= 0:                          # also rejects NaN
            raise ValueError(f"{limit.option} must be a non-negative number, got {value:g}")
        if value > limit.most:
            raise ValueError(f"{limit.option} must be a share from 0 to {limit.most:g} {unit}, got {value:g}")
        out[key] = value
    return out


def limits_text(limits):
    """The set limits as text: 'porosity <= 50 % and coverage >= 95 %' ('no limits' for none)."""
    parts = [f"{LIMITS[k].name} {'<=' if LIMITS[k].kind == 'max' else '>='} {v:g} "
             f"{ALL_METRICS[LIMITS[k].column][1]}" for k, v in check_limits(limits).items()]
    return " and ".join(parts) or "no limits"


def check_model_has(model, limits):
    """Raise a ValueError naming the options of ``limits`` (keys of :data:`LIMITS`) whose metric
    ``model`` does not predict (a model fitted without the layer-structure metrics)."""
    have = metrics_of(model)
    lacking = [LIMITS[k] for k in limits if LIMITS[k].column not in have]
    if lacking:
        raise ValueError(f"{', '.join(lim.option for lim in lacking)}: this model does not predict the "
                         f"{' or '.join(lim.name for lim in lacking)} (it predicts {', '.join(have)}); refit it "
                         "with the workflow's surrogate rule on a dataset with packing_fraction and coverage")


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


def recommend(model, meta, max_porosity_pct=None, max_roughness_um=None, n=201, confidence=None, fixed=None,
              axis_points=11, max_void_fraction_pct=None, min_coverage_pct=None):
    """Setting of highest predicted throughput whose single-run interval meets the limits (:data:`LIMITS`).

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
    max_porosity_pct : float, optional
        Highest acceptable porosity Phi of a run (eq. 7), %.
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
    max_void_fraction_pct : float, optional
        Highest acceptable void fraction of a run, ``100 (1 - packing fraction)``, %, 0-100.
    min_coverage_pct : float, optional
        Least acceptable coverage of the substrate by a run's layer, %, 0-100 (the lower end of
        the single-run interval must meet it).

    Returns
    -------
    dict or None
        None if no grid point meets the limits even on the mean prediction.
        Otherwise every input (``U_mm_s``, ``omega_rad_s``, and the other axes), the predicted metrics
        (``mass_g``, ``throughput_mm2_s``, ``roughness_um``, ``porosity_pct``, then
        ``void_fraction_pct`` and ``coverage_pct`` when the model has them),
        their single-run interval ``<metric>_lo``, ``<metric>_hi`` (NaN without
        intervals), ``limits`` (the set limits, :func:`check_limits`), ``metrics`` (the
        model's), ``confidence`` (the level applied, or None), ``n_feasible``
        (grid points whose interval meets the limits), ``n_feasible_mean`` (on the
        mean alone), ``n_grid``, ``inputs`` (the input names) and ``meets_confidence``: False when no
        setting's interval meets the limits; the point returned is then the best on the mean alone.

    Raises
    ------
    ValueError
        A negative or NaN limit, a share above 100 %, a limit on a metric the model does not
        predict, a confidence outside (0, 1) or too high for the model's calibration runs,
        n < 2, metadata without the swept range, or a fixed value that is not an input or
        lies outside its range.
    """
    limits = check_limits({"max_porosity_pct": max_porosity_pct, "max_roughness_um": max_roughness_um,
                           "max_void_fraction_pct": max_void_fraction_pct, "min_coverage_pct": min_coverage_pct})
    check_model_has(model, limits)
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
    names, metrics = list(search_grid(meta, 2, fixed, 2)), metrics_of(model)
    for m in metrics:
        for end in ("lo", "hi"):
            if f"{m}_{end}" not in grid:
                grid[f"{m}_{end}"] = np.nan
    on_mean, on_interval = meets_limits(grid, limits, with_intervals)
    if not on_mean.any():
        return None
    pool = on_interval if on_interval.any() else on_mean
    best = grid.loc[grid["throughput_mm2_s"].where(pool).idxmax()]
    return {**{c: float(best[c]) for c in (*names, *metrics)},
            **{f"{m}_{end}": float(best[f"{m}_{end}"]) for m in metrics for end in ("lo", "hi")},
            "limits": limits, "metrics": list(metrics),
            "confidence": confidence, "meets_confidence": bool(on_interval.any()),
            "n_feasible": int(on_interval.sum()), "n_feasible_mean": int(on_mean.sum()),
            "n_grid": len(grid), "inputs": names}


def meets_limits(grid, limits, with_intervals=True):
    """Which rows of a prediction frame meet the limits.

    Parameters
    ----------
    grid : pandas.DataFrame
        Predictions (:func:`analysis.surrogate.predict.predict_frame`): each limited metric's
        column and, ``with_intervals``, its ``<metric>_lo`` and ``<metric>_hi``.
    limits : dict
        ``{key of LIMITS: value or None}`` (None: no limit), e.g. config ``maps.operating_window``.
    with_intervals : bool
        Judge the single-run interval's end; False: the mean.

    Returns
    -------
    on_mean, on_interval : numpy.ndarray of bool
        The predicted mean within every limit; the single-run interval's end within every
        limit (the upper end, ``<metric>_hi``, against an upper limit; the lower end against a
        lower one; the mean, when ``with_intervals`` is False).
    """
    on_mean = np.ones(len(grid), bool)
    on_interval = np.ones(len(grid), bool)
    for key, value in check_limits(limits).items():
        limit = LIMITS[key]
        mean = grid[limit.column].to_numpy(float)
        end = grid[f"{limit.column}_{'hi' if limit.kind == 'max' else 'lo'}"].to_numpy(float) if with_intervals \
            else mean
        on_mean &= _within(mean, limit.kind, value)
        on_interval &= _within(end, limit.kind, value)
    return on_mean, on_interval


def _within(values, kind, limit):
    """``values <= limit`` for an upper limit ("max"), ``values >= limit`` for a lower one ("min")."""
    return values <= limit if kind == "max" else values >= limit


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


#: The predicted metrics in the report's order, with a note on what each is.
_SHOWN = {"throughput_mm2_s": "", "mass_g": "", "roughness_um": "", "porosity_pct": " (eq. 7)",
          "void_fraction_pct": " (void fraction: 100 (1 - packing fraction))",
          "coverage_pct": " (coverage of the substrate)"}


def _predicted_lines(found):
    """'predicted: Q_s = ...' and one line per further metric the found setting has, symbols aligned."""
    shown = [m for m in _SHOWN if m in found]
    width = max(len(ALL_METRICS[m][0]) for m in shown)
    lines = [f"{ALL_METRICS[m][0]:>{width}} = {_value(found, m, ALL_METRICS[m][1])}{_SHOWN[m]}" for m in shown]
    return [f"  {'predicted:' if i == 0 else '':<10} {line}{',' if i < len(lines) - 1 else ''}"
            for i, line in enumerate(lines)]


def _rule(found):
    """How a setting was judged, as text."""
    if found["confidence"] is None:
        return "the limits met by the predicted mean (this model has no calibrated intervals: refit it)"
    level = f"{100 * found['confidence']:g} %"
    lower = any(LIMITS[k].kind == "min" for k in found.get("limits", {}))
    return (f"the upper end of the {level} single-run interval within each limit"
            + (" (its lower end for a least value)" if lower else "")
            + f"; a run: the calibrated interval that {level} of new DEM runs at that setting fall in")


def _report(found, meta, limits, fixed=None):
    return "\n".join([
        f"Highest predicted throughput with {limits}",
        f"(surrogate grid of {found['n_grid']} points over {_range_text(meta, fixed)}; "
        f"{found['n_feasible']} meet the limits; {_rule(found)}):",
        *_setting_lines(found, meta),
        *_predicted_lines(found),
    ])


def _nearest_text(grid, limits):
    """The best each limited metric gets over the grid: 'the lowest predicted porosity there is 28 %'."""
    parts = []
    for key in limits:
        limit, unit = LIMITS[key], ALL_METRICS[LIMITS[key].column][1]
        values = grid[limit.column]
        best, word = (values.min(), "lowest") if limit.kind == "max" else (values.max(), "highest")
        parts.append(f"the {word} predicted {limit.name} there is {best:.4g} {unit}")
    return " and ".join(parts)


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """Bad arguments: one line on stderr, exit 2."""
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv=None):
    """Command-line entry; returns the exit status."""
    parser = _Parser(prog="python -m analysis.surrogate.recommend", description=__doc__.split("\n\n")[0])
    for key, limit in LIMITS.items():         # at least one (checked below)
        parser.add_argument(limit.option, dest=key, type=float, metavar=key.rsplit("_", 1)[1].upper(),
                            help=limit.help.replace("%", "%%"))
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
    limits = {key: getattr(args, key) for key in LIMITS}
    if all(v is None for v in limits.values()):
        parser.error("give at least one limit: " + ", ".join(lim.option for lim in LIMITS.values()))
    try:
        fixed = _parse_fixed(args.fix)
        limits = check_limits(limits)
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
        found = recommend(model, meta, n=args.grid_points, confidence=args.confidence, fixed=fixed,
                          axis_points=args.axis_points, **limits)
    except USER_ERRORS as err:
        parser.error(error_line(err))
    text = limits_text(limits)
    if found is None:
        grid = _predict_search_grid(model, meta, args.grid_points, fixed, args.axis_points)
        print(f"No speeds in {_range_text(meta, fixed)} are predicted to meet {text}; "
              f"{_nearest_text(grid, limits)}.")
        return 1
    if not found["meets_confidence"]:
        level = f"{100 * found['confidence']:g} %"
        setting = ", ".join(line.strip() for line in _setting_lines(found, meta))
        shown = [*dict.fromkeys([*(LIMITS[k].column for k in limits), "porosity_pct", "roughness_um"])]
        values = ", ".join(f"{ALL_METRICS[m][0]} = {_value(found, m, ALL_METRICS[m][1])}"
                           for m in (*shown, "throughput_mm2_s"))
        print(f"{found['n_feasible_mean']} settings in {_range_text(meta, fixed)} are predicted to meet "
              f"{text} on the mean, but at none does the {level} single-run interval stay within "
              "the limits: runs there would exceed them too often. The best on the mean alone "
              f"({setting}) has {values}. Simulate near it, relax the limits, or lower --confidence.")
        return 1
    print(_report(found, meta, text, fixed))
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
