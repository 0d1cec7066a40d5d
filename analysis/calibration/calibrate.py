"""Calibrate the virtual powder: contact coefficients that reproduce a measured angle of repose
and bulk density (docs/calibration.md).

1. :func:`design`: a space-filling Latin hypercube over the coefficients being calibrated
   (``calibration.coefficients``: a ``material`` key and its range each).
2. The characterisation tests (:mod:`analysis.calibration.characterise`) at every design point.
3. :func:`fit_responses`: the project's Gaussian-process surrogate
   (:class:`analysis.surrogate.candidates.GPSurrogate`) of each measured property over the
   coefficients, its std of the mean calibrated on leave-one-point-out residuals
   (:func:`analysis.surrogate.intervals.calibrate`, :func:`~analysis.surrogate.intervals.conformal_quantile`).
4. :func:`solve`: on a grid over the box, the coefficients whose predicted properties agree with
   every measurement within ``z sqrt(sd_measured^2 + sd_model^2)`` (z: the two-sided normal
   quantile of ``surrogate.confidence``); the chosen ones minimise the chi-square, their
   uncertainty is the range of that set. A measurement outside what the box can reach is
   refused (:class:`CalibrationError`) with the reachable range.
"""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from scipy.stats import qmc

from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.intervals import calibrate as calibrate_scale
from analysis.surrogate.intervals import conformal_quantile

#: The measured properties: result column, config key of the value and of its sd, unit, test.
PROPERTIES = {
    "angle_of_repose_deg": ("angle_of_repose_deg", "angle_of_repose_sd_deg", "deg", "repose"),
    "bulk_density_kg_m3": ("bulk_density_kg_m3", "bulk_density_sd_kg_m3", "kg/m^3", "bulk_density"),
}

#: Decimals the design's coefficients are rounded to (clean run parameters).
DESIGN_DECIMALS = 4


class CalibrationError(ValueError):
    """No coefficients in the calibrated box reproduce the measurements; the message says what can be reached."""


def check_calibration(config: dict) -> None:
    """Cross-key checks of ``calibration`` the schema cannot make; raises :class:`CalibrationError`
    naming the key."""
    cal = config["calibration"]
    if cal["level"] not in config["fidelity"]:
        raise CalibrationError(f"config key 'calibration.level' = {cal['level']!r}: no such fidelity level; "
                               f"choose one of {sorted(config['fidelity'])}")
    if not coefficient_bounds(cal):
        raise CalibrationError("config key 'calibration.coefficients': no coefficient to calibrate (all null)")
    for name, (lo, hi) in coefficient_bounds(cal).items():
        if not hi > lo:
            raise CalibrationError(f"config key 'calibration.coefficients.{name}' = {[lo, hi]}: "
                                   "the range must have hi > lo")
    if not targets(cal):
        raise CalibrationError("config key 'calibration.measured': no measurement given (both values are null)")
    bases = heap_bases_mm(cal)
    if len(set(bases)) != len(bases):
        raise CalibrationError(f"config key 'calibration.repose_base_diameter_mm' = {bases}: a base is "
                               "given twice; give one base, or two or more different ones (mm)")


def heap_bases_mm(cal: dict) -> list[float]:
    """The angle-of-repose heap's base diameters [mm]: ``repose_base_diameter_mm``, one value or a
    list (two or more: the angle is the large-heap limit of their size trend,
    :func:`analysis.calibration.characterise.large_heap_angle`)."""
    bases = cal["repose_base_diameter_mm"]
    return [float(b) for b in (bases if isinstance(bases, list) else [bases])]


def coefficient_bounds(cal: dict) -> dict[str, tuple[float, float]]:
    """``{material key: (lo, hi)}`` of the coefficients being calibrated, in config order; a null
    range leaves its coefficient at the material's value (a --configfile cannot delete a key)."""
    return {name: (float(r[0]), float(r[1])) for name, r in cal["coefficients"].items() if r is not None}


