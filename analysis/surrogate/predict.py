"""Ask a fitted surrogate: predictions (with a standard deviation where the
model gives one) on points or a (U, omega) grid, and the paper's hybrid
indices (Figure 10): defect index Rq/max * Phi/max against throughput index
Qs/max * Ms/max.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from analysis.columns import METRICS
from analysis.surrogate.intervals import PRODUCTS, interval_frame, metrics_of


def metric_maxima(frame):
    """Maxima of the four metrics over ``frame`` (units of the columns)."""
    return {m: float(frame[m].max()) for m in METRICS}


def hybrid_indices(frame, maxima=None):
    """The paper's hybrid properties of Figure 10.

    Parameters
    ----------
    frame : pandas.DataFrame
        Has the four metric columns.
    maxima : dict, optional
        Metric maxima to normalise by; default: the maxima over ``frame``.

    Returns
    -------
    throughput_index, defect_index : numpy.ndarray (dimensionless)
        ``Q_s/max(Q_s) * M_s/max(M_s)`` and ``R_q/max(R_q) * Phi+/max(Phi)``, with
        ``Phi+ = max(Phi, 0)``: eq. 7's porosity goes negative where a deposit is deeper
        than 4 R_q (and a model of it may), a layer's void fraction cannot; so the
        defect index is never negative.
    """
    maxima = metric_maxima(frame) if maxima is None else maxima
    bad = [m for m in METRICS if not maxima[m] > 0]
    if bad:
        raise ValueError(f"cannot normalise by a non-positive maximum: {', '.join(bad)}")
    norm = {m: frame[m].to_numpy(float) / maxima[m] for m in METRICS}
    return (norm["throughput_mm2_s"] * norm["mass_g"],
            norm["roughness_um"] * np.clip(norm["porosity_pct"], 0.0, None))


def provides_std(model):
    """True if ``model.predict(X, return_std=True)`` gives a predictive standard deviation.

    The candidates of :mod:`analysis.surrogate.selection` do (GP posterior, spread of
    an MLP ensemble or of a tree ensemble); the plain network of
    :func:`make_surrogate` does not.
    """
    return bool(getattr(model, "provides_std", False))


def predict_with_std(model, U, omega, extra=None):
    """Predicted metrics and their predictive standard deviation at the speeds.

    Parameters
    ----------
    model : estimator
        A fitted surrogate with :func:`provides_std`.
    U, omega : array_like, 1-D, same length
        Spreader translation speed (mm/s) and roller angular speed (rad/s).
    extra : dict, optional
        The values of the model's further inputs (swept config keys, their config units),
        ``{axis: array or scalar}`` in the model's input order.

    Returns
    -------
    mean, std : numpy.ndarray, shape (n, k)
        Columns in the model's metrics' order (:func:`analysis.surrogate.intervals.metrics_of`:
        the four of :data:`METRICS`, then any layer-structure metrics), in their units.  ``std`` is
        the uncertainty of the predicted *mean* metric (not the seed-to-seed
        scatter of a single run, see :mod:`analysis.metrics.noise_floor`).

    Raises
    ------
    ValueError
        If the model gives no predictive standard deviation.
    """
    if not provides_std(model):
        raise ValueError(f"{type(model).__name__} gives no predictive standard deviation; "
                         "refit with a model of analysis.surrogate.selection (gp, mlp ensemble, trees)")
    mean, std = model.predict(_design(U, omega, extra), return_std=True)
    return np.asarray(mean, float), np.asarray(std, float)


def _design(U, omega, extra=None):
    """The (n, 2 + len(extra)) input array: U, omega, then the extra inputs (scalars broadcast)."""
    U, omega = np.asarray(U, float), np.asarray(omega, float)
    return np.column_stack([U, omega, *(np.broadcast_to(np.asarray(v, float), U.shape)
                                        for v in (extra or {}).values())])


def predict_frame(model, U, omega, confidence=None, extra=None):
    """Predict the metrics at the speeds ``U`` [mm/s] and ``omega`` [rad/s] (1-D, same length).

    ``extra`` gives the model's further inputs (``{axis: array or scalar}``, the model's
    input order, config units), when it has any. Returns a frame of the inputs and the
    model's metrics (:func:`analysis.surrogate.intervals.metrics_of`: the four, then the
    layer-structure metrics of a model that has them); when the model gives a predictive
    standard deviation (:func:`provides_std`), also ``<metric>_std`` columns in the metric's
    unit; when it gives calibrated intervals
    (:func:`provides_intervals`), their columns (:func:`analysis.surrogate.intervals.interval_frame`)
    at ``confidence`` (default: the model's level).
    """
    X = _design(U, omega, extra)
    frame = pd.DataFrame(X, columns=["U_mm_s", "omega_rad_s", *(extra or {})])
    if provides_std(model):
        pred, std = predict_with_std(model, X[:, 0], X[:, 1], dict(zip(extra or {}, X[:, 2:].T)))
    else:
        pred, std = model.predict(X), None
    metrics = metrics_of(model)
    frame[list(metrics)] = pred
    if std is not None:
        frame[[f"{m}_std" for m in metrics]] = std
    if provides_intervals(model):
        frame = pd.concat([frame, interval_frame(model, X, confidence)], axis=1)
    return frame


def provides_intervals(model):
    """True if ``model`` gives calibrated intervals (:class:`analysis.surrogate.intervals.CalibratedSurrogate`)."""
    return callable(getattr(model, "predict_interval", None))


def hybrid_index_std(frame, maxima):
    """First-order standard deviation of the hybrid indices from the metrics' ``_std`` columns.

    Treats the errors of the metrics as independent:
    ``std(Q M) = sqrt((std_Q M)^2 + (Q std_M)^2)``, divided by the maxima
    (held fixed).  Returns (throughput_index_std, defect_index_std),
    dimensionless.
    """
    def product_std(a, b):
        va, vb = frame[a].to_numpy(float), frame[b].to_numpy(float)
        sa, sb = frame[f"{a}_std"].to_numpy(float), frame[f"{b}_std"].to_numpy(float)
        return np.hypot(sa * vb, va * sb) / (maxima[a] * maxima[b])
    return (product_std("throughput_mm2_s", "mass_g"), product_std("roughness_um", "porosity_pct"))


def predict_grid(model, U_range, omega_range, n, confidence=None, extra=None):
    """Evaluate the surrogate on a regular n x n grid of spreader speeds (at each value of the extra inputs).

    Parameters
    ----------
    model : estimator
        A fitted surrogate.
    U_range : (float, float)
        Translation speed limits, mm/s.
    omega_range : (float, float)
        Roller angular speed limits, rad/s.
    n : int
        Grid points per axis (>= 2).
    confidence : float, optional
        Coverage level of the intervals (default: the model's, config ``surrogate.confidence``).
    extra : dict, optional
        The model's further inputs, ``{axis: values}`` (config units, the model's input
        order): the n x n grid is evaluated at every combination of their values.

    Returns
    -------
    pandas.DataFrame
        n*n rows per combination of the extra values (those outer, in order, then U,
        then omega): ``U_mm_s``, ``omega_rad_s``, the extra inputs, the model's
        metrics in their units (the four, then the layer-structure metrics of a model that
        has them: :func:`predict_frame`), and the dimensionless ``throughput_index`` and
        ``defect_index`` (:func:`hybrid_indices`, maxima over this grid).  When
        the model gives a predictive standard deviation, also
        ``<metric>_std`` (metric units) and ``throughput_index_std``,
        ``defect_index_std`` (:func:`hybrid_index_std`).  When it gives calibrated
        intervals (:func:`provides_intervals`), also ``<q>_lo``, ``<q>_hi`` (single-run
        interval) and ``<q>_mean_lo``, ``<q>_mean_hi`` (interval of the mean) of the
        metrics, of the products and of the two indices (:func:`index_intervals`), at the
        model's confidence level.
    """
    if int(n) < 2:
        raise ValueError(f"grid needs at least 2 points per axis, got {n}")
    extra = extra or {}
    mesh = np.meshgrid(*(np.asarray(v, float) for v in extra.values()), np.linspace(*U_range, int(n)),
                       np.linspace(*omega_range, int(n)), indexing="ij")
    *values, U, omega = (a.ravel() for a in mesh)
    return with_indices(model, predict_frame(model, U, omega, confidence, dict(zip(extra, values))))


def with_indices(model, grid):
    """Add the hybrid indices to a prediction frame of ``model`` (:func:`predict_frame`), in
    place, normalised by the metrics' maxima over the frame: ``throughput_index``,
    ``defect_index``, and their ``_std`` or interval columns where the model gives them."""
    maxima = metric_maxima(grid)
    grid["throughput_index"], grid["defect_index"] = hybrid_indices(grid, maxima)
    if provides_std(model):
        grid["throughput_index_std"], grid["defect_index_std"] = hybrid_index_std(grid, maxima)
    if provides_intervals(model):
        index_intervals(grid, maxima)
    return grid


def index_intervals(frame, maxima):
    """Add the hybrid indices' intervals to a frame with the products' interval columns, in place.

    An index is its product (``throughput_product`` = Q_s M_s, ``defect_product`` =
    R_q Phi) over the product of the maxima, so its interval is the product's over the
    same constant: ``throughput_index_lo``, ``_hi``, ``_mean_lo``, ``_mean_hi``, and the
    same for ``defect_index`` (dimensionless), whose ends are clipped at 0 as its
    porosity is (:func:`hybrid_indices`; R_q > 0, so the clip maps the interval's ends).
    """
    for index, (product, (a, b)) in zip(("throughput_index", "defect_index"), PRODUCTS.items()):
        for end in ("lo", "hi", "mean_lo", "mean_hi"):
            value = frame[f"{product}_{end}"] / (maxima[a] * maxima[b])
            frame[f"{index}_{end}"] = value.clip(lower=0.0) if index == "defect_index" else value
    return frame
