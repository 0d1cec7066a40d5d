"""Calibrated prediction intervals: normalised cross-conformal prediction grouped by (U, omega) point.

Every candidate surrogate (:mod:`analysis.surrogate.candidates`) gives a mean and its
own predictive standard deviation ``s(x)`` of that mean: the GP's posterior, the
spread of the networks or of the trees.  That std is not a prediction interval:
it leaves out the run-to-run noise and, for the ensembles, is not calibrated at
all (the networks of the mlp ensemble agree far more than they are right).  Here
each candidate's intervals are calibrated on its own cross-validated residuals
(the k-fold cross-validation of model choice, folds grouped by (U, omega) point,
so a held-out run's point was never seen by the model that predicts it):

1. **Scale.**  The predictive scale of a single run is
   ``sigma(x) = sqrt((c s(x))^2 + (rho mu(x))^2)``: the model's std, inflated by a
   factor ``c``, and the run-to-run noise, ``rho`` times the predicted metric
   (the noise floor is relative: :mod:`analysis.metrics.noise_floor`).  A share in %
   whose runs pile up near 100 % (the coverage of the substrate) takes the noise of a
   binomial share instead, ``rho sqrt(C (100 - C))`` with C clipped to 5..95 %
   (:func:`share_scale`; ``shares=`` of the functions here).  ``rho``
   is the pooled relative seed-to-seed sd when the dataset has replicates, else
   the Gaussian process's white-noise term over the mean metric
   (:func:`relative_noise`); ``c`` makes the mean squared cross-validated
   residual equal the mean ``sigma^2`` (:func:`calibrate`).
2. **Conformal step.**  The scores ``|y - mu_cv(x)| / sigma_cv(x)`` of the
   held-out runs (pooled over the repeats of the k-fold) give the multiplier
   ``q``: their ``ceil(confidence (n + 1)) / (n + 1)`` quantile over the n runs
   (:func:`conformal_quantile`).  The
   single-run interval is ``mu(x) +- q sigma(x)`` around the model fitted on the
   training points: split conformal with the cross-validated residuals as the
   calibration set (MAPIE's ``method="base"`` with grouped folds; Barber et al.
   2021, "Predictive inference with the jackknife+", call it the CV method).
   Its coverage is the confidence level on average over new runs when the runs
   are exchangeable and the model fitted on all training points is no worse
   than the fold models; measured, not assumed: ``benchmarks/bench_intervals.py``.
3. **Mean.**  The interval of the expected metric (no run noise) is
   ``mu(x) +- q c s(x)``: the calibrated std of the mean with the same
   multiplier.  The mean is never observed, so this one cannot be conformal;
   its coverage is checked on synthetic data only.

The two products behind the paper's hybrid indices, ``Q_s M_s`` and ``R_q Phi``,
are calibrated the same way as two more quantities (:data:`QUANTITIES`): an index
is a product divided by constant maxima, so its interval is the product's divided
by the same constant, with no first-order propagation.

All arrays have one column per quantity in :data:`QUANTITIES` order, in the metrics'
units (the products in the products of the units).  A surrogate of other metrics (the
layer-structure metrics, :data:`analysis.columns.STRUCTURE_METRICS`) is calibrated the same way
with its own metrics and no products (``metrics=``, ``products=`` of the functions here), and
:class:`CalibratedStack` answers for several calibrated surrogates of disjoint metrics as one.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd

from analysis.columns import METRICS, input_columns
from analysis.metrics.dataset import point_groups
from analysis.surrogate.candidates import GPSurrogate

#: The four metrics and the two products of the hybrid indices (throughput: Q_s M_s, defect: R_q Phi).
QUANTITIES = (*METRICS, "throughput_product", "defect_product")

#: Each product's two factors.
PRODUCTS = {"throughput_product": ("throughput_mm2_s", "mass_g"),
            "defect_product": ("roughness_um", "porosity_pct")}

#: Where a share's binomial noise scale is clipped (%): a saturated share keeps some noise.
SHARE_CLIP_PCT = (5.0, 95.0)

METHOD = ("grouped cross-conformal (split conformal on the k-fold cross-validated residuals, "
          "folds by (U, omega) point), scores normalised by sqrt((c std)^2 + (rho mean)^2)")


def check_confidence(confidence):
    """``confidence`` as a float strictly between 0 and 1; a ValueError naming it otherwise."""
    try:
        value = float(confidence)
    except (TypeError, ValueError):
        raise ValueError(f"confidence must be a number between 0 and 1, got {confidence!r}") from None
    if not 0 < value < 1:       # also rejects NaN
        raise ValueError(f"confidence must be between 0 and 1 (e.g. 0.9), got {confidence}")
    return value


def with_products(mean, std=None, metrics=METRICS, products=PRODUCTS):
    """Append the product columns of ``products`` to metric columns.

    Parameters
    ----------
    mean : array_like, shape (n, k)
        Metrics in ``metrics`` order (metric units; default the four of :data:`METRICS`).
    std : array_like, shape (n, k), optional
        Their std; the products' std is first order, the factors' errors independent:
        ``std(a b) = hypot(std_a b, a std_b)``.
    metrics : sequence of str
        The metrics' names, in column order.
    products : dict
        ``{product: (factor, factor)}``, factors among ``metrics`` (default :data:`PRODUCTS`;
        ``{}``: none, the columns are returned as they are).

    Returns
    -------
    numpy.ndarray, shape (n, k + len(products)), or a pair of them with ``std``
    """
    mean = np.asarray(mean, float)
    col = {m: j for j, m in enumerate(metrics)}
    pairs = [(col[a], col[b]) for a, b in products.values()]
    out = np.column_stack([mean, *(mean[:, a] * mean[:, b] for a, b in pairs)])
    if std is None:
        return out
    std = np.asarray(std, float)
    return out, np.column_stack([std, *(np.hypot(std[:, a] * mean[:, b], mean[:, a] * std[:, b])
                                        for a, b in pairs)])


def share_scale(values):
    """What a share's run-to-run noise is proportional to: ``sqrt(C (100 - C))`` [%], C [%] clipped to
    :data:`SHARE_CLIP_PCT` (a binomial share's sd, up to a constant; never zero)."""
    share = np.clip(np.asarray(values, float), *SHARE_CLIP_PCT)
    return np.sqrt(share * (100.0 - share))


def noise_scale(mean, shares=None):
    """What each column's run-to-run noise is proportional to: the value itself, or
    :func:`share_scale` of it for the columns ``shares`` marks (a boolean per column; None: none)."""
    mean = np.asarray(mean, float)
    if shares is None or not np.any(shares):
        return mean
    return np.where(np.asarray(shares, bool), share_scale(mean), mean)


def relative_noise(df, n_restarts=0, random_state=0, metrics=METRICS, products=PRODUCTS, shares=()):
    """Run-to-run noise of each quantity relative to its value, shape (k + len(products),) (dimensionless).

    With replicates (>= 2 runs at some point): the pooled relative seed-to-seed sd,
    ``sqrt(mean over runs of ((y - point mean) / point mean)^2 x n/(n - points))``.
    With one run per point: the white-noise std of a :class:`GPSurrogate` fitted to
    all runs, over the mean |metric|.  The products: ``hypot`` of their factors'
    (independent noise, first order).  ``metrics`` and ``products``: as :func:`with_products`'s
    (default the four metrics and the hybrid indices' two products).  ``shares``: the metrics
    (in %) whose noise is taken relative to :func:`share_scale` of their value instead.

    Returns
    -------
    rho : numpy.ndarray, shape (k + len(products),)
    source : str
        Which of the two estimates it is.
    """
    Y = df[list(metrics)].to_numpy(float)
    share = np.isin(list(metrics), list(shares))
    groups = point_groups(df)
    counts = np.bincount(groups)
    if (counts >= 2).any():
        means = np.stack([np.bincount(groups, Y[:, j]) / counts for j in range(Y.shape[1])], axis=1)[groups]
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(share, (Y - means) / share_scale(means), Y / means - 1.0)
        dof = len(Y) - len(counts)
        rho = np.sqrt((rel ** 2).sum(axis=0) / dof)
        source = f"pooled seed-to-seed sd of {len(Y)} runs at {len(counts)} points (replicates)"
    else:
        gp = GPSurrogate(n_restarts=n_restarts, random_state=random_state).fit(df[input_columns(df)]
                                                                                .to_numpy(float), Y)
        rho = gp.noise_std_ / np.where(share, share_scale(Y).mean(axis=0), np.abs(Y).mean(axis=0))
        source = "Gaussian process white-noise term (one run per point)"
    col = {m: j for j, m in enumerate(metrics)}
    rho = np.r_[rho, [np.hypot(rho[col[a]], rho[col[b]]) for a, b in products.values()]]
    return rho, source


def conformal_quantile(scores, confidence, n_runs=None):
    """The split-conformal quantile of non-negative scores, per column.

    Parameters
    ----------
    scores : array_like, shape (m, k)
        Scores of held-out runs (several cross-validation repeats may be pooled).
    confidence : float
        Coverage level, 0 < confidence < 1.
    n_runs : int, optional
        Distinct runs the scores come from (default m).  With one score per run this
        is split conformal's ``ceil(confidence (n + 1))``-th smallest score, whose
        coverage of a new run is ``ceil(confidence (n + 1)) / (n + 1)`` on average
        over calibration sets; scores pooled over repeats are taken at that level
        (``method="higher"``), the same expected coverage.

    Returns
    -------
    numpy.ndarray, shape (k,)
        ``inf`` where ``ceil(confidence (n + 1)) > n`` (too few runs for the confidence).
    """
    scores = np.asarray(scores, float)
    n = len(scores) if n_runs is None else int(n_runs)
    rank = math.ceil(check_confidence(confidence) * (n + 1))
    if rank > n:
        return np.full(scores.shape[1:], np.inf)
    return np.quantile(scores, rank / (n + 1), axis=0, method="higher")


def _scale(mean, std, c, rho, shares=None):
    """Single-run predictive scale sqrt((c s)^2 + (rho mu)^2) (mu: :func:`noise_scale`'s), never below
    1e-12 |mu|."""
    return np.maximum(np.hypot(c * std, rho * noise_scale(mean, shares)), 1e-12 * np.abs(mean) + 1e-300)


def calibrate(y, mean, std, rho, shares=None):
    """Inflation factor c of the model's std and the conformal scores of held-out runs.

    Parameters
    ----------
    y, mean, std : array_like, shape (m, 6)
        Held-out runs (:func:`with_products`), their cross-validated predictions and
        the predicting model's std of its mean.
    rho : array_like, shape (6,)
        Relative run-to-run noise (:func:`relative_noise`).
    shares : array_like of bool, optional
        The columns whose noise scales with :func:`share_scale` of the prediction, not with it.

    Returns
    -------
    c : numpy.ndarray, shape (6,)
        ``max(mean(r^2) - mean((rho mu)^2), 0) / mean(s^2)``, square-rooted (0 for a
        model without spread).
    scores : numpy.ndarray, shape (m, 6)
        ``|y - mu| / sigma`` (:mod:`module docs <analysis.surrogate.intervals>`).
    """
    y, mean, std = (np.asarray(a, float) for a in (y, mean, std))
    rho = np.asarray(rho, float)
    excess = np.mean((y - mean) ** 2, axis=0) - np.mean((rho * noise_scale(mean, shares)) ** 2, axis=0)
    spread = np.mean(std ** 2, axis=0)
    c = np.sqrt(np.where(spread > 0, np.clip(excess, 0, None) / np.where(spread > 0, spread, 1), 0.0))
    return c, np.abs(y - mean) / _scale(mean, std, c, rho, shares)


def interval_score(y, lower, upper, confidence):
    """Interval score of central intervals (Gneiting & Raftery 2007, eq. 43), per run.

    ``(u - l) + (2/alpha) (l - y)+ + (2/alpha) (y - u)+`` with ``alpha = 1 - confidence``:
    the width, plus a penalty for each miss growing with its distance; lower is
    better, and its expectation is least for the true quantiles (a proper score).
    Units of y.
    """
    alpha = 1.0 - check_confidence(confidence)
    y, lower, upper = (np.asarray(a, float) for a in (y, lower, upper))
    return (upper - lower) + 2 / alpha * (np.clip(lower - y, 0, None) + np.clip(y - upper, 0, None))


def metrics_of(model):
    """The metrics a surrogate predicts, in its column order: its ``metrics`` attribute (a
    calibrated surrogate or a stack of them), else the paper's four (:data:`METRICS`)."""
    return tuple(getattr(model, "metrics", None) or METRICS)


def quantities_of(model):
    """The quantities of a calibrated surrogate's intervals, in column order: its metrics, then
    its products (:data:`QUANTITIES` for one of the paper's four metrics)."""
    return tuple(getattr(model, "quantities", None) or QUANTITIES)


class _Coverage:
    """What a calibrated surrogate's level needs of its runs, from ``confidence`` and ``n_runs``;
    and its intervals from ``half_widths``."""

    def runs_needed(self, confidence=None):
        """Least calibration runs for a finite interval at ``confidence``: ``ceil(c / (1 - c))``."""
        c = self.confidence if confidence is None else check_confidence(confidence)
        return math.ceil(c / (1 - c) - 1e-9)

    def is_finite(self, confidence=None):
        """True if there are enough calibration runs for finite intervals at ``confidence``."""
        return self.n_runs >= self.runs_needed(confidence)

    def predict_interval(self, X, confidence=None, kind="run"):
        """Lower and upper ends of the central intervals of the quantities at X.

        Parameters
        ----------
        X : array_like, shape (n, k)
            U (mm/s), omega (rad/s), then any extra axes (config units), in the model's input order.
        confidence : float, optional
            Coverage level (default ``self.confidence``).
        kind : {"run", "mean"}
            ``run``: where a single new DEM run lands (noise included);
            ``mean``: the expected metric.

        Returns
        -------
        mean, lower, upper : numpy.ndarray, shape (n, len(quantities))
            Columns in ``self.quantities`` order (the six :data:`QUANTITIES` for the four
            metrics), their units.
        """
        if kind not in ("run", "mean"):
            raise ValueError(f"kind must be 'run' or 'mean', got {kind!r}")
        mean, run, of_mean = self.half_widths(X, confidence)
        half = run if kind == "run" else of_mean
        return mean, mean - half, mean + half


class CalibratedSurrogate(_Coverage):
    """A fitted candidate with its calibrated intervals.

    Parameters
    ----------
    model : fitted estimator
        Gives ``predict(X, return_std=True)`` (the candidates do), one column per metric.
    c : array_like, shape (q,)
        Inflation of the model's std per quantity (:func:`calibrate`; q = 6 for the four
        metrics and their two products).
    rho : array_like, shape (q,)
        Relative run-to-run noise (:func:`relative_noise`).
    scores : array_like, shape (m, q)
        Conformal scores of the held-out runs (:func:`calibrate`).
    n_runs : int
        Distinct runs behind the scores.
    confidence : float
        Default coverage level of :meth:`predict_interval` (config ``surrogate.confidence``).
    noise_source : str
        Where ``rho`` comes from.
    metrics : sequence of str, optional
        The model's metrics in its column order (default the paper's four, :data:`METRICS`).
    products : dict, optional
        Products calibrated as further quantities, ``{name: (factor, factor)}`` (default
        :data:`PRODUCTS` with the default metrics, else none).
    shares : sequence of str, optional
        Metrics (in %) whose run-to-run noise scales with :func:`share_scale` of their value
        (default none).

    ``predict(X)`` is the model's; ``predict(X, return_std=True)`` gives the
    calibrated std of the mean, ``c s(x)``; :meth:`predict_interval` the intervals.
    """

    provides_std = True
    method = METHOD
    metrics = tuple(METRICS)        # class defaults: a model saved before these attributes has them
    products = PRODUCTS
    shares = ()

    def __init__(self, model, c, rho, scores, n_runs, confidence=0.9, noise_source="", metrics=None,
                 products=None, shares=None):
        self.model = model
        self.c = np.asarray(c, float)
        self.rho = np.asarray(rho, float)
        self.scores = np.asarray(scores, float)
        self.n_runs = int(n_runs)
        self.confidence = check_confidence(confidence)
        self.noise_source = noise_source
        if metrics is not None:
            self.metrics = tuple(metrics)
        if products is not None or self.metrics != tuple(METRICS):
            self.products = dict(products or {})
        if shares:
            self.shares = tuple(shares)

    @property
    def name(self):
        return getattr(self.model, "name", type(self.model).__name__)

    @property
    def quantities(self):
        """The metrics, then the products: the columns of the intervals."""
        return (*self.metrics, *self.products)

    def predict(self, X, return_std=False):
        """Predicted metrics (n, k); with ``return_std`` also the calibrated std of the mean, ``c s(x)``."""
        if not return_std:
            return self.model.predict(X)
        mean, std = self.model.predict(X, return_std=True)
        return mean, np.asarray(std, float) * self.c[:len(self.metrics)]

    def multiplier(self, confidence=None):
        """The conformal multiplier q per quantity, shape (q,)."""
        return conformal_quantile(self.scores, self.confidence if confidence is None else confidence,
                                  self.n_runs)

    def half_widths(self, X, confidence=None):
        """The quantities at X and the half-widths of their run and mean intervals.

        Returns
        -------
        mean, run, of_mean : numpy.ndarray, shape (n, q)
            ``q sigma(x)`` and ``q c s(x)`` (module docs).
        """
        mean, std = with_products(*self.model.predict(np.asarray(X, float), return_std=True),
                                  self.metrics, self.products)
        q = self.multiplier(confidence)
        shares = np.isin(self.quantities, self.shares)
        return mean, q * _scale(mean, std, self.c, self.rho, shares), q * self.c * std

    def summary(self):
        """JSON-ready: method, noise source, rho, c and the multiplier at the default confidence."""
        q = self.multiplier()
        return {"method": self.method, "confidence": self.confidence, "n_calibration_runs": self.n_runs,
                "noise_source": self.noise_source,
                **({"binomial_noise": {m: "sd proportional to sqrt(C (100 - C)), C clipped to "
                                          f"{SHARE_CLIP_PCT[0]:g}..{SHARE_CLIP_PCT[1]:g} %" for m in self.shares}}
                   if self.shares else {}),
                **{k: {name: float(v) for name, v in zip(self.quantities, values)}
                   for k, values in (("relative_noise", self.rho), ("std_inflation", self.c),
                                     ("multiplier", q))}}


class SurrogateStack:
    """Fitted surrogates of disjoint metrics over the same inputs, answering as one.

    Parameters
    ----------
    parts : sequence of fitted estimators
        Each gives ``predict(X)`` and ``predict(X, return_std=True)``, one column per metric.
    part_metrics : sequence of sequence of str, optional
        Each part's metrics in its column order (default :func:`metrics_of` of each part).

    ``predict`` gives the parts' columns side by side, in ``metrics`` order.
    """

    def __init__(self, parts, part_metrics=None):
        self.parts = list(parts)
        self.part_metrics = [tuple(m) for m in (part_metrics or [metrics_of(p) for p in self.parts])]
        names = [m for ms in self.part_metrics for m in ms]
        if len(set(names)) != len(names):
            raise ValueError(f"stacked surrogates must predict disjoint metrics, got {names}")

    @property
    def provides_std(self):
        """True when every part gives a predictive standard deviation."""
        return all(getattr(p, "provides_std", False) for p in self.parts)

    @property
    def metrics(self):
        """Every part's metrics, in the parts' order."""
        return tuple(m for ms in self.part_metrics for m in ms)

    def predict(self, X, return_std=False):
        """The parts' predictions side by side, (n, k) [metric units]; with ``return_std`` also their std."""
        if not return_std:
            return np.column_stack([p.predict(X) for p in self.parts])
        out = [p.predict(X, return_std=True) for p in self.parts]
        return np.column_stack([m for m, _ in out]), np.column_stack([s for _, s in out])


class CalibratedStack(SurrogateStack, _Coverage):
    """Calibrated surrogates (:class:`CalibratedSurrogate`) of disjoint metrics, answering as one.

    The chosen model of the paper's four metrics and the same candidate fitted to the
    layer-structure metrics (:mod:`analysis.surrogate.structure`): each keeps its own
    calibration; predictions, standard deviations, multipliers and intervals are the parts'
    side by side. ``metrics``: the parts' metrics; ``quantities``: each part's metrics and
    products, part after part. The parts share the confidence level.
    """

    method = METHOD

    def __init__(self, parts):
        parts = list(parts)
        levels = {p.confidence for p in parts}
        if len(levels) != 1:
            raise ValueError(f"stacked surrogates must share a confidence level, got {sorted(levels)}")
        super().__init__(parts, [p.metrics for p in parts])

    @property
    def confidence(self):
        return self.parts[0].confidence

    @property
    def n_runs(self):
        """The fewest calibration runs of a part (each part calibrates on the same runs)."""
        return min(p.n_runs for p in self.parts)

    @property
    def noise_source(self):
        return self.parts[0].noise_source

    @property
    def name(self):
        return self.parts[0].name

    @property
    def quantities(self):
        return tuple(q for p in self.parts for q in p.quantities)

    @property
    def model(self):
        """The parts' uncalibrated models as one :class:`SurrogateStack` (predictions without intervals)."""
        return SurrogateStack([p.model for p in self.parts], self.part_metrics)

    def multiplier(self, confidence=None):
        """The parts' conformal multipliers side by side, shape (len(quantities),)."""
        return np.concatenate([p.multiplier(confidence) for p in self.parts])

    def half_widths(self, X, confidence=None):
        """The parts' :meth:`CalibratedSurrogate.half_widths` side by side, in ``quantities`` order."""
        out = [p.half_widths(X, confidence) for p in self.parts]
        return tuple(np.column_stack([o[k] for o in out]) for k in range(3))

    def summary(self):
        """JSON-ready: the first part's :meth:`CalibratedSurrogate.summary` with every part's rho, c and
        multiplier per quantity."""
        parts = [p.summary() for p in self.parts]
        merged = {**parts[0], "n_calibration_runs": self.n_runs}
        for key in ("relative_noise", "std_inflation", "multiplier"):
            merged[key] = {q: v for s in parts for q, v in s[key].items()}
        return merged


def calibrated_from_predictions(model, predictions, df, rho, confidence, noise_source="", metrics=METRICS,
                                products=PRODUCTS, shares=()):
    """Wrap ``model`` with the calibration from its cross-validated predictions.

    Parameters
    ----------
    model : fitted estimator with ``predict(X, return_std=True)``
    predictions : pandas.DataFrame
        The model's held-out predictions (:func:`analysis.surrogate.selection.cross_validate_models`
        with ``return_predictions``, rows of one model and the ``kfold`` scheme):
        ``row``, ``<metric>`` (prediction) and ``<metric>_std`` columns.
    df : pandas.DataFrame
        The runs (rows as ``predictions["row"]``).
    rho, confidence, noise_source
        As :class:`CalibratedSurrogate`.
    metrics, products
        The model's metrics (column order) and the products calibrated beside them
        (:func:`with_products`; default the paper's four and the hybrid indices' two).
    shares : sequence of str
        Metrics whose noise scales with :func:`share_scale` (``rho`` estimated so,
        :func:`relative_noise`'s ``shares``).
    """
    rows = predictions["row"].to_numpy(int)
    metrics = list(metrics)
    y = with_products(df[metrics].to_numpy(float)[rows], None, metrics, products)
    mean, std = with_products(predictions[metrics].to_numpy(float),
                              predictions[[f"{m}_std" for m in metrics]].to_numpy(float), metrics, products)
    c, scores = calibrate(y, mean, std, rho, np.isin([*metrics, *products], list(shares)))
    return CalibratedSurrogate(model, c, rho, scores, len(np.unique(rows)), confidence, noise_source,
                               metrics, products, shares)


def unbounded_warning(grid, n_runs, confidence):
    """A one-line warning if ``grid`` holds infinite values (interval bounds no calibration run could
    set: split conformal needs ``ceil(confidence (n + 1)) <= n`` runs), else None."""
    numeric = grid.select_dtypes("number")
    columns = [c for c in numeric.columns if np.isinf(numeric[c].to_numpy(float)).any()]
    if not columns:
        return None
    need = next(n for n in itertools.count(1) if math.ceil(confidence * (n + 1)) <= n)  # conformal_quantile's
    return (f"warning: {len(columns)} interval columns of the grid are infinite ({', '.join(columns[:3])}"
            f"{', ...' if len(columns) > 3 else ''}): {100 * confidence:g} % intervals need at least {need} "
            f"calibration runs, the model has {n_runs}; add sweep points or replicates, or lower "
            "surrogate.confidence")


def interval_frame(model, X, confidence=None):
    """The run and mean intervals of a calibrated surrogate's quantities at X as columns.

    Returns
    -------
    pandas.DataFrame
        ``<q>_lo``, ``<q>_hi`` (single run) and ``<q>_mean_lo``, ``<q>_mean_hi`` for
        every quantity q of the model (:func:`quantities_of`: the six :data:`QUANTITIES`, then
        the layer-structure metrics of a :class:`CalibratedStack`), in their units.
    """
    mean, run, of_mean = model.half_widths(X, confidence)
    cols = {}
    for j, q in enumerate(quantities_of(model)):
        cols.update({f"{q}_lo": mean[:, j] - run[:, j], f"{q}_hi": mean[:, j] + run[:, j],
                     f"{q}_mean_lo": mean[:, j] - of_mean[:, j], f"{q}_mean_hi": mean[:, j] + of_mean[:, j]})
    return pd.DataFrame(cols)
