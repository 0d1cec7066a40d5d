"""Candidate surrogates with a predictive standard deviation, and their choice by cross-validation.

The paper fits one network on one 35/10 split.  Here three kinds of model are
scored on the same runs, by repeated k-fold and leave-one-point-out
cross-validation grouped by (U, omega) point (replicates of a point are never
split), and the best is the one the maps, the grid and the recommendation use:

``mlp``
    The paper's Table 2 network (:func:`analysis.surrogate.make_surrogate`),
    as an ensemble of ``mlp_members`` networks started from different random
    seeds (:class:`MLPEnsemble`): the prediction is their mean, the
    predictive standard deviation their spread.
``gp``
    A Gaussian process per metric (:class:`GPSurrogate`): scikit-learn's
    ``GaussianProcessRegressor`` with ``ConstantKernel * RBF(length_scale=[l_U,
    l_omega]) + WhiteKernel`` on standardised inputs and targets (anisotropic:
    one length scale per speed; the white term is the run-to-run noise).  The
    predictive standard deviation is the posterior's, without the noise term.
``trees``
    Extremely randomised trees (:class:`TreeEnsemble`, ``tree_count`` trees)
    on standardised targets; the standard deviation is the trees' spread.

Choice (:func:`choose_model`): the highest repeated-k-fold R^2 averaged over
the four metrics (R^2, unlike the paper's R, also penalises an offset or a
wrong scale); ties go to the model listed first in ``surrogate.models``.

Every model takes X = (U [mm/s], omega [rad/s]) of shape (n, 2) and returns
the four metrics of :data:`analysis.surrogate.METRICS` in their units;
``predict(X, return_std=True)`` returns ``(mean, std)``, both (n, 4).
"""
from __future__ import annotations

import time
import warnings

import numpy as np
import pandas as pd
from joblib import Parallel, delayed
from scipy.linalg import cho_solve, solve_triangular
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.ensemble import ExtraTreesRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from analysis.surrogate import (METRICS, N_INIT_DEFAULT, _check_dataset, _convergence_messages, _num,
                                atomic_path,
                                inputs_of, make_surrogate, point_folds, point_groups,
                                regression_scores, targets_of)

#: Candidate names and what they are (for tables and the report).
CANDIDATES = {
    "mlp": "paper's Table 2 network, ensemble over random seeds",
    "gp": "Gaussian process, anisotropic RBF + white noise, one per metric",
    "trees": "extremely randomised trees",
}

#: Defaults of the model-choice keys of config.yaml's ``surrogate:`` section (tests only).
DEFAULT_CHOICE = {"models": ["mlp", "gp", "trees"], "cv_repeats": 3, "cv_loo": True,
                  "mlp_members": 5, "gp_restarts": 2, "tree_count": 300}


