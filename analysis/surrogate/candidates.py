"""Candidate surrogates with a predictive standard deviation, as scikit-learn
estimators: :class:`GPSurrogate` (a Gaussian process per metric),
:class:`MLPEnsemble` (the paper's Table 2 network started from several seeds)
and :class:`TreeEnsemble` (extremely randomised trees); :func:`make_candidate`
builds one by name. :mod:`analysis.surrogate.selection` chooses among them.
"""
from __future__ import annotations

import copy
import warnings

import numpy as np
from joblib import Parallel, delayed
from scipy.linalg import cho_solve, solve_triangular
from sklearn.ensemble import ExtraTreesRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from analysis.surrogate.network import MetricsRegressor, convergence_messages, make_surrogate

#: Candidate names and what they are (for tables and the report).
CANDIDATES = {
    "mlp": "paper's Table 2 network, ensemble over random seeds",
    "gp": "Gaussian process, anisotropic RBF + white noise, one per metric",
    "trees": "extremely randomised trees",
}


class GPSurrogate(MetricsRegressor):
    """One Gaussian process per metric over the standardised inputs, anisotropic RBF + noise.

    The inputs are any number k of columns: U, omega and a sweep's extra axes
    (:func:`analysis.surrogate.data.inputs_of`).  Kernel of each metric (on
    standardised inputs and targets): ``ConstantKernel(1) * RBF([1] * k) +
    WhiteKernel(0.1)``, one length scale per input, hyperparameters by maximum
    marginal likelihood (``n_restarts`` extra random starts).

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
    length_scales_ : numpy.ndarray, shape (4, k)
        Fitted length scales per metric in input units (U mm/s, omega rad/s, an extra axis
        in its config units).
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

    def fit(self, X, y):
        """Fit on X (n, k) [U mm/s, omega rad/s, then any extra axes in their config units] and
        y (n, 4) [metric units]."""
        X, Y = self._validate_fit(X, y)
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
        """Metrics (n, 4) at X (n, k); with ``return_std`` also the posterior std of the mean, (n, 4)."""
        X = self._validate_predict(X)
        Xs = self.x_scaler_.transform(X)
        mean = np.column_stack([gp.predict(Xs) for gp in self.gps_]) * self.y_scale_ + self.y_mean_
        if not return_std:
            return self._shaped(mean)
        return self._shaped(mean), self._shaped(np.sqrt(self._latent_var(Xs)) * self.y_scale_)

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


class MLPEnsemble(MetricsRegressor):
    """The paper's network fitted from ``n_members`` random seeds; mean and spread.

    Member k is :func:`analysis.surrogate.network.make_surrogate` with ``random_state
    = params["random_state"] + k * n_init`` (each keeps its own ``n_init``
    restarts, so no two members share an initialisation).

    Parameters
    ----------
    params : dict
        The ``surrogate:`` section of config.yaml.
    n_members : int
        Networks in the ensemble (>= 2 for a standard deviation).
    n_jobs : int
        Members fitted at once (joblib processes; the fit does not depend on it). 1 inside
        cross-validation, whose folds are the parallel tasks.
    """

    provides_std = True

    def __init__(self, params=None, n_members=5, n_jobs=1):
        self.params = params
        self.n_members = n_members
        self.n_jobs = n_jobs

    def fit(self, X, y):
        """Fit every member on X (n, k) [U mm/s, omega rad/s, then any extra axes] and y (n, 4)."""
        X, Y = self._validate_fit(X, y)
        n_init = int(self.params["n_init"])
        base = int(self.params["random_state"])
        members = [make_surrogate({**self.params, "random_state": base + k * n_init})
                   for k in range(int(self.n_members))]
        if int(self.n_jobs) == 1:
            self.members_ = [m.fit(X, self._shaped(Y)) for m in members]
        else:
            self.members_ = Parallel(n_jobs=int(self.n_jobs))(delayed(m.fit)(X, self._shaped(Y)) for m in members)
        return self

    def predict(self, X, return_std=False):
        """Mean of the members (n, 4); with ``return_std`` also their standard deviation (ddof 1)."""
        X = self._validate_predict(X)
        P = np.stack([m.predict(X) for m in self.members_])
        mean = P.mean(axis=0)
        if not return_std:
            return mean
        return mean, P.std(axis=0, ddof=1) if len(P) > 1 else np.zeros_like(mean)


def refit_warm(ensemble, X, y):
    """A copy of a fitted :class:`MLPEnsemble` refitted on (X, y), each member from its own weights.

    Each member's scalers are refitted on the new runs and its kept network is trained on
    from its fitted weights (``warm_start``; one start instead of ``n_init`` restarts): about
    5x cheaper than a fresh fit when the runs differ little (a leave-one-point-out fit
    started from a k-fold model). Start from a model that has not seen the runs to be held
    out, or their held-out score is optimistic.
    """
    model = copy.deepcopy(ensemble)
    X, Y = model._validate_fit(X, y)
    for member in model.members_:
        Xs = member["scale_inputs"].fit_transform(X)
        target = member[-1]
        ys = target.transformer_.fit_transform(model._shaped(Y).reshape(len(Y), -1))
        restarted = target.regressor_
        net = restarted.best_.set_params(warm_start=True)
        with convergence_messages() as messages, threadpool_limits(1, user_api="blas"):
            net.fit(Xs, ys if ys.shape[1] > 1 else ys[:, 0])
        restarted.loss_, restarted.n_iter_, restarted.losses_ = net.loss_, net.n_iter_, [float(net.loss_)]
        restarted.convergence_warnings_ = messages
        for message in messages:
            warnings.warn(message, ConvergenceWarning, stacklevel=2)
    return model


class TreeEnsemble(MetricsRegressor):
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

    def fit(self, X, y):
        """Fit on X (n, k) [U mm/s, omega rad/s, then any extra axes] and y (n, 4)."""
        X, Y = self._validate_fit(X, y)
        self.y_mean_ = Y.mean(axis=0)
        self.y_scale_ = np.where(Y.std(axis=0) > 0, Y.std(axis=0), 1.0)
        self.forest_ = ExtraTreesRegressor(int(self.n_trees), random_state=int(self.random_state),
                                           min_samples_leaf=int(self.min_samples_leaf))
        self.forest_.fit(X, (Y - self.y_mean_) / self.y_scale_)
        return self

    def predict(self, X, return_std=False):
        """Forest mean (n, 4); with ``return_std`` also the trees' standard deviation."""
        X = self._validate_predict(X)
        # each tree's own predict() re-validates X (about 0.3 ms a tree, 300 trees a call); its tree_.predict
        # on the float32 X that predict() would make gives the same numbers
        X32 = np.ascontiguousarray(X, dtype=np.float32)
        P = np.stack([t.tree_.predict(X32).reshape(len(X), -1) for t in self.forest_.estimators_]).reshape(
            len(self.forest_.estimators_), len(X), -1)
        mean = P.mean(axis=0) * self.y_scale_ + self.y_mean_
        if not return_std:
            return self._shaped(mean)
        return self._shaped(mean), self._shaped(P.std(axis=0) * self.y_scale_)


def make_candidate(name, params):
    """Build the unfitted candidate ``name`` (one of :data:`CANDIDATES`) from ``surrogate:`` params.

    Raises
    ------
    ValueError
        For an unknown name (the message lists the known ones).
    """
    p = params
    if name == "mlp":
        return MLPEnsemble(dict(params), n_members=int(p["mlp_members"]))
    if name == "gp":
        return GPSurrogate(n_restarts=int(p["gp_restarts"]), random_state=int(p["random_state"]))
    if name == "trees":
        return TreeEnsemble(int(p["tree_count"]), random_state=int(p["random_state"]))
    raise ValueError(f"unknown surrogate model {name!r}; choose from {', '.join(CANDIDATES)}")
