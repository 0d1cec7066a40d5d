"""Adaptive Design of Simulations: fewer DEM runs for the same map.

The paper simulates a fixed 5 x 9 grid.  Here the design grows where the
surrogate is least sure:

1. a space-filling start: ``initial_points`` scrambled-Sobol (or Latin
   hypercube) points over the sweep grid's U and omega ranges
   (:func:`initial_design`), seeded;
2. each round, fit a Gaussian process per metric (:class:`~analysis.surrogate.candidates.GPSurrogate`)
   to every run so far and choose a batch of ``batch_size`` new points that
   maximise the expected squared prediction error (:func:`choose_batch`,
   after the MEPE criterion of Liu, Xu & Wang, 2017)::

       a(x) = w * e^2(nearest run to x) + (1 - w) * s^2(x)

   summed over the four standardised metrics: ``e`` is that run's
   leave-one-out error (large where the metrics vary faster than the GP's
   length scales expect, e.g. at the multi-layer jump), ``s^2`` the GP's
   posterior variance of the mean (large far from any run); ``w`` is
   ``error_weight``.  Within a batch the posterior variance is updated as if
   the chosen points had been run (kriging believer; the variance does not
   depend on the results) and a chosen point's own error counts as 0, so the
   batch spreads out;
3. run them (a Snakemake run that only simulates the new points:
   :class:`WorkflowEvaluator`), and repeat until the run budget
   ``max_runs`` is spent (the last batch is cut to fit it exactly) or the
   leave-one-out R^2, averaged over the metrics, reaches ``target_loo_r2``.

Points are snapped to a lattice (``resolution_U_mm_s``,
``resolution_omega_rad_s``) so that run folders keep clean names and a point
already simulated (by the grid or an earlier design) is reused.

Command line (the loop through the workflow)::

    python -m analysis.surrogate.adaptive --level default --name adaptive --cores 2 [--max-runs 15]

writes ``results/<level>/adaptive/<name>/``: ``design.csv`` (points, round,
acquisition), ``rounds.csv`` (runs and leave-one-out scores per round),
``dataset.csv`` (the design's runs), ``model.joblib`` (the final GP, usable by
``python -m analysis.surrogate.recommend --model``) and ``round_<k>.yaml`` (the points
config each round's Snakemake run used).  Units: U in mm/s, omega in rad/s,
metrics as the dataset.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from scipy.linalg import solve_triangular
from scipy.stats import qmc

from analysis.config import PROJECT_DIR, load_config, run_name, sweep_axes
from analysis.io import USER_ERRORS, atomic_path, error_line
from analysis.metrics.dataset import INPUTS, METRICS
from analysis.surrogate.candidates import GPSurrogate
from analysis.surrogate.data import inputs_of, targets_of
from analysis.surrogate.intervals import calibrated_from_predictions, relative_noise
from analysis.surrogate.persistence import save_surrogate
from analysis.surrogate.selection import cross_validate_models

ROOT = PROJECT_DIR


#: acquisition functions of :func:`choose_batch` (``adaptive.acquisition``)
ACQUISITIONS = ("mepe", "imse")


def sweep_bounds(config):
    """((U_min, U_max) mm/s, (omega_min, omega_max) rad/s) of the sweep grid in ``config``."""
    sweep = config["sweep"]
    return ((float(min(sweep["U_mm_s"])), float(max(sweep["U_mm_s"]))),
            (float(min(sweep["omega_rad_s"])), float(max(sweep["omega_rad_s"]))))


def _check_bounds(bounds):
    for (lo, hi), name in zip(bounds, ("U (mm/s)", "omega (rad/s)")):
        if not hi > lo:
            raise ValueError(f"the {name} range {lo:g}..{hi:g} is empty: the sweep needs at "
                             "least two values of each speed to span a design space")


def snap(points, bounds, resolution):
    """Round (n, 2) points to the lattice ``lo + k * resolution`` inside ``bounds``."""
    points = np.atleast_2d(np.asarray(points, float))
    lo = np.array([b[0] for b in bounds])
    hi = np.array([b[1] for b in bounds])
    res = np.asarray(resolution, float)
    k = np.round((np.clip(points, lo, hi) - lo) / res)
    k = np.minimum(k, np.floor((hi - lo) / res + 1e-9))
    return np.round(lo + k * res, 6)


def lattice(bounds, resolution):
    """Every lattice point of :func:`snap` in ``bounds``, shape (m, 2) (the candidates)."""
    axes = [np.round(lo + res * np.arange(int(np.floor((hi - lo) / res + 1e-9)) + 1), 6)
            for (lo, hi), res in zip(bounds, resolution)]
    U, omega = np.meshgrid(*axes, indexing="ij")
    return np.c_[U.ravel(), omega.ravel()]


def initial_design(n, bounds, resolution, method="sobol", seed=0):
    """``n`` distinct space-filling points over ``bounds``, snapped to the lattice.

    A scrambled Sobol sequence (``method="sobol"``; nested: the first k
    points of a longer design with the same seed are this design) or a Latin
    hypercube (``"lhs"``), seeded.  Points that coincide after snapping are
    dropped and later ones of the sequence used instead.

    Returns
    -------
    numpy.ndarray, shape (n, 2)
        U (mm/s), omega (rad/s).
    """
    _check_bounds(bounds)
    n = int(n)
    if n < 1:
        raise ValueError(f"initial design needs at least 1 point, got {n}")
    lo, hi = [b[0] for b in bounds], [b[1] for b in bounds]
    if method == "sobol":
        sampler = qmc.Sobol(2, scramble=True, seed=int(seed))
    elif method == "lhs":
        sampler = qmc.LatinHypercube(2, seed=int(seed))
    else:
        raise ValueError(f"unknown initial design {method!r}; choose sobol or lhs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # Sobol: n not a power of 2
        raw = sampler.random(8 * n)
    points = snap(qmc.scale(raw, lo, hi), bounds, resolution)
    _, first = np.unique(points, axis=0, return_index=True)
    unique = points[np.sort(first)]
    if len(unique) < n:
        raise ValueError(f"the lattice ({resolution[0]:g} mm/s x {resolution[1]:g} rad/s) is too "
                         f"coarse for {n} distinct points")
    return unique[:n]


def _keys(points):
    """Hashable, sortable keys of (n, 2) points (rounded to 1e-6): U + i omega."""
    P = np.round(np.atleast_2d(np.asarray(points, float)), 6)
    return P[:, 0] + 1j * P[:, 1]


def _scaled_nearest(gp, X_query, X_points):
    """Index of the nearest of ``X_points`` to each query, in standardised input units."""
    a, b = gp.x_scaler_.transform(X_query), gp.x_scaler_.transform(X_points)
    d2 = (a * a).sum(1)[:, None] - 2 * a @ b.T + (b * b).sum(1)[None, :]
    return np.argmin(d2, axis=1)


def _reference(bounds_scaled, n=21):
    """An n x n grid over the standardised design box: where the integrated variance is summed."""
    (a0, a1), (b0, b1) = bounds_scaled
    A, B = np.meshgrid(np.linspace(a0, a1, n), np.linspace(b0, b1, n), indexing="ij")
    return np.c_[A.ravel(), B.ravel()]


def _variance_reduction(gp, Xs_cand, Xs_train, Xs_ref, weight_ref):
    """Drop of the (weighted) mean posterior variance over ``Xs_ref`` if each candidate were run.

    For one metric with signal kernel k, noise variance s_n^2 and posterior
    covariance c(x, x') given the runs ``Xs_train``, running candidate x_c
    lowers the variance at x by ``c(x, x_c)^2 / (c(x_c, x_c) + s_n^2)``; this
    is averaged over the reference points (weights ``weight_ref``) and summed
    over the metrics (standardised units), shape (m,).  Hyperparameters are
    kept and the result does not depend on targets (kriging believer).
    """
    out = np.zeros(len(Xs_cand))
    w = weight_ref / weight_ref.sum()
    for gp_j in gp.gps_:
        signal, noise = gp_j.kernel_.k1, gp_j.kernel_.k2.noise_level
        L = np.linalg.cholesky(gp_j.kernel_(Xs_train) + 1e-10 * np.eye(len(Xs_train)))
        Vc = solve_triangular(L, signal(Xs_train, Xs_cand), lower=True)       # (n, m)
        Vr = solve_triangular(L, signal(Xs_train, Xs_ref), lower=True)        # (n, r)
        cov = signal(Xs_ref, Xs_cand) - Vr.T @ Vc                              # (r, m)
        var_c = np.clip(signal.diag(Xs_cand) - np.sum(Vc * Vc, axis=0), 0.0, None)
        out += (w @ (cov * cov)) / (var_c + noise)
    return out


def choose_batch(gp, X, candidates, batch_size, error_weight=0.5, exclude=None,
                 acquisition="mepe", bounds=None):
    """Choose ``batch_size`` new points by expected prediction error or integrated variance.

    Parameters
    ----------
    gp : analysis.surrogate.candidates.GPSurrogate
        Fitted on the runs X (all replicates).
    X : numpy.ndarray, shape (n, 2)
        Inputs of the runs it was fitted on (U mm/s, omega rad/s).
    candidates : numpy.ndarray, shape (m, 2)
        Where new points may go (a lattice, :func:`lattice`).
    batch_size : int
    error_weight : float
        w in [0, 1]: weight of the nearest run's leave-one-out error.
    exclude : numpy.ndarray, shape (k, 2), optional
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
    bounds : ((float, float), (float, float)), optional
        The design box for ``"imse"`` (default: the candidates' extent).

    Returns
    -------
    points : numpy.ndarray, shape (b, 2)
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
    taken = points if exclude is None else np.r_[points, np.atleast_2d(exclude)]
    keep = ~np.isin(_keys(candidates), _keys(taken))
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


def loo_r2(gp, Y):
    """Leave-one-out R^2 per metric of a GP fitted on Y (n, 4), from its closed-form residuals."""
    r = gp.loo_residuals()
    Y = np.asarray(Y, float)
    ss = ((Y - Y.mean(axis=0)) ** 2).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ss > 0, 1.0 - (r * r).sum(axis=0) / ss, np.nan)


@dataclass
class AdaptiveResult:
    """What :func:`run_adaptive` did.

    Attributes
    ----------
    design : pandas.DataFrame
        One row per point: ``U_mm_s``, ``omega_rad_s``, ``round`` (0: initial
        design), ``acquisition`` (NaN for the initial design).
    data : pandas.DataFrame
        Every run (rows returned by the evaluator).
    rounds : pandas.DataFrame
        One row per round: ``round``, ``n_points``, ``n_runs``,
        ``loo_R2_<metric>``, ``loo_R2_mean``, ``wall_s``.
    model : GPSurrogate
        The GP fitted on all runs.
    stop : str
        ``"budget"`` or ``"target"``.
    """
    design: pd.DataFrame
    data: pd.DataFrame
    rounds: pd.DataFrame
    model: GPSurrogate
    stop: str
    history: list = field(default_factory=list)


def check_settings(settings, replicates=1):
    """Raise ValueError naming the bad ``adaptive:`` value."""
    if settings.get("acquisition", "mepe") not in ACQUISITIONS:
        raise ValueError(f"adaptive.acquisition = {settings['acquisition']!r}: choose one of "
                         f"{ACQUISITIONS}")
    budget_points = int(settings["max_runs"]) // int(replicates)
    if int(settings["initial_points"]) > budget_points:
        raise ValueError(f"adaptive.initial_points = {settings['initial_points']} x "
                         f"{replicates} replicate(s) exceeds the run budget adaptive.max_runs = "
                         f"{settings['max_runs']}")
    if int(settings["initial_points"]) < 4:
        raise ValueError(f"adaptive.initial_points = {settings['initial_points']}: at least 4 "
                         "points are needed to fit the first surrogate")


def run_adaptive(evaluate, bounds, settings, *, replicates=1, exclude=None, gp_params=None,
                 on_round=None, log=print):
    """The adaptive loop: initial design, then batches by expected error until the budget.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(points)`` with points (k, 2) [mm/s, rad/s] returns a
        DataFrame of their runs: ``U_mm_s``, ``omega_rad_s`` and the four
        metrics, ``replicates`` rows per point.
    bounds : ((float, float), (float, float))
        U (mm/s) and omega (rad/s) ranges.
    settings : dict
        The ``adaptive:`` section of config.yaml.
    replicates : int
        Runs per point (counts against ``max_runs``).
    exclude : array (k, 2), optional
        Points never chosen (a held-out test set).
    gp_params : dict, optional
        Keyword arguments of :class:`~analysis.surrogate.candidates.GPSurrogate`.
    on_round : callable, optional
        ``on_round(round_index, data, gp)`` after each fit (e.g. to score
        against held-out runs).
    log : callable
        Receives one progress line per round.

    Returns
    -------
    AdaptiveResult
    """
    check_settings(settings, replicates)
    _check_bounds(bounds)
    resolution = (float(settings["resolution_U_mm_s"]), float(settings["resolution_omega_rad_s"]))
    budget = int(settings["max_runs"])
    target = settings.get("target_loo_r2")
    candidates = lattice(bounds, resolution)
    points = initial_design(settings["initial_points"], bounds, resolution,
                            settings["initial_design"], settings["seed"])
    if exclude is not None and len(exclude):
        clash = np.isin(_keys(points), _keys(exclude))
        if clash.any():
            raise ValueError(f"initial design points {points[clash].tolist()} are in the "
                             "excluded (held-out) set; change adaptive.seed")
    design = pd.DataFrame({"U_mm_s": points[:, 0], "omega_rad_s": points[:, 1],
                           "round": 0, "acquisition": np.nan})
    t0 = time.perf_counter()
    data = evaluate(points)
    rounds = []
    k = 0
    while True:
        gp = GPSurrogate(**(gp_params or {})).fit(inputs_of(data), targets_of(data))
        r2 = loo_r2(gp, targets_of(data))
        row = {"round": k, "n_points": len(design), "n_runs": len(data),
               **{f"loo_R2_{m}": float(v) for m, v in zip(METRICS, r2)},
               "loo_R2_mean": float(np.nanmean(r2)), "wall_s": round(time.perf_counter() - t0, 1)}
        rounds.append(row)
        if on_round:
            on_round(k, data, gp)
        new = design[design["round"] == k]
        log(f"round {k}: {len(new)} new point(s) "
            + ", ".join(f"({u:g}, {w:g})" for u, w in new[list(INPUTS)].to_numpy())
            + f"; {len(data)} runs in all; leave-one-out R^2 "
            + " / ".join(f"{v:.3f}" for v in r2) + f" (mean {row['loo_R2_mean']:.3f})")
        if target is not None and row["loo_R2_mean"] >= float(target):
            stop = "target"
            break
        room = (budget - len(data)) // int(replicates)
        if room <= 0:
            stop = "budget"
            break
        k += 1
        batch, acq = choose_batch(gp, inputs_of(data), candidates,
                                  min(int(settings["batch_size"]), room),
                                  float(settings["error_weight"]), exclude,
                                  settings.get("acquisition", "mepe"), bounds)
        design = pd.concat([design, pd.DataFrame({"U_mm_s": batch[:, 0], "omega_rad_s": batch[:, 1],
                                                  "round": k, "acquisition": acq})],
                           ignore_index=True)
        data = pd.concat([data, evaluate(batch)], ignore_index=True)
    log(f"stopped at round {k}: {'run budget' if stop == 'budget' else 'target accuracy'} "
        f"({len(data)} runs of {budget})")
    return AdaptiveResult(design, data, pd.DataFrame(rounds), gp, stop)


class WorkflowEvaluator:
    """Run design points through the Snakemake workflow; return their dataset rows.

    Each call writes ``<outdir>/round_<k>.yaml`` (``sweep.points_mm_s_rad_s``:
    every point so far), asks Snakemake for those runs' ``metrics.json`` (so
    only runs not yet done are simulated: folders are named by speed and
    replicate, and runs of the grid or of other designs are reused) and
    gathers the requested points' runs with :func:`analysis.metrics.dataset.build_dataset`
    (the workflow's own ``results/<level>/dataset.csv`` is left alone).

    Parameters
    ----------
    level : str
        Fidelity level.
    outdir : pathlib.Path
        Where the round configs and datasets go.
    workdir : pathlib.Path
        Snakemake's working directory (its ``results/`` holds the runs).
    cores : int
        ``snakemake --cores``.
    replicates : int
    configfile : pathlib.Path
        The base config (default: the repository's config.yaml).
    log : callable
    """

    def __init__(self, level, outdir, workdir=ROOT, cores=2, replicates=1, configfile=None,
                 log=print):
        self.level, self.outdir, self.workdir = level, Path(outdir), Path(workdir)
        self.cores, self.replicates, self.log = int(cores), int(replicates), log
        self.configfile = Path(configfile or ROOT / "config.yaml")
        self.points = []
        self.calls = 0

    def runs(self, points):
        """Run folder names of the points (all replicates)."""
        return [run_name(float(U), float(w), r) for U, w in np.atleast_2d(points)
                for r in range(self.replicates)]

    def __call__(self, points):
        from analysis.metrics.dataset import build_dataset
        points = np.atleast_2d(np.asarray(points, float))
        known = {tuple(p) for p in self.points}
        self.points += [tuple(p) for p in points if tuple(p) not in known]
        self.outdir.mkdir(parents=True, exist_ok=True)
        round_cfg = self.outdir / f"round_{self.calls}.yaml"
        n_test = max(1, min(2, len(self.points) - 3))
        with atomic_path(round_cfg) as tmp:
            tmp.write_text(yaml.safe_dump({
                "level": self.level,
                "sweep": {"points_mm_s_rad_s": [[float(u), float(w)] for u, w in self.points],
                          "replicates": self.replicates},
                "surrogate": {"n_test": n_test}}, sort_keys=False))
        runs = self.runs(points)
        out = f"results/{self.level}"
        targets = [f"{out}/runs/{run}/metrics.json" for run in runs]
        log_path = self.workdir / f"results/logs/{self.level}/adaptive/{self.outdir.name}_round{self.calls}.log"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "snakemake", *targets, "-s", str(ROOT / "Snakefile"),
               "-d", str(self.workdir), "--configfile", str(self.configfile), str(round_cfg),
               "--cores", str(self.cores), "--rerun-incomplete"]
        t0 = time.perf_counter()
        with open(log_path, "w") as f:
            proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
        if proc.returncode != 0:
            tail = "".join(log_path.read_text().splitlines(keepends=True)[-25:])
            raise RuntimeError(f"snakemake failed for round {self.calls} (log {log_path}):\n{tail}")
        done = log_path.read_text().count("rule spread:")
        self.log(f"  snakemake: {len(runs)} run(s) requested, {done} simulated, "
                 f"{time.perf_counter() - t0:.0f} s (config {round_cfg.name})")
        bench = f"results/benchmarks/{self.level}"
        base = self.workdir
        data = build_dataset([base / f"{out}/runs/{r}/metrics.json" for r in runs],
                             [base / f"{out}/runs/{r}/health.json" for r in runs],
                             [base / f"{bench}/spread/{r}.tsv" for r in runs],
                             self.outdir / f"runs_round{self.calls}.csv")
        self.calls += 1
        return data


