"""Candidate surrogates with a predictive standard deviation, and their choice by cross-validation.

The paper fits one network on one 35/10 split.  Here three kinds of model are
scored on the same runs, by repeated k-fold and leave-one-point-out
cross-validation grouped by (U, omega) point (replicates of a point are never
split), and the best is the one the maps, the grid and the recommendation use:

``mlp``
    The paper's Table 2 network (:func:`analysis.surrogate.network.make_surrogate`),
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
the four metrics of :data:`analysis.surrogate.data.METRICS` in their units;
``predict(X, return_std=True)`` returns ``(mean, std)``, both (n, 4).
"""
from __future__ import annotations

import time

import numpy as np
import pandas as pd
from joblib import Parallel, delayed

from analysis.io import atomic_path
from analysis.metrics.dataset import METRICS, point_groups
from analysis.surrogate.candidates import CANDIDATES, GPSurrogate, make_candidate
from analysis.surrogate.data import _check_dataset, inputs_of, point_folds, targets_of
from analysis.surrogate.network import _convergence_messages
from analysis.surrogate.scores import _num, regression_scores


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
    p = params
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

    ``ceiling`` is :func:`analysis.metrics.noise_floor.accuracy_ceiling` (or None).
    """
    symbols = [s for s, _ in METRICS.values()]
    title = "# Surrogate model choice by cross-validation" + (f" ({level})" if level else "")
    head = ["model", "scheme", f"R: {' / '.join(symbols)}", f"R^2: {' / '.join(symbols)}",
            f"MAPE %: {' / '.join(symbols)}", "mean R^2", "fits", "s"]
    lines = [title, "",
             f"Chosen: **{chosen}** ({CANDIDATES.get(chosen, chosen)}): the highest repeated "
             "k-fold R^2 averaged over the four metrics. Folds are (U, omega) points: the "
             "replicates of a point are left out together.", ""]

    def joined(values, f):
        return " / ".join("n/a" if not np.isfinite(v) else format(v, f) for v in values)

    rows = []
    for (model, scheme), block in table.groupby(["model", "scheme"], sort=False):
        block = block.set_index("metric").loc[list(METRICS)]
        rows.append([f"**{model}**" if model == chosen else model, scheme, joined(block["R"], ".3f"),
                     joined(block["R2"], ".3f"), joined(block["MAPE_pct"], ".1f"), f"{block['R2'].mean():.3f}",
                     str(int(block["n_splits"].iloc[0])), f"{block['fit_s'].iloc[0]:.1f}"])
    if ceiling:
        c = [ceiling[m] for m in METRICS]
        rows.append(["*noise ceiling*", "replicates", joined([x["R_max"] for x in c], ".3f"),
                     joined([x["R2_max"] for x in c], ".3f"), joined([x["MAPE_floor_pct"] for x in c], ".1f"),
                     f"{np.mean([x['R2_max'] for x in c]):.3f}", "", ""])
    lines.append(pd.DataFrame(rows, columns=head).to_markdown(index=False, colalign=["left"] * 5 + ["right"] * 3))
    if ceiling:
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
        ``scores["split"]`` of :func:`analysis.surrogate.network.fit_surrogate` (row positions).
    table : pandas.DataFrame
        The cross-validation table (:func:`cross_validate_models` or model_choice.csv).

    Returns
    -------
    dict
        ``info`` plus ``fitted_on``, ``train`` and ``test`` scores
        (:func:`analysis.surrogate.scores.regression_scores`), ``cv`` (per scheme and
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