class GPSurrogate(RegressorMixin, BaseEstimator):
    """One Gaussian process per metric over standardised (U, omega), anisotropic RBF + noise.

    Kernel of each metric (on standardised inputs and targets):
    ``ConstantKernel(1) * RBF([1, 1]) + WhiteKernel(0.1)``, hyperparameters by
    maximum marginal likelihood (``n_restarts`` extra random starts).

    Parameters
    ----------
    n_restarts : int
        Restarts of the kernel optimiser.
    random_state : int
        Seed of those restarts.
    length_scale_bounds : (float, float)
        Bounds of the length scales, in standard deviations of the inputs.
    noise_bounds : (float, float)
        Bounds of the white-noise variance, in variances of the target.

    Attributes
    ----------
    gps_ : list of GaussianProcessRegressor
        The fitted processes, one per metric.
    length_scales_ : numpy.ndarray, shape (4, 2)
        Fitted length scales per metric in input units (mm/s, rad/s).
    noise_std_ : numpy.ndarray, shape (4,)
        Fitted run-to-run noise (white kernel) per metric, metric units.
    convergence_warnings_ : int
        Optimiser warnings (e.g. a length scale at its bound), not re-emitted.
    """

    provides_std = True

    def __init__(self, n_restarts=2, random_state=0, length_scale_bounds=(0.05, 50.0),
                 noise_bounds=(1e-6, 1.0)):
        self.n_restarts = n_restarts
        self.random_state = random_state
        self.length_scale_bounds = length_scale_bounds
        self.noise_bounds = noise_bounds

    def _kernel(self, n_inputs):
        return (ConstantKernel(1.0, (1e-3, 1e3))
                * RBF(np.ones(n_inputs), tuple(self.length_scale_bounds))
                + WhiteKernel(0.1, tuple(self.noise_bounds)))

    def fit(self, X, Y):
        """Fit on X (n, 2) [mm/s, rad/s] and Y (n, 4) [metric units]."""
        X, Y = np.asarray(X, float), np.asarray(Y, float)
        self.x_scaler_ = StandardScaler().fit(X)
        self.y_mean_ = Y.mean(axis=0)
        self.y_scale_ = np.where(Y.std(axis=0) > 0, Y.std(axis=0), 1.0)
        Xs, Ys = self.x_scaler_.transform(X), (Y - self.y_mean_) / self.y_scale_
        self.gps_ = []
        self.convergence_warnings_ = 0
        with warnings.catch_warnings(record=True) as caught, threadpool_limits(1, user_api="blas"):
            warnings.simplefilter("always", ConvergenceWarning)
            for j in range(Ys.shape[1]):          # one process per metric (4), not per point
                gp = GaussianProcessRegressor(self._kernel(X.shape[1]), normalize_y=False,
                                              n_restarts_optimizer=int(self.n_restarts),
                                              random_state=int(self.random_state))
                self.gps_.append(gp.fit(Xs, Ys[:, j]))
        for w in caught:
            if issubclass(w.category, ConvergenceWarning):
                self.convergence_warnings_ += 1
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        self.X_train_ = Xs
        self.length_scales_ = np.array([gp.kernel_.k1.k2.length_scale for gp in self.gps_]) \
            * self.x_scaler_.scale_
        self.noise_std_ = np.sqrt([gp.kernel_.k2.noise_level for gp in self.gps_]) * self.y_scale_
        return self

    def _latent_var(self, Xs_query, Xs_train=None):
        """Posterior variance of each metric's mean (standardised units), shape (m, 4).

        ``Xs_train`` (standardised) replaces the training inputs, with the
        fitted hyperparameters kept: the variance does not depend on the
        targets, so this is the variance after adding runs whose results are
        not known yet (kriging believer).
        """
        Xs_train = self.X_train_ if Xs_train is None else Xs_train
        out = np.empty((len(Xs_query), len(self.gps_)))
        for j, gp in enumerate(self.gps_):
            signal = gp.kernel_.k1
            K = gp.kernel_(Xs_train)                       # white noise on the diagonal
            L = np.linalg.cholesky(K + 1e-10 * np.eye(len(K)))
            v = solve_triangular(L, signal(Xs_train, Xs_query), lower=True)
            out[:, j] = np.clip(signal.diag(Xs_query) - np.sum(v * v, axis=0), 0.0, None)
        return out

    def predict(self, X, return_std=False):
        """Metrics at X (n, 2); with ``return_std`` also the posterior std of the mean, (n, 4)."""
        Xs = self.x_scaler_.transform(np.asarray(X, float))
        mean = np.column_stack([gp.predict(Xs) for gp in self.gps_]) * self.y_scale_ + self.y_mean_
        if not return_std:
            return mean
        return mean, np.sqrt(self._latent_var(Xs)) * self.y_scale_

    def loo_residuals(self):
        """Leave-one-run-out residuals y - y_loo of the training runs, (n, 4), metric units.

        Closed form with the fitted hyperparameters kept:
        ``r_i = [K^-1 y]_i / [K^-1]_ii``.
        """
        out = np.empty((len(self.X_train_), len(self.gps_)))
        for j, gp in enumerate(self.gps_):
            K_inv = cho_solve((gp.L_, True), np.eye(len(self.X_train_)))
            out[:, j] = gp.alpha_ / np.diag(K_inv)
        return out * self.y_scale_