def write_result(result, outdir, level, extra_meta=None, surrogate_params=None):
    """Write design.csv, rounds.csv, dataset.csv and model.joblib of a run into ``outdir``.

    With ``surrogate_params`` (config's ``surrogate:``) the GP is saved with its intervals
    calibrated on its grouped k-fold held-out predictions over the design's runs
    (:mod:`analysis.surrogate.intervals`), so ``spreadmap-recommend`` can use them.
    """
    outdir = Path(outdir)
    for name, frame in (("design", result.design), ("rounds", result.rounds),
                        ("dataset", result.data)):
        with atomic_path(outdir / f"{name}.csv") as tmp:
            frame.to_csv(tmp, index=False)
    X = inputs_of(result.data)
    meta = {"level": level, "kind": "adaptive design GP", "stop": result.stop,
            "n_runs": len(result.data),
            "input_range": {c: [float(X[:, j].min()), float(X[:, j].max())]
                            for j, c in enumerate(INPUTS)},
            "model": {"name": "gp", "length_scale": result.model.length_scales_.tolist(),
                      "noise_std": result.model.noise_std_.tolist()},
            **(extra_meta or {})}
    model = result.model
    if surrogate_params is not None:
        params = {**surrogate_params, "models": ["gp"], "cv_loo": False}
        _, held_out = cross_validate_models(result.data, params, return_predictions=True)
        rho, source = relative_noise(result.data, random_state=int(params["random_state"]))
        model = calibrated_from_predictions(model, held_out[held_out.scheme == "kfold"], result.data, rho,
                                            params["confidence"], source)
        meta["model"]["intervals"] = model.summary()
    save_surrogate(model, outdir / "model.joblib", meta)


