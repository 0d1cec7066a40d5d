"""Choosing the adaptive design's next points: a batch that maximises the expected squared
prediction error (MEPE, after Liu, Xu & Wang, 2017) or the drop of the integrated variance
(IMSE) of a Gaussian process per metric (:func:`choose_batch`; the criteria: the docstring of
:mod:`analysis.surrogate.adaptive`).  Inputs: U (mm/s), omega (rad/s), then the sweep's extra
axes (config units).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular

from analysis.surrogate.design_space import among

#: acquisition functions of :func:`choose_batch` (``adaptive.acquisition``)
ACQUISITIONS = ("mepe", "imse")

#: points of the IMSE reference grid over the design box: 21 x 21 over (U, omega); with more
#: design dimensions about as many, ``round(441 ** (1 / d))`` per dimension
REFERENCE_POINTS = 441

#: entries of the largest (reference x candidate) block :func:`_variance_reduction` holds at once
_BLOCK = 20_000_000

def _scaled_nearest(gp, X_query, X_points):
    """Index of the nearest of ``X_points`` (m, k) to each query (n, k), in standardised input units."""
    a, b = gp.x_scaler_.transform(X_query), gp.x_scaler_.transform(X_points)
    d2 = (a * a).sum(1)[:, None] - 2 * a @ b.T + (b * b).sum(1)[None, :]
    return np.argmin(d2, axis=1)


def _reference(bounds_scaled, n=None):
    """A regular grid over the standardised design box: where the integrated variance is summed.

    Parameters
    ----------
    bounds_scaled : sequence of k (lo, hi)
        The box in standardised input units; an input with lo == hi (held) is one value.
    n : int, optional
        Points per design dimension (default: ``round(REFERENCE_POINTS ** (1 / d))`` over d
        dimensions, at least 2: 21 for (U, omega)).

    Returns
    -------
    numpy.ndarray, shape (n ** d, k)
    """
    free = [hi > lo for lo, hi in bounds_scaled]
    if n is None:
        n = max(2, int(round(REFERENCE_POINTS ** (1.0 / max(sum(free), 1)))))
    axes = [np.linspace(lo, hi, n) if f else np.array([lo], float)
            for (lo, hi), f in zip(bounds_scaled, free)]
    return np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def _variance_reduction(gp, Xs_cand, Xs_train, Xs_ref, weight_ref):
    """Drop of the (weighted) mean posterior variance over ``Xs_ref`` if each candidate were run.

    For one metric with signal kernel k, noise variance s_n^2 and posterior
    covariance c(x, x') given the runs ``Xs_train``, running candidate x_c
    lowers the variance at x by ``c(x, x_c)^2 / (c(x_c, x_c) + s_n^2)``; this
    is averaged over the reference points (weights ``weight_ref``) and summed
    over the metrics (standardised units), shape (m,).  Hyperparameters are
    kept and the result does not depend on targets (kriging believer).  All
    inputs are (., k) arrays in standardised units; candidates are taken in
    blocks of at most ``_BLOCK / len(Xs_ref)`` (one block for the (U, omega)
    lattice).
    """
    out = np.zeros(len(Xs_cand))
    w = weight_ref / weight_ref.sum()
    block = max(1, _BLOCK // len(Xs_ref))
    for gp_j in gp.gps_:
        signal, noise = gp_j.kernel_.k1, gp_j.kernel_.k2.noise_level
        L = np.linalg.cholesky(gp_j.kernel_(Xs_train) + 1e-10 * np.eye(len(Xs_train)))
        Vr = solve_triangular(L, signal(Xs_train, Xs_ref), lower=True)        # (n, r)
        for start in range(0, len(Xs_cand), block):                           # blocks of candidates
            C = Xs_cand[start:start + block]
            Vc = solve_triangular(L, signal(Xs_train, C), lower=True)         # (n, b)
            cov = signal(Xs_ref, C) - Vr.T @ Vc                                # (r, b)
            var_c = np.clip(signal.diag(C) - np.sum(Vc * Vc, axis=0), 0.0, None)
            out[start:start + block] += (w @ (cov * cov)) / (var_c + noise)
    return out


def choose_batch(gp, X, candidates, batch_size, error_weight=0.5, exclude=None,
                 acquisition="mepe", bounds=None):
    """Choose ``batch_size`` new points by expected prediction error or integrated variance.

    Parameters
    ----------
    gp : analysis.surrogate.candidates.GPSurrogate
        Fitted on the runs X (all replicates).
    X : numpy.ndarray, shape (n, k)
        Inputs of the runs it was fitted on: U (mm/s), omega (rad/s), then the
        extra axes (config units), in the GP's input order.
    candidates : numpy.ndarray, shape (m, k)
        Where new points may go (a lattice, :func:`analysis.surrogate.design_space.lattice`).
    batch_size : int
    error_weight : float
        w in [0, 1]: weight of the nearest run's leave-one-out error.
    exclude : numpy.ndarray, shape (e, k), optional
        Points never to choose (e.g. a held-out test set); existing points
        are never chosen again.
    acquisition : {"mepe", "imse"}
        ``"mepe"``: a(x) = w e^2(nearest run) + (1 - w) s^2(x), the point
        where the map is least sure (module docstring).  ``"imse"``: the
        point whose run would most lower the posterior variance averaged
        over the whole design box (integrated mean squared error, Cohn's
        active learning), each place of the box weighted by
        ``(1 - w) + w e^2(nearest run) / mean(e^2)``.  Maximum variance
        tends to pick the box's edges and corners; IMSE picks points that
        serve the most of the map, which is what the map error measures.
    bounds : sequence of k (lo, hi), optional
        The design box for ``"imse"``, in the inputs' units (default: the
        candidates' extent); an input with lo == hi is held.

    Returns
    -------
    points : numpy.ndarray, shape (b, k)
    acquisition : numpy.ndarray, shape (b,)
        a(x) of each chosen point when it was chosen (standardised units).
    """
    if acquisition not in ACQUISITIONS:
        raise ValueError(f"unknown acquisition {acquisition!r}; choose one of {ACQUISITIONS}")
    X = np.asarray(X, float)
    points, inverse = np.unique(X, axis=0, return_inverse=True)
    # leave-one-out squared error per run, standardised and summed over metrics;
    # averaged over the replicates of each point
    e2_run = np.sum((gp.loo_residuals() / gp.y_scale_) ** 2, axis=1)
    e2 = np.bincount(inverse.ravel(), weights=e2_run) / np.bincount(inverse.ravel())
    taken = points if exclude is None else np.r_[points, np.asarray(exclude, float).reshape(-1, X.shape[1])]
    keep = ~among(candidates, taken)
    cand = candidates[keep]
    if len(cand) < batch_size:
        raise ValueError(f"only {len(cand)} candidate points left for a batch of {batch_size}")
    Xs_train = gp.x_scaler_.transform(X)
    Xs_cand = gp.x_scaler_.transform(cand)
    if acquisition == "imse":
        if bounds is None:
            bounds = tuple((float(lo), float(hi)) for lo, hi in zip(candidates.min(0),
                                                                   candidates.max(0)))
        corners = gp.x_scaler_.transform(np.array(bounds, float).T)
        ref = _reference(tuple(zip(corners[0], corners[1])))
        ref_e2 = e2[_scaled_nearest(gp, gp.x_scaler_.inverse_transform(ref), points)]
        weight_ref = (1.0 - error_weight) + error_weight * ref_e2 / max(e2.mean(), 1e-12)
    chosen, values = [], []
    for _ in range(int(batch_size)):          # batch slots, each a vectorised sweep of candidates
        if acquisition == "imse":
            acq = _variance_reduction(gp, Xs_cand, Xs_train, ref, weight_ref)
        else:
            var = gp._latent_var(Xs_cand, Xs_train).sum(axis=1)
            design = np.r_[points, cand[chosen]] if chosen else points
            err = np.r_[e2, np.zeros(len(chosen))][_scaled_nearest(gp, cand, design)]
            acq = error_weight * err + (1.0 - error_weight) * var
        acq[chosen] = -np.inf
        best = int(np.argmax(acq))
        chosen.append(best)
        values.append(float(acq[best]))
        Xs_train = np.r_[Xs_train, Xs_cand[best:best + 1]]
    return cand[chosen], np.array(values)