class MLPEnsemble(RegressorMixin, BaseEstimator):
    """The paper's network fitted from ``n_members`` random seeds; mean and spread.

    Member k is :func:`analysis.surrogate.make_surrogate` with ``random_state
    = params["random_state"] + k * n_init`` (each keeps its own ``n_init``
    restarts, so no two members share an initialisation).

    Parameters
    ----------
    params : dict
        The ``surrogate:`` section of config.yaml.
    n_members : int
        Networks in the ensemble (>= 2 for a standard deviation).
    """

    provides_std = True

    def __init__(self, params=None, n_members=5):
        self.params = params
        self.n_members = n_members

    def fit(self, X, Y):
        """Fit every member on X (n, 2) [mm/s, rad/s] and Y (n, 4)."""
        n_init = int(self.params.get("n_init", N_INIT_DEFAULT))
        base = int(self.params["random_state"])
        self.members_ = [make_surrogate({**self.params, "random_state": base + k * n_init}).fit(X, Y)
                         for k in range(int(self.n_members))]
        return self

    def predict(self, X, return_std=False):
        """Mean of the members (n, 4); with ``return_std`` also their standard deviation (ddof 1)."""
        P = np.stack([m.predict(np.asarray(X, float)) for m in self.members_])
        mean = P.mean(axis=0)
        if not return_std:
            return mean
        return mean, P.std(axis=0, ddof=1) if len(P) > 1 else np.zeros_like(mean)


class TreeEnsemble(RegressorMixin, BaseEstimator):
    """Extremely randomised trees on standardised targets; mean and spread of the trees.

    Parameters
    ----------
    n_trees : int
    random_state : int
    min_samples_leaf : int
    """

    provides_std = True

    def __init__(self, n_trees=300, random_state=0, min_samples_leaf=1):
        self.n_trees = n_trees
        self.random_state = random_state
        self.min_samples_leaf = min_samples_leaf

    def fit(self, X, Y):
        """Fit on X (n, 2) [mm/s, rad/s] and Y (n, 4)."""
        Y = np.asarray(Y, float)
        self.y_mean_ = Y.mean(axis=0)
        self.y_scale_ = np.where(Y.std(axis=0) > 0, Y.std(axis=0), 1.0)
        self.forest_ = ExtraTreesRegressor(int(self.n_trees), random_state=int(self.random_state),
                                           min_samples_leaf=int(self.min_samples_leaf))
        self.forest_.fit(np.asarray(X, float), (Y - self.y_mean_) / self.y_scale_)
        return self

    def predict(self, X, return_std=False):
        """Forest mean (n, 4); with ``return_std`` also the trees' standard deviation."""
        X = np.asarray(X, float)
        if not return_std:
            return self.forest_.predict(X) * self.y_scale_ + self.y_mean_
        P = np.stack([t.predict(X) for t in self.forest_.estimators_]).reshape(
            len(self.forest_.estimators_), len(X), -1)
        return P.mean(axis=0) * self.y_scale_ + self.y_mean_, P.std(axis=0) * self.y_scale_


def make_candidate(name, params):
    """Build the unfitted candidate ``name`` (one of :data:`CANDIDATES`) from ``surrogate:`` params.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the known ones).
    """
    p = {**DEFAULT_CHOICE, **params}
    if name == "mlp":
        return MLPEnsemble(dict(params), n_members=int(p["mlp_members"]))
    if name == "gp":
        return GPSurrogate(n_restarts=int(p["gp_restarts"]), random_state=int(p["random_state"]))
    if name == "trees":
        return TreeEnsemble(int(p["tree_count"]), random_state=int(p["random_state"]))
    raise ValueError(f"unknown surrogate model {name!r}; choose from {', '.join(CANDIDATES)}")