def targets(cal: dict) -> dict[str, tuple[float, float]]:
    """``{property: (measured value, its sd)}`` of the measurements given (a null value is left out)."""
    measured = cal["measured"]
    return {prop: (float(measured[key]), float(measured[sd]))
            for prop, (key, sd, _, _) in PROPERTIES.items() if measured.get(key) is not None}


def tests_needed(cal: dict) -> list[str]:
    """The characterisation tests the measurements given need (``repose``, ``bulk_density``)."""
    return [PROPERTIES[prop][3] for prop in targets(cal)]


def design(cal: dict) -> pd.DataFrame:
    """The design: ``calibration.design_points`` points of a seeded Latin hypercube over the box,
    one column per coefficient, indexed ``p00``, ``p01``, ..."""
    bounds = coefficient_bounds(cal)
    n = int(cal["design_points"])
    lo, hi = (np.array([b[i] for b in bounds.values()]) for i in (0, 1))
    raw = qmc.LatinHypercube(len(bounds), seed=int(cal["design_seed"])).random(n)
    points = np.round(qmc.scale(raw, lo, hi), DESIGN_DECIMALS)
    width = max(2, len(str(n - 1)))
    return pd.DataFrame(points, columns=list(bounds), index=[f"p{i:0{width}d}" for i in range(n)])


def design_run(table: pd.DataFrame, run: str) -> dict:
    """Coefficients and seed index of the design run ``p<i>_r<rep>`` of the design ``table``:
    every run its own seeds (:func:`analysis.calibration.characterise.test_seeds`)."""
    point, rep = run.split("_r")
    return {"coefficients": table.loc[point].to_dict(),
            "seed_index": int(rep) * len(table) + table.index.get_loc(point)}


def calibration_run(table: pd.DataFrame, replicates: int, calset: str) -> dict:
    """Coefficients and seed index of a design run (``runs/p<i>_r<rep>``, :func:`design_run` of the
    design ``table``) or of a check (``check/r<rep>``: the calibrated config file's coefficients,
    ``None`` here, with seeds no design run of ``replicates`` per point uses)."""
    group, name = calset.split("/")
    if group == "runs":
        return design_run(table, name)
    return {"coefficients": None, "seed_index": replicates * len(table) + int(name[1:])}


def with_coefficients(config: dict, coefficients: dict) -> dict:
    """A copy of ``config`` whose ``material`` holds ``coefficients`` (material keys)."""
    out = copy.deepcopy(config)
    out["material"].update({k: float(v) for k, v in coefficients.items()})
    return out


@dataclass
class Response:
    """The surrogate of one measured property over the coefficients."""

    model: GPSurrogate
    scale: float        # calibrated inflation c of the model's std of its mean
    quantile: float     # conformal multiplier q of single-run intervals (inf: too few points)
    noise_sd: float     # run-to-run (seed) sd the GP's white noise estimates [property units]
    loo_rmse: float     # leave-one-point-out RMS error [property units]

    def predict(self, X):
        """Mean and calibrated std of the mean at X (n, k)."""
        mean, std = self.model.predict(np.atleast_2d(X), return_std=True)
        return mean, self.scale * std