def main(argv=None):
    """Command line: the adaptive loop through the workflow (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m analysis.surrogate.adaptive",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "config.yaml",
                        help="base config (default: the repository's config.yaml)")
    parser.add_argument("--level", help="fidelity level (default: the config's)")
    parser.add_argument("--name", default="adaptive", help="results/<level>/adaptive/<NAME>/")
    parser.add_argument("--cores", type=int, default=2, help="snakemake --cores (default 2)")
    parser.add_argument("--workdir", type=Path, default=ROOT, help="Snakemake working directory")
    for key, kind in (("initial_points", int), ("batch_size", int), ("max_runs", int),
                      ("target_loo_r2", float), ("acquisition", str), ("error_weight", float),
                      ("seed", int)):
        parser.add_argument("--" + key.replace("_", "-"), dest=key, type=kind,
                            help=f"overrides adaptive.{key}")
    args = parser.parse_args(argv)
    try:
        config = load_config(args.config)
        level = args.level or config["level"]
        if level not in config["fidelity"]:
            raise ValueError(f"--level {level}: no such fidelity level; choose one of "
                             f"{sorted(config['fidelity'])}")
        settings = {**config["adaptive"], **{k: v for k, v in vars(args).items()
                                               if k in config["adaptive"] and v is not None}}
        replicates = int(config["sweep"]["replicates"])
        check_settings(settings, replicates)
        if sweep_axes(config):
            raise ValueError(f"the adaptive design spans (U, omega) only; this sweep also has "
                             f"{', '.join(sweep_axes(config))}: remove them from sweep (or fix their value in "
                             "the config) to run it")
        if args.cores < 1:
            raise ValueError(f"--cores must be at least 1, got {args.cores}")
    except USER_ERRORS as err:  # ConfigError is a ValueError
        parser.exit(2, f"{parser.prog}: error: {error_line(err)}\n")
    bounds = sweep_bounds(config)
    outdir = args.workdir / f"results/{level}/adaptive/{args.name}"
    print(f"adaptive design at level {level}: U {bounds[0][0]:g}..{bounds[0][1]:g} mm/s, omega "
          f"{bounds[1][0]:g}..{bounds[1][1]:g} rad/s; {settings['initial_points']} initial "
          f"points, batches of {settings['batch_size']}, budget {settings['max_runs']} runs; "
          f"writing {outdir}", flush=True)
    evaluator = WorkflowEvaluator(level, outdir, args.workdir, args.cores, replicates, args.config,
                                  log=lambda line: print(line, flush=True))
    try:
        result = run_adaptive(evaluator, bounds, settings, replicates=replicates,
                              log=lambda line: print(line, flush=True))
        write_result(result, outdir, level, surrogate_params=config["surrogate"])
    except USER_ERRORS as err:
        print(f"{parser.prog}: error: {error_line(err)}", file=sys.stderr)
        return 1
    print(f"wrote {outdir}/design.csv, rounds.csv, dataset.csv, model.joblib")
    return 0


if __name__ == "__main__":
    sys.exit(main())