def _fold(name, p, X, Y, train, test):
    """Fit a fresh ``name`` candidate on one fold: (test rows, their predictions, ConvergenceWarnings, fit s)."""
    t0 = time.perf_counter()
    with _convergence_messages() as messages:
        model = make_candidate(name, p).fit(X[train], Y[train])
    return test, model.predict(X[test]), len(messages), time.perf_counter() - t0


def cross_validate_models(df, params, log=None, n_jobs=1):
    """Score every candidate of ``params["models"]`` by grouped cross-validation.

    Schemes: ``kfold``: ``cv_folds``-fold over the (U, omega) points, repeated
    ``cv_repeats`` times with shuffle seeds ``split_seed + r``; each repeat's
    pooled out-of-fold predictions are scored (:func:`regression_scores`) and
    the scores averaged over repeats (``*_sd``: their spread).  ``loo``
    (when ``cv_loo``): leave one (U, omega) point out, all its replicates
    together, pooled.

    Parameters
    ----------
    df : pandas.DataFrame
        The runs (speeds and metrics, finite).
    params : dict
        The ``surrogate:`` section (``models``, ``cv_folds``, ``cv_repeats``,
        ``cv_loo``, ``split_seed`` and the models' own keys).
    log : callable, optional
        Called with a progress line per model and scheme.
    n_jobs : int
        Folds fitted at once (joblib processes); the scores do not depend on it.

    Returns
    -------
    pandas.DataFrame
        One row per (model, scheme, metric): ``model``, ``scheme``,
        ``metric``, ``symbol``, ``R``, ``R2``, ``MAPE_pct``, ``R_sd``,
        ``R2_sd``, ``MAPE_pct_sd``, ``n_splits`` (folds x repeats, or points),
        ``fit_s`` (the scheme's fits, summed over its folds), ``convergence_warnings``.
    """
    p = {**DEFAULT_CHOICE, **params}
    _check_dataset(df)
    X, Y = inputs_of(df), targets_of(df)
    n_points = int(point_groups(df).max()) + 1
    schemes = [("kfold", [point_folds(df, p["cv_folds"], int(p["split_seed"]) + r)
                          for r in range(int(p["cv_repeats"]))])]
    if p["cv_loo"]:
        schemes.append(("loo", [point_folds(df, n_points, 0)]))
    tasks = [(name, scheme, r, train, test) for name in p["models"] for scheme, repeats in schemes
             for r, splits in enumerate(repeats) for train, test in splits]
    folds = Parallel(n_jobs=n_jobs)(delayed(_fold)(name, p, X, Y, train, test)
                                    for name, _, _, train, test in tasks)
    rows = []
    for name in p["models"]:
        for scheme, repeats in schemes:
            preds = {r: np.full_like(Y, np.nan) for r in range(len(repeats))}
            warned, elapsed = 0, 0.0
            for (n, sc, r, _, _), (test, fold_pred, n_warn, fit_s) in zip(tasks, folds):
                if (n, sc) == (name, scheme):
                    preds[r][test] = fold_pred
                    warned += n_warn
                    elapsed += fit_s
            scores = [regression_scores(Y, pred) for pred in preds.values()]
            for m, (symbol, _) in METRICS.items():
                values = {k: np.array([np.nan if s[m][k] is None else s[m][k] for s in scores])
                          for k in ("R", "R2", "MAPE_pct")}
                rows.append({"model": name, "scheme": scheme, "metric": m, "symbol": symbol,
                             **{k: float(np.mean(v)) for k, v in values.items()},
                             **{f"{k}_sd": float(np.std(v)) for k, v in values.items()},
                             "n_splits": sum(len(s) for s in repeats),
                             "fit_s": round(elapsed, 2), "convergence_warnings": warned})
            if log:
                r2 = np.mean([r["R2"] for r in rows[-len(METRICS):]])
                log(f"{name:>5} {scheme:>5}: mean R^2 {r2:.3f} over the metrics "
                    f"({sum(len(s) for s in repeats)} fits, {elapsed:.1f} s)")
    return pd.DataFrame(rows)