def fit_responses(results: pd.DataFrame, names: list[str], properties: list[str], confidence: float,
                  n_restarts: int = 2, random_state: int = 0) -> dict[str, Response]:
    """One GP per property over ``names`` from ``results`` (a row per test run, replicates included).

    Its std of the mean is calibrated on leave-one-point-out predictions: every design point's
    runs left out in turn, the GP refitted on the rest (:func:`analysis.surrogate.intervals.calibrate`
    with the GP's own relative white noise as run-to-run noise).
    """
    X = results[names].to_numpy(float)
    points = pd.factorize(pd.MultiIndex.from_frame(results[names]))[0]
    out = {}
    for prop in properties:
        y = results[prop].to_numpy(float)
        model = GPSurrogate(n_restarts=n_restarts, random_state=random_state).fit(X, y)
        mean_y = float(np.mean(np.abs(y))) or 1.0
        rho = float(model.noise_std_[0]) / mean_y
        loo_mean, loo_std = np.empty_like(y), np.empty_like(y)
        for p in np.unique(points):
            held = points == p
            fold = GPSurrogate(n_restarts=0, random_state=random_state).fit(X[~held], y[~held])
            loo_mean[held], loo_std[held] = fold.predict(X[held], return_std=True)
        c, scores = calibrate_scale(y[:, None], loo_mean[:, None], loo_std[:, None], np.array([rho]))
        q = float(conformal_quantile(scores, confidence, n_runs=len(np.unique(points)))[0])
        out[prop] = Response(model, max(float(c[0]), 1.0), q, float(model.noise_std_[0]),
                             float(np.sqrt(np.mean((y - loo_mean) ** 2))))
    return out


def grid(bounds: dict, n: int) -> np.ndarray:
    """Every point of an ``n``-per-axis grid over the box, shape (n^k, k)."""
    axes = [np.linspace(lo, hi, n) for lo, hi in bounds.values()]
    return np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def _fmt(value: float, unit: str) -> str:
    return f"{value:.4g} {unit}".strip()


def solve(responses: dict[str, Response], measured: dict[str, tuple[float, float]], bounds: dict,
          confidence: float, grid_points: int = 101) -> dict:
    """The coefficients that reproduce ``measured`` (``{property: (value, sd)}``).

    A grid point is consistent when every property's prediction lies within
    ``z sqrt(sd^2 + sd_model^2)`` of its measurement (z: the normal quantile of a central
    ``confidence`` interval). Returns the chosen point (least chi-square), the consistent
    set's range per coefficient and the predictions there. Raises :class:`CalibrationError`
    when a measurement lies outside the range the box reaches (naming that range) or no
    point agrees with all measurements at once.
    """
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    names = list(bounds)
    X = grid(bounds, grid_points)
    chi2 = np.zeros(len(X))
    ok = np.ones(len(X), bool)
    reach = {}
    for prop, (value, sd) in measured.items():
        mean, std = responses[prop].predict(X)
        sigma = np.hypot(sd, std)
        chi2 += ((mean - value) / sigma) ** 2
        ok &= np.abs(mean - value) <= z * sigma
        unit = PROPERTIES[prop][2]
        reach[prop] = (float(mean.min()), float(mean.max()))
        if value + z * sd < mean.min() - z * std.max() or value - z * sd > mean.max() + z * std.max():
            box = ", ".join(f"{n} {lo:g}..{hi:g}" for n, (lo, hi) in bounds.items())
            raise CalibrationError(
                f"the measured {prop} {_fmt(value, unit)} +- {_fmt(sd, unit)} cannot be reached: over the "
                f"calibrated box ({box}) the virtual powder gives {_fmt(mean.min(), unit)} to "
                f"{_fmt(mean.max(), unit)} (model sd up to {_fmt(std.max(), unit)}); widen "
                "calibration.coefficients or check the measurement")
    if not ok.any():
        best = X[np.argmin(chi2)]
        at = ", ".join(f"{n} = {v:.3g}" for n, v in zip(names, best))
        raise CalibrationError(
            "no coefficients in the box reproduce all measurements at once (each alone is reachable: "
            + "; ".join(f"{p} {_fmt(lo, PROPERTIES[p][2])} to {_fmt(hi, PROPERTIES[p][2])}"
                        for p, (lo, hi) in reach.items())
            + f"); the closest compromise is {at}")
    best = int(np.argmin(np.where(ok, chi2, np.inf)))
    chosen = dict(zip(names, map(float, X[best])))
    predicted = {}
    for prop in measured:
        mean, std = responses[prop].predict(X[best][None, :])
        predicted[prop] = {"mean": float(mean[0]), "sd_model": float(std[0])}
    spacing = {n: (hi - lo) / (grid_points - 1) for n, (lo, hi) in bounds.items()}
    return {"chosen": chosen, "range": {n: (float(X[ok, j].min()), float(X[ok, j].max()))
                                        for j, n in enumerate(names)},
            "grid_spacing": spacing, "chi2": float(chi2[best]), "z": z, "confidence": confidence,
            "consistent_fraction": float(ok.mean()), "predicted": predicted, "reachable": reach,
            "measured": {p: {"value": v, "sd": s} for p, (v, s) in measured.items()},
            "at_box_edge": [n for n, v in chosen.items() if np.isclose(v, bounds[n][0])
                            or np.isclose(v, bounds[n][1])]}


