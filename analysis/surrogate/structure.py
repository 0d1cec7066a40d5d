"""The layer-structure metrics beside the paper's four: a spread layer's void fraction and its
coverage of the substrate (:data:`analysis.columns.STRUCTURE_METRICS`), fitted by the candidate the
model choice chose for the four, with the same settings, and calibrated intervals of their own.

Why: eq. 7's porosity Phi takes 4 R_q as the layer's thickness. Where the deposit is deeper than
that, Phi reads dense (low, even negative) whatever the packing; where the layer is thinner
(patchy, bare substrate between particles) it counts the empty top of the 4 R_q cuboid as void.
The void fraction ``100 (1 - packing fraction)`` takes the measured mean thickness instead, and
the coverage says how much of the substrate the layer covers at all (docs/performance.md: when
eq. 7 misleads).

The four metrics' model, its choice and its scores are untouched: this is a second fit of the
same candidate (:func:`analysis.surrogate.candidates.make_candidate`, the ``surrogate:`` settings)
on the structure metrics alone, scored on the same training / test split and cross-validated on
the model choice's repeated k-fold (the same folds and seeds), whose held-out predictions
calibrate its intervals (:func:`analysis.surrogate.intervals.calibrated_from_predictions`, no
products; the coverage's noise that of a binomial share, :data:`SHARES`), stacked beside the
four's model (:class:`analysis.surrogate.intervals.CalibratedStack`).

Units: inputs U [mm/s], omega [rad/s] (then any swept axis in its config units); the structure
metrics in % (void fraction, coverage).
"""
from __future__ import annotations

import numpy as np
import pandas as pd
from joblib import Parallel, delayed

from analysis.columns import STRUCTURE_METRICS, input_columns
from analysis.metrics.dataset import structure_problem, with_structure_metrics
from analysis.surrogate.candidates import make_candidate
from analysis.surrogate.data import inputs_of, point_folds
from analysis.surrogate.intervals import CalibratedStack, calibrated_from_predictions, relative_noise
from analysis.surrogate.network import convergence_messages
from analysis.surrogate.scores import json_number, regression_scores

#: Structure metrics whose run-to-run noise is a binomial share's, sd ~ sqrt(C (100 - C))
#: (:func:`analysis.surrogate.intervals.share_scale`), not proportional to the value: the coverage
#: piles up at 94-100 % under forward rolling. On the default map (45 runs, the mlp's k-fold
#: held-out predictions) noise proportional to the value gave 90 % intervals of +-11.8 points
#: where the coverage is above 94 % (covering all of those runs; their held-out errors' 90th
#: percentile: 3.4 points) and of +-7.9 points in the patchy layers (covering 84 %); the binomial
#: share gives +-3.7 (covering 90 %) and +-8.4 (covering 95 %).
SHARES = ("coverage_pct",)

#: Where each structure metric comes from, for scores.json.
DERIVED_FROM = {"void_fraction_pct": "100 (1 - packing_fraction): packing fraction = solid volume of the "
                                     "particles centred in the region / (L_x L_y thk_avg)",
                "coverage_pct": "100 coverage: share of profilometer probes with powder above the substrate"}


def structure_targets(df):
    """(n, 2) float array of the layer-structure metrics [%] in :data:`STRUCTURE_METRICS` order."""
    return df[list(STRUCTURE_METRICS)].to_numpy(float)


def _held_out(name, params, X, Y, train, test):
    """Fit candidate ``name`` on the rows ``train``; its mean and std at ``test`` and its warnings."""
    with convergence_messages() as messages:
        model = make_candidate(name, params).fit(X[train], Y[train])
    mean, std = model.predict(X[test], return_std=True)
    return mean, std, len(messages)


def kfold_predictions(df, params, name, n_jobs=1):
    """Held-out predictions of candidate ``name`` on the structure metrics, on the model choice's k-fold.

    The folds are :func:`analysis.surrogate.selection.cross_validate_models`' ``kfold`` scheme's:
    ``cv_folds`` folds over the (U, omega) points, repeated ``cv_repeats`` times with shuffle
    seeds ``split_seed + r``, replicates of a point together.

    Parameters
    ----------
    df : pandas.DataFrame
        The runs, with the structure metrics' columns (:func:`with_structure_metrics`).
    params : dict
        The ``surrogate:`` section.
    name : str
        The candidate (the model choice's).
    n_jobs : int
        Folds fitted at once; the predictions do not depend on it.

    Returns
    -------
    predictions : pandas.DataFrame
        One row per (repeat, run): ``model``, ``scheme`` ('kfold'), ``repeat``, ``row``, the
        inputs, each structure metric's held-out prediction [%] and its ``<metric>_std``.
    warnings : int
        ConvergenceWarnings of the fold fits.
    """
    X, Y = inputs_of(df), structure_targets(df)
    repeats = [point_folds(df, params["cv_folds"], int(params["split_seed"]) + r)
               for r in range(int(params["cv_repeats"]))]
    tasks = [(r, train, test) for r, folds in enumerate(repeats) for train, test in folds]
    done = Parallel(n_jobs=n_jobs)(delayed(_held_out)(name, params, X, Y, train, test) for _, train, test in tasks)
    mean, std = np.full((2, len(repeats), *Y.shape), np.nan)
    for (r, _, test), (fold_mean, fold_std, _) in zip(tasks, done):
        mean[r, test], std[r, test] = fold_mean, fold_std
    metrics = list(STRUCTURE_METRICS)
    n = len(df)
    frame = pd.DataFrame({"model": name, "scheme": "kfold", "repeat": np.repeat(np.arange(len(repeats)), n),
                          "row": np.tile(np.arange(n), len(repeats)),
                          **{c: np.tile(X[:, j], len(repeats)) for j, c in enumerate(input_columns(df))},
                          **{m: mean[:, :, j].ravel() for j, m in enumerate(metrics)},
                          **{f"{m}_std": std[:, :, j].ravel() for j, m in enumerate(metrics)}})
    return frame, sum(w for _, _, w in done)