def choose_model(table, order=None):
    """The candidate with the highest mean k-fold R^2 over the metrics; ties: first in ``order``.

    Returns
    -------
    name : str
    ranking : pandas.Series
        Mean k-fold R^2 per model, best first.
    """
    kfold = table[table["scheme"] == "kfold"]
    mean_r2 = kfold.groupby("model", sort=False)["R2"].mean()
    order = list(order or mean_r2.index)
    rank = pd.Series({m: mean_r2[m] for m in order if m in mean_r2.index})
    rank = rank.fillna(-np.inf)
    best = max(rank.index, key=lambda m: (rank[m], -order.index(m)))
    return best, rank.sort_values(ascending=False, kind="stable")


def model_choice_markdown(table, chosen, ceiling=None, level=None):
    """The cross-validation table as Markdown, the chosen model in bold, the noise ceiling beside it.

    ``ceiling`` is :func:`analysis.noise_floor.accuracy_ceiling` (or None).
    """
    symbols = [s for s, _ in METRICS.values()]
    title = "# Surrogate model choice by cross-validation" + (f" ({level})" if level else "")
    head = ["model", "scheme", f"R: {' / '.join(symbols)}", f"R^2: {' / '.join(symbols)}",
            f"MAPE %: {' / '.join(symbols)}", "mean R^2", "fits", "s"]
    lines = [title, "",
             f"Chosen: **{chosen}** ({CANDIDATES.get(chosen, chosen)}): the highest repeated "
             "k-fold R^2 averaged over the four metrics. Folds are (U, omega) points: the "
             "replicates of a point are left out together.", "",
             "| " + " | ".join(head) + " |", "|---|---|---|---|---|---:|---:|---:|"]
    for (model, scheme), block in table.groupby(["model", "scheme"], sort=False):
        block = block.set_index("metric").loc[list(METRICS)]
        name = f"**{model}**" if model == chosen else model
        fmt = lambda col, f: " / ".join("n/a" if not np.isfinite(v) else format(v, f)  # noqa: E731
                                        for v in block[col])
        lines.append(f"| {name} | {scheme} | {fmt('R', '.3f')} | {fmt('R2', '.3f')} | "
                     f"{fmt('MAPE_pct', '.1f')} | {block['R2'].mean():.3f} | "
                     f"{int(block['n_splits'].iloc[0])} | {block['fit_s'].iloc[0]:.1f} |")
    if ceiling:
        c = [ceiling[m] for m in METRICS]
        fmt = lambda key, f: " / ".join(format(x[key], f) for x in c)  # noqa: E731
        lines.append(f"| *noise ceiling* | replicates | {fmt('R_max', '.3f')} | "
                     f"{fmt('R2_max', '.3f')} | {fmt('MAPE_floor_pct', '.1f')} | "
                     f"{np.mean([x['R2_max'] for x in c]):.3f} | | |")
        lines += ["", "The noise ceiling is the best a perfect model of the mean metric could "
                  "score on single runs, given the seed-to-seed spread (noise_floor.md): "
                  "no model can beat it, and scores near it mean the model is as good as the "
                  "data allow."]
    else:
        lines += ["", "One run per point: the noise ceiling is not measured "
                  "(set `sweep.replicates` >= 2)."]
    return "\n".join(lines) + "\n"


