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
wrong scale) decides only when it is clear: every candidate within one
standard error of the best score (:func:`fold_scores`) is tied with it, and a
tie goes to the first listed smooth model (:data:`SMOOTH`: the paper's network,
then the GP, in ``surrogate.models`` order); the trees, whose surfaces are
piecewise flat, are chosen only when better by more than that margin.

Leave-one-point-out only reports, the choice is the k-fold's: with ``cv_loo: ties``
(:func:`loo_candidates`) it is run for the candidates tied within the margin when
there are two or more, and skipped when the k-fold scores decide alone.  The
network's leave-one-point-out fits are warm-started
(:func:`analysis.surrogate.candidates.refit_warm`) from the first k-fold
repeat's fold model that held the same point out, so no fit starts from
weights that saw its held-out point.

Every model takes X = (U [mm/s], omega [rad/s]) of shape (n, 2) and returns
the four metrics of :data:`analysis.surrogate.data.METRICS` in their units;
``predict(X, return_std=True)`` returns ``(mean, std)``, both (n, 4).
"""
from __future__ import annotations

import time

import numpy as np
import pandas as pd
from joblib import Parallel, delayed
from scipy.stats import norm

from analysis.columns import METRICS, input_columns
from analysis.io import atomic_path
from analysis.metrics.dataset import point_groups
from analysis.surrogate.candidates import CANDIDATES, GPSurrogate, make_candidate, refit_warm
from analysis.surrogate.data import check_dataset, inputs_of, point_folds, targets_of
from analysis.surrogate.intervals import (
    calibrate,
    calibrated_from_predictions,
    check_confidence,
    conformal_quantile,
    interval_score,
    relative_noise,
    with_products,
)
from analysis.surrogate.network import convergence_messages
from analysis.surrogate.scores import json_number, regression_scores

#: Candidates whose surfaces are smooth, in the order a tie prefers them (config order decides among them).
SMOOTH = ("mlp", "gp")

#: ``surrogate.cv_loo`` value: leave-one-point-out only for the candidates the k-fold scores leave tied
#: (:func:`loo_candidates`).
LOO_TIES = "ties"


def _fold(name, p, X, Y, train, test, start=None, keep=False):
    """Fit a ``name`` candidate on one fold: fresh, or warm-started from the fitted ``start``.

    Returns (test rows, their predictions and std, ConvergenceWarnings, fit s, the model
    when ``keep`` else None).
    """
    t0 = time.perf_counter()
    with convergence_messages() as messages:
        if start is None:
            model = make_candidate(name, p).fit(X[train], Y[train])
        else:
            model = refit_warm(start, X[train], Y[train])
    mean, std = model.predict(X[test], return_std=True)
    return test, mean, std, len(messages), time.perf_counter() - t0, model if keep else None


def fold_scores(Y, pred, folds):
    """Mean R^2 over the metrics of each fold's held-out runs, on the scale of all runs.

    Pooled over the runs, the mean R^2 over the metrics is ``1 - mean_i l_i`` with
    ``l_i = mean_m (y_im - yhat_im)^2 / var_m`` (``var_m`` over all runs), so a fold's
    score ``1 - mean_{i in fold} l_i`` averages to the pooled score over equal folds and
    stays finite on a fold whose own spread is small.

    Returns
    -------
    numpy.ndarray, shape (len(folds),)
    """
    var = Y.var(axis=0)
    loss = (((Y - pred) ** 2) / np.where(var > 0, var, 1.0)).mean(axis=1)
    return np.array([1 - loss[test].mean() for _, test in folds])


def interval_scores(Y, preds, stds, repeats, rho, confidence):
    """Coverage, width and interval score of calibrated and of raw intervals, cross-fitted.

    Each fold's held-out runs get the interval calibrated (:func:`analysis.surrogate.intervals.calibrate`)
    on the held-out predictions of the *other* runs, pooled over all repeats, so no run
    calibrates its own interval.

    Parameters
    ----------
    Y : numpy.ndarray, shape (n, 4)
        The runs' metrics.
    preds, stds : list of numpy.ndarray, shape (n, 4)
        Held-out predictions and the models' std, one per repeat.
    repeats : list of list of (train, test)
        The folds of each repeat.
    rho : numpy.ndarray, shape (6,)
        Relative run-to-run noise (:func:`analysis.surrogate.intervals.relative_noise`).
    confidence : float
        Coverage level of the intervals.

    Returns
    -------
    dict of numpy.ndarray, shape (4,)
        Per metric: ``coverage_pct`` (held-out runs inside their calibrated single-run
        interval), ``width_pct`` and ``interval_score_pct`` (its mean width and interval
        score, in % of the mean |metric|), ``std_coverage_pct`` (runs inside
        mean +- z std of the model's own std, z the normal quantile of the level: what
        the maps showed before calibration).
    """
    k = Y.shape[1]
    y = with_products(Y)
    n = len(Y)
    P = np.stack([with_products(m, s)[0] for m, s in zip(preds, stds)])   # (R, n, 6)
    S = np.stack([with_products(m, s)[1] for m, s in zip(preds, stds)])
    inside = np.zeros((len(preds), n, k), bool)
    width = np.zeros((len(preds), n, k))
    score = np.zeros((len(preds), n, k))
    for r, folds in enumerate(repeats):
        for _, test in folds:
            keep = np.ones(n, bool)
            keep[test] = False
            c, scores = calibrate(np.tile(y[keep], (len(preds), 1)), P[:, keep].reshape(-1, 6),
                                  S[:, keep].reshape(-1, 6), rho)
            q = conformal_quantile(scores, confidence, keep.sum())
            half = q * np.hypot(c * S[r, test], rho * P[r, test])
            lo, hi = P[r, test] - half, P[r, test] + half
            inside[r, test] = ((y[test] >= lo) & (y[test] <= hi))[:, :k]
            width[r, test] = (hi - lo)[:, :k]
            score[r, test] = interval_score(y[test], lo, hi, confidence)[:, :k]
    z = norm.ppf(0.5 + confidence / 2)
    raw = np.abs(np.stack(preds) - Y) <= z * np.stack(stds)
    scale = np.abs(Y).mean(axis=0) / 100
    return {"coverage_pct": 100 * inside.mean(axis=(0, 1)), "width_pct": width.mean(axis=(0, 1)) / scale,
            "interval_score_pct": score.mean(axis=(0, 1)) / scale,
            "std_coverage_pct": 100 * raw.mean(axis=(0, 1))}


def loo_setting(value):
    """``surrogate.cv_loo`` checked: ``True`` (every candidate), ``False`` (none) or :data:`LOO_TIES`."""
    if value is True or value is False or value == LOO_TIES:
        return value
    raise ValueError(f"surrogate.cv_loo must be true, false or {LOO_TIES!r}, not {value!r}")


def loo_candidates(kfold_table, params):
    """The candidates to score by leave-one-point-out, given the k-fold table and ``surrogate.cv_loo``.

    ``True``: every candidate; ``False``: none; :data:`LOO_TIES`: the candidates the k-fold
    scores cannot separate, i.e. those tied with the best within its standard error
    (:func:`decide`'s ``tied``), when there are at least two; none when the best is clear of
    every other eligible candidate by more than the margin: the k-fold scores then decide
    alone.  Leave-one-point-out never changes the choice; in a tie it is a second look, with
    the lower variance of fits on all points but one, at what the tie-break (the first smooth
    model) gives up against the best score.
    """
    setting = loo_setting(params["cv_loo"])
    models = list(params["models"])
    if setting != LOO_TIES:
        return models if setting else []
    least = min_coverage_pct(params) if "coverage_tolerance_pct" in params else None
    tied = decide(kfold_table, models, least)["tied"]
    return [m for m in models if m in tied] if len(tied) > 1 else []


def cross_validate_models(df, params, log=None, n_jobs=1, return_predictions=False, warm_loo=True):
    """Score every candidate of ``params["models"]`` by grouped cross-validation.

    Schemes: ``kfold``: ``cv_folds``-fold over the (U, omega) points, repeated
    ``cv_repeats`` times with shuffle seeds ``split_seed + r``; each repeat's
    pooled out-of-fold predictions are scored (:func:`regression_scores`) and
    the scores averaged over repeats (``*_sd``: their spread).  ``loo``, for the
    candidates of :func:`loo_candidates` (``cv_loo``: ``true`` every one, ``ties`` those
    the k-fold scores leave tied, ``false`` none): leave one (U, omega) point out, all its
    replicates together, pooled.  Each scheme also scores the candidate's intervals at
    ``confidence`` (:func:`interval_scores`): calibrated, cross-fitted, and its own std.

    The folds are fitted in two batches of ``n_jobs`` processes: every k-fold fit (and, with
    ``cv_loo: true``, the leave-one-point-out fits that start from nothing), then the
    leave-one-point-out fits that depend on them (the tied candidates', the network's
    warm-started ones).

    Parameters
    ----------
    df : pandas.DataFrame
        The runs (speeds and metrics, finite).
    params : dict
        The ``surrogate:`` section (``models``, ``cv_folds``, ``cv_repeats``,
        ``cv_loo``, ``split_seed``, ``confidence`` and the models' own keys;
        ``coverage_tolerance_pct`` for the tie of ``cv_loo: ties``).
    log : callable, optional
        Called with a progress line per model and scheme.
    n_jobs : int
        Folds fitted at once (joblib processes); the scores do not depend on it.
    return_predictions : bool
        Also return the held-out predictions.
    warm_loo : bool
        Warm-start the network's leave-one-point-out fits from the first repeat's k-fold
        models (:func:`analysis.surrogate.candidates.refit_warm`); False: fresh fits, as the
        k-fold's (benchmarks/bench_model_choice.py compares the two).

    Returns
    -------
    table : pandas.DataFrame
        One row per (model, scheme, metric), each model's k-fold rows before its
        leave-one-point-out rows: ``model``, ``scheme``,
        ``metric``, ``symbol``, ``R``, ``R2``, ``MAPE_pct``, ``R_sd``,
        ``R2_sd``, ``MAPE_pct_sd``, the columns of :func:`interval_scores`,
        ``mean_R2_se`` (the standard error of the model's mean R^2 over the metrics: the
        standard deviation of its per-fold scores (:func:`fold_scores`) over every repeat and
        fold, over the square root of the folds of one repeat, as the runs are split that
        many ways; repeats reshuffle the same runs), ``n_splits`` (folds x repeats, or points),
        ``fit_s`` (the scheme's fits, summed over its folds), ``convergence_warnings``.
    predictions : pandas.DataFrame
        Only with ``return_predictions``: one row per (model, scheme, repeat, run):
        ``row`` (position in df), the inputs (U_mm_s, omega_rad_s, extra axes), the held-out prediction of each
        metric and its ``<metric>_std`` (the fold model's std of its mean).
    """
    p = params
    check_dataset(df)
    setting = loo_setting(p["cv_loo"])
    X, Y = inputs_of(df), targets_of(df)
    confidence = check_confidence(p["confidence"])
    rho, _ = relative_noise(df, random_state=int(p["random_state"]))
    n_points = int(point_groups(df).max()) + 1
    models = list(p["models"])
    schemes = {"kfold": [point_folds(df, p["cv_folds"], int(p["split_seed"]) + r)
                         for r in range(int(p["cv_repeats"]))]}
    if setting is not False:
        schemes["loo"] = [point_folds(df, n_points, 0)]
    warm = warm_loo and setting is not False and "mlp" in models   # the network's LOO from its k-fold models

    def tasks(name, scheme):
        return [(name, scheme, r, i, train, test) for r, splits in enumerate(schemes[scheme])
                for i, (train, test) in enumerate(splits)]

    fits, start = {}, {}            # start: point row -> the repeat-0 k-fold network that held it out

    def fit_all(batch):
        done = Parallel(n_jobs=n_jobs)(
            delayed(_fold)(name, p, X, Y, train, test,
                           start=start[int(test[0])] if warm and name == "mlp" and scheme == "loo" else None,
                           keep=warm and name == "mlp" and scheme == "kfold" and r == 0)
            for name, scheme, r, _, train, test in batch)
        fits.update(zip([t[:4] for t in batch], done))
        for fold in done:
            if fold[-1] is not None:
                start.update(dict.fromkeys(fold[0].tolist(), fold[-1]))

    rows, held_out = {}, {}

    def score(name, scheme):
        repeats = schemes[scheme]
        preds = {r: np.full_like(Y, np.nan) for r in range(len(repeats))}
        stds = {r: np.full_like(Y, np.nan) for r in range(len(repeats))}
        warned, elapsed = 0, 0.0
        for t in tasks(name, scheme):
            test, fold_pred, fold_std, n_warn, fit_s, _ = fits[t[:4]]
            preds[t[2]][test] = fold_pred
            stds[t[2]][test] = fold_std
            warned += n_warn
            elapsed += fit_s
        scores = [regression_scores(Y, pred) for pred in preds.values()]
        per_fold = np.concatenate([fold_scores(Y, preds[r], splits) for r, splits in enumerate(repeats)])
        se = float(per_fold.std(ddof=1) / np.sqrt(len(repeats[0]))) if len(per_fold) > 1 else 0.0
        covered = interval_scores(Y, list(preds.values()), list(stds.values()), repeats, rho, confidence)
        block = []
        for j, (m, (symbol, _)) in enumerate(METRICS.items()):
            values = {k: np.array([np.nan if s[m][k] is None else s[m][k] for s in scores])
                      for k in ("R", "R2", "MAPE_pct")}
            block.append({"model": name, "scheme": scheme, "metric": m, "symbol": symbol,
                          **{k: float(np.mean(v)) for k, v in values.items()},
                          **{f"{k}_sd": float(np.std(v)) for k, v in values.items()},
                          **{k: float(v[j]) for k, v in covered.items()},
                          "mean_R2_se": se, "n_splits": sum(len(s) for s in repeats),
                          "fit_s": round(elapsed, 2), "convergence_warnings": warned})
        rows[name, scheme] = block
        frames = []
        for r in preds:
            frame = pd.DataFrame(np.c_[preds[r], stds[r]], columns=[*METRICS, *(f"{m}_std" for m in METRICS)])
            frame.insert(0, "row", np.arange(len(df)))
            frame.insert(0, "repeat", r)
            frame.insert(0, "scheme", scheme)
            frame.insert(0, "model", name)
            for j, c in enumerate(input_columns(df)):
                frame.insert(4 + j, c, X[:, j])
            frames.append(frame)
        held_out[name, scheme] = frames
        if log:
            log(f"{name:>5} {scheme:>5}: mean R^2 {np.mean([b['R2'] for b in block]):.3f}, "
                f"{100 * confidence:g} % interval covers {np.mean([b['coverage_pct'] for b in block]):.1f} % "
                f"({sum(len(s) for s in repeats)} fits, {elapsed:.1f} s)")

    # every k-fold fit first, with the leave-one-point-out fits known to be wanted that start from nothing
    first = [t for name in models for t in tasks(name, "kfold")]
    if setting is True:
        first += [t for name in models if not (warm and name == "mlp") for t in tasks(name, "loo")]
    fit_all(first)
    for name in models:
        score(name, "kfold")
    loo = loo_candidates(pd.DataFrame([r for name in models for r in rows[name, "kfold"]]), p)
    fit_all([t for name in loo for t in tasks(name, "loo") if t[:4] not in fits])
    for name in loo:
        score(name, "loo")
    if log and setting == LOO_TIES and not loo:
        log("  leave-one-point-out skipped: the k-fold scores decide alone (no other candidate within the margin)")
    keys = [(name, scheme) for name in models for scheme in ("kfold", "loo") if (name, scheme) in rows]
    table = pd.DataFrame([r for k in keys for r in rows[k]])
    if return_predictions:
        return table, pd.concat([f for k in keys for f in held_out[k]], ignore_index=True)
    return table


def min_coverage_pct(params):
    """The least k-fold coverage (%) a candidate's intervals may have: ``100 confidence -
    coverage_tolerance_pct`` of the ``surrogate:`` section."""
    return 100 * check_confidence(params["confidence"]) - float(params["coverage_tolerance_pct"])


def under_covering(table, min_coverage):
    """Models whose calibrated k-fold intervals cover less than ``min_coverage`` (%) of the
    held-out runs for at least one metric, as {model: [symbols of those metrics]}."""
    if min_coverage is None or "coverage_pct" not in table:
        return {}
    kfold = table[table["scheme"] == "kfold"]
    low = kfold[kfold["coverage_pct"] < min_coverage]
    return {m: block["symbol"].tolist() for m, block in low.groupby("model", sort=False)}


def decide(table, order=None, min_coverage=None):
    """The choice of :func:`choose_model` with its reasons.

    Returns
    -------
    dict
        ``chosen``; ``best`` (highest mean k-fold R^2 among the eligible); ``margin`` (its
        standard error, ``mean_R2_se``; 0 for a table without it); ``tied`` (the eligible
        within the margin of the best, config order); ``ranking`` (mean k-fold R^2 per model,
        best first); ``se`` (per model); ``under_covering`` (:func:`under_covering`).
    """
    kfold = table[table["scheme"] == "kfold"]
    mean_r2 = kfold.groupby("model", sort=False)["R2"].mean()
    se = (kfold.groupby("model", sort=False)["mean_R2_se"].first() if "mean_R2_se" in kfold
          else pd.Series(0.0, index=mean_r2.index)).fillna(0.0)
    order = list(order or mean_r2.index)
    rank = pd.Series({m: mean_r2[m] for m in order if m in mean_r2.index}).fillna(-np.inf)
    low = under_covering(table, min_coverage)
    eligible = [m for m in rank.index if m not in low] or list(rank.index)
    best = max(eligible, key=lambda m: (rank[m], -order.index(m)))
    margin = float(se.get(best, 0.0))
    tied = [m for m in eligible if rank[best] - rank[m] <= margin]
    smooth = [m for m in tied if m in SMOOTH]
    return {"chosen": smooth[0] if smooth else best, "best": best, "margin": margin, "tied": tied,
            "ranking": rank.sort_values(ascending=False, kind="stable"), "se": se, "under_covering": low}


def choose_model(table, order=None, min_coverage=None):
    """The candidate chosen by the k-fold scores, robust to their noise.

    Among the candidates whose intervals do not under-cover, the one with the highest mean
    k-fold R^2 over the metrics is the best; every candidate whose score is within the
    best's standard error (``mean_R2_se``) is tied with it, and a tie goes to the first
    smooth model (:data:`SMOOTH`) in ``order``; the best is chosen when no smooth model is
    tied with it.

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`cross_validate_models`' table.
    order : list of str, optional
        Candidates in config order (ties go to the first smooth one, then to the first).
    min_coverage : float, optional
        Least k-fold coverage (%) of the calibrated intervals, for every metric
        (:func:`min_coverage_pct`); a candidate below it is passed over unless all are.
        None: R^2 alone.

    Returns
    -------
    name : str
    ranking : pandas.Series
        Mean k-fold R^2 per model, best first.
    """
    d = decide(table, order, min_coverage)
    return d["chosen"], d["ranking"]


def choice_rule_text(d):
    """One sentence: the best score, its standard error, the tie and the chosen model (:func:`decide`)."""
    best, chosen, margin = d["best"], d["chosen"], d["margin"]
    text = (f"best mean k-fold R^2: {best} {d['ranking'][best]:.4f} +- {margin:.4f} (its standard error: "
            "the spread of its per-fold scores over every repeat and fold, over sqrt(folds)); ")
    others = [m for m in d["tied"] if m != best]
    if others:
        text += ("within that margin, tied with it: " + ", ".join(f"{m} {d['ranking'][m]:.4f}" for m in others)
                 + "; ")
    if chosen != best:
        return text + (f"the tie goes to the first listed smooth model, **{chosen}** "
                       f"({d['ranking'][best] - d['ranking'][chosen]:.4f} below the best, less than the margin)")
    if best not in SMOOTH:
        return text + f"no smooth model within the margin: **{best}** is clearly better and is chosen"
    return text + f"**{best}** is chosen"


def loo_text(table, d, setting):
    """One sentence: which candidates have leave-one-point-out scores and why (``setting``:
    ``surrogate.cv_loo``; ``d``: :func:`decide` on ``table``)."""
    setting = loo_setting(setting)
    done = [m for m in dict.fromkeys(table["model"]) if ((table["model"] == m) & (table["scheme"] == "loo")).any()]
    if setting is False:
        return "Leave-one-point-out: off (`surrogate.cv_loo: false`)."
    if setting is True:
        return ("Leave-one-point-out: every candidate (`surrogate.cv_loo: true`); it reports, the k-fold "
                "scores decide.")
    if done:
        return (f"Leave-one-point-out only for the candidates tied within the margin ({', '.join(done)}; "
                f"`surrogate.cv_loo: {LOO_TIES}`): a second look at the tie with fits on all points but one; "
                "it reports, the k-fold scores decide.")
    return (f"Leave-one-point-out skipped (`surrogate.cv_loo: {LOO_TIES}`): no other candidate is within the "
            f"margin of {d['best']}, so the k-fold scores decide alone.")


def model_choice_markdown(table, chosen, ceiling=None, level=None, confidence=None, min_coverage=None,
                          cv_loo=None):
    """The cross-validation table as Markdown, the chosen model in bold, the noise ceiling beside it.

    ``ceiling`` is :func:`analysis.metrics.noise_floor.accuracy_ceiling` (or None);
    ``confidence`` the intervals' level and ``min_coverage`` (%) the choice's least
    coverage (:func:`choose_model`), for the intervals' table and the flags; ``cv_loo``
    (``surrogate.cv_loo``, optional) for a sentence on the leave-one-point-out (:func:`loo_text`).
    """
    symbols = [s for s, _ in METRICS.values()]
    title = "# Surrogate model choice by cross-validation" + (f" ({level})" if level else "")
    head = ["model", "scheme", f"R: {' / '.join(symbols)}", f"R^2: {' / '.join(symbols)}",
            f"MAPE %: {' / '.join(symbols)}", "mean R^2 +- se", "fits", "s"]
    low = under_covering(table, min_coverage)
    rule = "the highest repeated k-fold R^2 averaged over the four metrics"
    if min_coverage is not None:
        rule += (f" among the candidates whose calibrated {100 * confidence:g} % intervals cover at least "
                 f"{min_coverage:g} % of the held-out runs of every metric (k-fold)")
        if chosen in low:
            rule += "; **every candidate under-covers**, so the best R^2 is taken regardless"
    rule += ("; a candidate within one standard error of the best score is tied with it, and a tie goes to the "
             "first listed smooth model (mlp, then gp, in config order): the trees only when clearly better")
    lines = [title, "",
             f"Chosen: **{chosen}** ({CANDIDATES.get(chosen, chosen)}): {rule}. Folds are points "
             "(U, omega and any swept axis): the replicates of a point are left out together.", ""]
    if "mean_R2_se" in table:
        d = decide(table, list(dict.fromkeys(table["model"])), min_coverage)
        lines += [f"Margin: {choice_rule_text(d)}.", ""]
        if cv_loo is not None:
            lines += [loo_text(table, d, cv_loo), ""]

    def joined(values, f):
        return " / ".join("n/a" if not np.isfinite(v) else format(v, f) for v in values)

    def bold(model):
        return f"**{model}**" if model == chosen else model

    rows, intervals = [], []
    for (model, scheme), block in table.groupby(["model", "scheme"], sort=False):
        block = block.set_index("metric").loc[list(METRICS)]
        rows.append([bold(model), scheme, joined(block["R"], ".3f"),
                     joined(block["R2"], ".3f"), joined(block["MAPE_pct"], ".1f"),
                     f"{block['R2'].mean():.4f}" + (f" +- {block['mean_R2_se'].iloc[0]:.4f}"
                                                    if "mean_R2_se" in block else ""),
                     str(int(block["n_splits"].iloc[0])), f"{block['fit_s'].iloc[0]:.1f}"])
        if "coverage_pct" in block:
            flag = ("under-covers " + ", ".join(low[model])) if scheme == "kfold" and model in low else ""
            intervals.append([bold(model), scheme, joined(block["coverage_pct"], ".0f"),
                              f"{block['coverage_pct'].mean():.1f}", joined(block["width_pct"], ".1f"),
                              joined(block["interval_score_pct"], ".1f"),
                              f"{block['interval_score_pct'].mean():.1f}",
                              joined(block["std_coverage_pct"], ".0f"), flag])
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
    if intervals and confidence is not None:
        level_pct = f"{100 * confidence:g} %"
        ihead = ["model", "scheme", f"covers %: {' / '.join(symbols)}", "mean covers %",
                 f"width %: {' / '.join(symbols)}", f"interval score %: {' / '.join(symbols)}",
                 "mean interval score %", f"own std covers %: {' / '.join(symbols)}", "flag"]
        lines += ["", f"## Intervals: {level_pct} single-run prediction intervals on the held-out runs", "",
                  pd.DataFrame(intervals, columns=ihead).to_markdown(
                      index=False, colalign=["left", "left", "left", "right", "left", "left", "right", "left", "left"]),
                  "", f"*covers*: share of held-out runs inside their calibrated {level_pct} single-run "
                  "interval (grouped cross-conformal, analysis.surrogate.intervals; each fold's interval "
                  "calibrated on the other runs' held-out residuals); *width* and *interval score* "
                  "(Gneiting & Raftery: width + 2/alpha x each miss; lower is better) in % of the "
                  f"mean metric; *own std covers*: runs inside mean +- {norm.ppf(0.5 + confidence / 2):.3g} x "
                  "the model's own predictive std, uncalibrated. *n/a* width: "
                  "too few held-out runs for a finite interval at this level (at least confidence/(1 - "
                  "confidence) are needed)."
                  + ("" if min_coverage is None else
                     f" A candidate whose calibrated k-fold coverage is below {min_coverage:g} % for a "
                     "metric is flagged and not chosen while another is not.")]
    return "\n".join(lines) + "\n"


def write_model_choice(table, chosen, csv_path, md_path, ceiling=None, level=None, confidence=None,
                       min_coverage=None, predictions=None, predictions_path=None, cv_loo=None):
    """Write the cross-validation table as CSV (with a ``chosen`` column) and Markdown, atomically;
    with ``predictions`` also the held-out predictions as CSV (``predictions_path``)."""
    with atomic_path(csv_path) as tmp:
        table.assign(chosen=table["model"] == chosen).to_csv(tmp, index=False)
    with atomic_path(md_path) as tmp:
        tmp.write_text(model_choice_markdown(table, chosen, ceiling, level, confidence, min_coverage, cv_loo))
    if predictions is not None:
        with atomic_path(predictions_path) as tmp:
            predictions.to_csv(tmp, index=False)


def read_choice(csv_path):
    """The chosen model's name from a model_choice.csv written by :func:`write_model_choice`."""
    table = pd.read_csv(csv_path)
    chosen = table.loc[table["chosen"].astype(bool), "model"].unique()
    if len(chosen) != 1:
        raise ValueError(f"{csv_path} names {len(chosen)} chosen models, expected 1")
    return str(chosen[0]), table


def fit_chosen(df, params, name, train_idx=None, n_jobs=1):
    """Fit candidate ``name`` on the runs ``train_idx`` (default all) of ``df``; ``n_jobs``: the
    network ensemble's members fitted at once (the fit does not depend on it).

    Returns
    -------
    model : fitted estimator with ``predict(X, return_std=True)``
    info : dict
        JSON-ready: ``name``, ``description``, ``fit_time_s``, ``n_train``,
        and for the GP the fitted length scales (per input, its units) and noise std
        per metric.
    """
    X, Y = inputs_of(df), targets_of(df)
    rows = np.arange(len(df)) if train_idx is None else np.asarray(train_idx, int)
    model = make_candidate(name, params)
    if name == "mlp":
        model.set_params(n_jobs=n_jobs)
    t0 = time.perf_counter()
    with convergence_messages() as messages:
        model.fit(X[rows], Y[rows])
    info = {"name": name, "description": CANDIDATES[name], "n_train": int(len(rows)),
            "fit_time_s": round(time.perf_counter() - t0, 3),
            "convergence_warnings": messages}
    if isinstance(model, GPSurrogate):
        info["length_scale"] = {m: {c: float(v) for c, v in zip(input_columns(df), ls)}
                                for m, ls in zip(METRICS, model.length_scales_)}
        info["noise_std"] = {m: float(s) for m, s in zip(METRICS, model.noise_std_)}
    return model, info


def fit_calibrated(df, params, name, train_idx, predictions, n_jobs=1):
    """Candidate ``name`` fitted on the runs ``train_idx`` (:func:`fit_chosen`, ``n_jobs``), its intervals
    calibrated on its k-fold held-out predictions (``predictions``: cv_predictions.csv, every candidate's).

    Returns (the :class:`analysis.surrogate.intervals.CalibratedSurrogate`, :func:`fit_chosen`'s info,
    the noise's source as text).
    """
    model, info = fit_chosen(df, params, name, train_idx, n_jobs)
    held_out = predictions[(predictions["model"] == name) & (predictions["scheme"] == "kfold")]
    rho, source = relative_noise(df, random_state=int(params["random_state"]))
    return calibrated_from_predictions(model, held_out, df, rho, params["confidence"], source), info, source


def smooth_stand_in(df, params, name, train_idx, predictions):
    """For the process map's iso-lines: None when ``name`` is a smooth model (:data:`SMOOTH`), else the
    first smooth candidate of ``params["models"]`` (the GP if none is listed), fitted and calibrated as
    the chosen model is (:func:`fit_calibrated`), and its name."""
    if name in SMOOTH:
        return None, None
    smooth = next((m for m in params["models"] if m in SMOOTH), "gp")
    if smooth not in set(predictions["model"]):
        return None, None
    return fit_calibrated(df, params, smooth, train_idx, predictions)[0], smooth


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
    cv = {scheme: {row.metric: {"R": json_number(row.R), "R2": json_number(row.R2),
                                "MAPE_pct": json_number(row.MAPE_pct)} for row in block.itertuples()}
          for scheme, block in mine.groupby("scheme", sort=False)}
    _, ranking = choose_model(table)
    return {**info,
            "fitted_on": "the training points of the paper-style split (test points unseen)",
            "predictive_std": "std of the predicted mean (grid.csv *_std; with calibrated intervals "
                              "inflated by their std_inflation c): " + {
                "gp": "Gaussian-process posterior (noise term excluded)",
                "mlp": "spread of the ensemble's networks",
                "trees": "spread of the trees"}[info["name"]],
            "train": regression_scores(Y[train], model.predict(X[train])),
            "test": regression_scores(Y[test], model.predict(X[test])),
            "cv": cv,
            "ranking_mean_kfold_R2": {m: json_number(v) for m, v in ranking.items()}}