def kfold_scores(df, predictions):
    """R, R^2 and MAPE (%) of the held-out predictions per structure metric, each repeat's pooled
    scores averaged over the repeats (``*_sd``: their spread), as model_choice.md's.

    Returns
    -------
    dict
        ``{metric: {"R", "R2", "MAPE_pct", "R_sd", "R2_sd", "MAPE_pct_sd"}}``, JSON-ready.
    """
    metrics = list(STRUCTURE_METRICS)
    Y = structure_targets(df)
    per_repeat = [regression_scores(Y[block["row"].to_numpy(int)], block[metrics].to_numpy(float), metrics)
                  for _, block in predictions.groupby("repeat", sort=True)]
    out = {}
    for m in metrics:
        values = {k: np.array([np.nan if s[m][k] is None else s[m][k] for s in per_repeat])
                  for k in ("R", "R2", "MAPE_pct")}
        out[m] = {**{k: json_number(np.mean(v)) for k, v in values.items()},
                  **{f"{k}_sd": json_number(np.std(v)) for k, v in values.items()}}
    return out


def fit_structure(df, params, name, split, n_jobs=1):
    """Candidate ``name`` fitted to the structure metrics on the training runs, calibrated, and scored.

    Parameters
    ----------
    df : pandas.DataFrame
        The runs, with ``packing_fraction`` and ``coverage`` (or the structure metrics), finite.
    params : dict
        The ``surrogate:`` section (the candidate's settings, ``cv_folds``, ``cv_repeats``,
        ``split_seed``, ``random_state``, ``confidence``).
    name : str
        The candidate chosen for the four metrics.
    split : dict
        ``{"train": rows, "test": rows}``: the paper-style split of ``scores.json``.
    n_jobs : int
        Folds fitted at once.

    Returns
    -------
    model : analysis.surrogate.intervals.CalibratedSurrogate
        Of the structure metrics (no products), fitted on the training runs.
    record : dict
        JSON-ready, for scores.json's ``structure``: ``metrics`` (symbol, unit, ``from``), ``model``,
        ``n_train``, ``fitted_on``, ``train`` and ``test`` scores (R, R^2, MAPE per metric),
        ``cv`` (``kfold``: :func:`kfold_scores`), ``cv_settings``, ``intervals`` (the calibration's
        summary) and ``convergence_warnings``.
    """
    df = with_structure_metrics(df)
    metrics = list(STRUCTURE_METRICS)
    X, Y = inputs_of(df), structure_targets(df)
    train, test = (np.asarray(split[k], int) for k in ("train", "test"))
    held_out, cv_warnings = kfold_predictions(df, params, name, n_jobs)
    with convergence_messages() as messages:
        fitted = make_candidate(name, params).fit(X[train], Y[train])
    rho, source = relative_noise(df, random_state=int(params["random_state"]), metrics=metrics, products={},
                                 shares=SHARES)
    model = calibrated_from_predictions(fitted, held_out, df, rho, params["confidence"], source, metrics, {},
                                        SHARES)
    record = {"metrics": {m: {"symbol": s, "unit": u, "from": DERIVED_FROM[m]}
                          for m, (s, u) in STRUCTURE_METRICS.items()},
              "model": name, "n_train": len(train),
              "fitted_on": "the training points of the paper-style split, the model choice's candidate and "
                           "settings, fitted to these metrics alone (the four metrics' model is not changed)",
              "train": regression_scores(Y[train], fitted.predict(X[train]), metrics),
              "test": regression_scores(Y[test], fitted.predict(X[test]), metrics),
              "cv": {"kfold": kfold_scores(df, held_out)},
              "cv_settings": {"folds": int(params["cv_folds"]), "repeats": int(params["cv_repeats"]),
                              "seeds": f"split_seed + repeat ({int(params['split_seed'])}...)",
                              "grouped_by": "(U, omega) point", "as": "model_choice.md's kfold scheme"},
              "intervals": model.summary(),
              "convergence_warnings": len(messages) + cv_warnings}
    return model, record


def stack_structure(model, df, params, name, split, n_jobs=1):
    """The calibrated model of the four metrics with the structure metrics' model stacked beside it.

    Returns
    -------
    model : CalibratedStack or the given model
        The given one, unchanged, when the dataset cannot give the structure metrics
        (:func:`analysis.metrics.dataset.structure_problem`).
    record : dict
        :func:`fit_structure`'s record, or ``{"skipped": why}``.
    """
    df = with_structure_metrics(df)
    problem = structure_problem(df)
    if problem:
        return model, {"skipped": problem}
    structure, record = fit_structure(df, params, name, split, n_jobs)
    return CalibratedStack([model, structure]), record


def format_structure(record):
    """One log line: the structure metrics' test R and k-fold R^2, or why they were not fitted."""
    if "skipped" in record:
        return f"layer-structure metrics not fitted: {record['skipped']}"
    parts = [f"{s} test R {_num(record['test'][m]['R'])}, k-fold R^2 {_num(record['cv']['kfold'][m]['R2'])}"
             for m, (s, _) in STRUCTURE_METRICS.items()]
    return f"layer-structure metrics ({record['model']}, fitted on their own): " + "; ".join(parts)


def _num(x):
    return "n/a" if x is None else f"{x:.3f}"