def write_model_choice(table, chosen, csv_path, md_path, ceiling=None, level=None):
    """Write the cross-validation table as CSV (with a ``chosen`` column) and Markdown, atomically."""
    with atomic_path(csv_path) as tmp:
        table.assign(chosen=table["model"] == chosen).to_csv(tmp, index=False)
    with atomic_path(md_path) as tmp:
        tmp.write_text(model_choice_markdown(table, chosen, ceiling, level))


def read_choice(csv_path):
    """The chosen model's name from a model_choice.csv written by :func:`write_model_choice`."""
    table = pd.read_csv(csv_path)
    chosen = table.loc[table["chosen"].astype(bool), "model"].unique()
    if len(chosen) != 1:
        raise ValueError(f"{csv_path} names {len(chosen)} chosen models, expected 1")
    return str(chosen[0]), table


def fit_chosen(df, params, name, train_idx=None):
    """Fit candidate ``name`` on the runs ``train_idx`` (default all) of ``df``.

    Returns
    -------
    model : fitted estimator with ``predict(X, return_std=True)``
    info : dict
        JSON-ready: ``name``, ``description``, ``fit_time_s``, ``n_train``,
        and for the GP the fitted length scales (mm/s, rad/s) and noise std
        per metric.
    """
    X, Y = inputs_of(df), targets_of(df)
    rows = np.arange(len(df)) if train_idx is None else np.asarray(train_idx, int)
    model = make_candidate(name, params)
    t0 = time.perf_counter()
    with _convergence_messages() as messages:
        model.fit(X[rows], Y[rows])
    info = {"name": name, "description": CANDIDATES[name], "n_train": int(len(rows)),
            "fit_time_s": round(time.perf_counter() - t0, 3),
            "convergence_warnings": messages}
    if isinstance(model, GPSurrogate):
        info["length_scale"] = {m: {"U_mm_s": float(ls[0]), "omega_rad_s": float(ls[1])}
                                for m, ls in zip(METRICS, model.length_scales_)}
        info["noise_std"] = {m: float(s) for m, s in zip(METRICS, model.noise_std_)}
    return model, info


def chosen_summary(model, info, df, split, table):
    """JSON-ready record of the chosen model for scores.json.

    Parameters
    ----------
    model : fitted candidate (from :func:`fit_chosen` on the training rows)
    info : dict
        :func:`fit_chosen`'s info.
    df : pandas.DataFrame
        The runs.
    split : dict
        ``scores["split"]`` of :func:`analysis.surrogate.fit_surrogate` (row positions).
    table : pandas.DataFrame
        The cross-validation table (:func:`cross_validate_models` or model_choice.csv).

    Returns
    -------
    dict
        ``info`` plus ``fitted_on``, ``train`` and ``test`` scores
        (:func:`analysis.surrogate.regression_scores`), ``cv`` (per scheme and
        metric: R, R2, MAPE_pct of the candidate) and ``ranking`` (mean k-fold
        R^2 per candidate).
    """
    X, Y = inputs_of(df), targets_of(df)
    train, test = (np.asarray(split[k], int) for k in ("train", "test"))
    mine = table[table["model"] == info["name"]]
    cv = {scheme: {row.metric: {"R": _num(row.R), "R2": _num(row.R2),
                                "MAPE_pct": _num(row.MAPE_pct)} for row in block.itertuples()}
          for scheme, block in mine.groupby("scheme", sort=False)}
    _, ranking = choose_model(table)
    return {**info,
            "fitted_on": "the training points of the paper-style split (test points unseen)",
            "predictive_std": "std of the predicted mean: " + {
                "gp": "Gaussian-process posterior (noise term excluded)",
                "mlp": "spread of the ensemble's networks",
                "trees": "spread of the trees"}[info["name"]],
            "train": regression_scores(Y[train], model.predict(X[train])),
            "test": regression_scores(Y[test], model.predict(X[test])),
            "cv": cv,
            "ranking_mean_kfold_R2": {m: _num(v) for m, v in ranking.items()}}