def calibrated_config(solution: dict, source: str = "") -> str:
    """The calibrated coefficients as a config file for ``--configfile`` (YAML text), their
    uncertainty and the measurements in comments."""
    lines = ["# spreadmap: a calibrated virtual powder (analysis.calibration.calibrate; docs/calibration.md).",
             "# Use with: snakemake --configfile config.yaml <this file> ...", "#"]
    for prop, m in solution["measured"].items():
        unit = PROPERTIES[prop][2]
        p = solution["predicted"][prop]
        lines.append(f"# measured {prop}: {_fmt(m['value'], unit)} +- {_fmt(m['sd'], unit)}; "
                     f"the calibrated powder: {_fmt(p['mean'], unit)} +- {_fmt(p['sd_model'], unit)} (model)")
    if source:
        lines.append(f"# source: {source}")
    lines.append("material:")
    for name, value in solution["chosen"].items():
        lo, hi = solution["range"][name]
        lines.append(f"  {name}: {value:.4g}   # consistent range {lo:.4g}..{hi:.4g} "
                     f"({100 * solution['confidence']:g} % bands)")
    return "\n".join(lines) + "\n"


def _test_results(paths: list) -> pd.DataFrame:
    """One row per run folder (``<run>/<test>/<test>.json``), a column per measured property (and,
    for a large-heap angle, ``angle_d<D>_deg`` per heap base D [mm])."""
    rows = {}
    for path in paths:
        path = Path(path)
        result = json.loads(path.read_text())
        row = rows.setdefault(path.parent.parent.name, {})
        row.update({prop: result[prop] for prop in PROPERTIES if prop in result})
        if result.get("extrapolated"):  # the heaps behind a large-heap angle, by base
            row.update({f"angle_d{d:g}_deg": a for d, a in zip(result["base_diameters_mm"], result["angles_deg"])})
    return pd.DataFrame.from_dict(rows, orient="index")


def collect_results(cal: dict, paths: list) -> pd.DataFrame:
    """The design runs' results (``runs/p<i>_r<rep>/<test>/<test>.json``) with their coefficients:
    columns ``point``, ``replicate``, the coefficients, the measured properties."""
    table = _test_results(paths)
    point, rep = zip(*(name.split("_r") for name in table.index))
    coefficients = design(cal).loc[list(point)].reset_index(drop=True)
    return pd.concat([pd.DataFrame({"point": point, "replicate": [int(r) for r in rep]}), coefficients,
                      table.reset_index(drop=True)], axis=1)


def read_checks(paths: list) -> pd.DataFrame:
    """The check runs' results (``check/r<rep>/<test>/<test>.json``), a row per replicate."""
    return _test_results(paths) if paths else pd.DataFrame()


def response_summary(responses: dict[str, Response]) -> dict:
    """What the report shows of each surrogate (JSON-ready)."""
    return {prop: {"loo_rmse": r.loo_rmse, "noise_sd": r.noise_sd, "scale": r.scale, "quantile": r.quantile}
            for prop, r in responses.items()}
