"""Adaptive Design of Simulations: fewer DEM runs for the same map, through the Snakemake workflow.

Each round's points become a config (:func:`round_config`) and a Snakemake run in a subprocess
that simulates only the new runs (:class:`WorkflowEvaluator`); the loop itself is
:func:`analysis.surrogate.adaptive.run_adaptive`.

Command line::

    python -m analysis.adaptive_workflow --level default --name adaptive --cores 2 [--max-runs 15]

(``spreadmap-adaptive``) writes ``results/<level>/adaptive/<name>/``: ``design.csv`` (points,
round, acquisition), ``rounds.csv`` (runs and leave-one-out scores per round), ``dataset.csv``
(the design's runs), ``model.joblib`` (the final GP, usable by ``python -m
analysis.surrogate.recommend --model``) and ``round_<k>.yaml`` (the points config each round's
Snakemake run used: :func:`round_config`).  Units: U in mm/s, omega in rad/s, an extra axis in
its config units (the dataset's dotted column), metrics as the dataset.
"""
from __future__ import annotations

import argparse
import copy
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from analysis.config.load import load_config
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import SPEED_AXES, runs_at, sweep_axes
from analysis.io import USER_ERRORS, atomic_path, error_line
from analysis.metrics.dataset import build_dataset
from analysis.surrogate.adaptive import check_settings, run_adaptive, write_result
from analysis.surrogate.design_space import (
    check_design_box,
    describe_box,
    design_inputs,
    sweep_bounds,
    sweep_resolution,
)

ROOT = PROJECT_DIR


def round_config(level, points, axes=(), replicates=1, n_test=1, cv_folds=None):
    """The config a round's Snakemake run adds to the base config (``--configfile base round``).

    Parameters
    ----------
    level : str
        Fidelity level.
    points : array_like, shape (n, k)
        Every design point so far: U (mm/s), omega (rad/s), then the extra axes (config units).
    axes : sequence of str
        The sweep's extra axes (dotted config keys), the columns ``points[:, 2:]``.
    replicates : int
    n_test : int
        ``surrogate.n_test`` (the workflow's surrogate checks it against the points).
    cv_folds : int, optional
        ``surrogate.cv_folds``, at most the points (the config check refuses more); default: the base's.

    Returns
    -------
    dict
        ``level``, ``sweep`` and ``surrogate``.  The points are ``sweep.points`` over every
        axis, or ``sweep.points_mm_s_rad_s`` (U, omega pairs) when there are no extra axes;
        the base config's axis lists stay and give the range.
    """
    P = np.atleast_2d(np.asarray(points, float))
    names = [*SPEED_AXES, *axes]
    if P.shape[1] != len(names):
        raise ValueError(f"points have {P.shape[1]} columns for the {len(names)} inputs {', '.join(names)}")
    listed = ({"points": [dict(zip(names, map(float, p))) for p in P]} if len(axes) else
              {"points_mm_s_rad_s": [[float(u), float(w)] for u, w in P]})
    return {"level": level, "sweep": {**listed, "replicates": int(replicates)},
            "surrogate": {"n_test": int(n_test), **({} if cv_folds is None else
                                                    {"cv_folds": int(min(cv_folds, max(2, len(P))))})}}


class WorkflowEvaluator:
    """Run design points through the Snakemake workflow; return their dataset rows.

    Each call writes ``<outdir>/round_<k>.yaml`` (:func:`round_config`: every
    point so far), asks Snakemake for those runs' ``metrics.json`` (so only
    runs not yet done are simulated: runs of the grid or of other designs at
    the same point are reused) and gathers the requested points' runs with
    :func:`analysis.metrics.dataset.build_dataset` (the workflow's own
    ``results/<level>/dataset.csv`` is left alone).  The run folders are the
    round config's own (:func:`analysis.config.sweep.runs_at` over the base config
    merged with the round's, as Snakemake merges them), so they follow the
    workflow's naming.  The extra axes are the base config's
    (:func:`analysis.config.sweep_axes`); points are (b, k): U (mm/s),
    omega (rad/s), then each axis (config units).

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
        self.base = yaml.safe_load(self.configfile.read_text())
        self.axes = sweep_axes(self.base)
        self.points = []
        self.calls = 0

    def resolved(self, round_cfg):
        """The config Snakemake runs the round with: the base updated by ``round_cfg``
        (Snakemake's ``update_config``), loaded and checked (:func:`analysis.config.load.load_config`)."""
        from snakemake.utils import update_config
        merged = copy.deepcopy(self.base)
        update_config(merged, round_cfg)
        return load_config(merged, base_dir=ROOT)

    def run_table(self, points, config):
        """The runs (:class:`analysis.config.sweep.Run`) of the points (b, k), every replicate, in ``config``."""
        names = [*SPEED_AXES, *self.axes]
        return runs_at(config, [dict(zip(names, p)) for p in np.atleast_2d(points).tolist()])

    def runs(self, points, config):
        """Run folder names (under ``runs/``) of the points (b, k), every replicate, in ``config``."""
        return [run.name for run in self.run_table(points, config)]

    def __call__(self, points):
        points = np.atleast_2d(np.asarray(points, float))
        known = {tuple(p) for p in self.points}
        self.points += [tuple(p) for p in points if tuple(p) not in known]
        self.outdir.mkdir(parents=True, exist_ok=True)
        round_path = self.outdir / f"round_{self.calls}.yaml"
        cfg = round_config(self.level, self.points, self.axes, self.replicates,
                           n_test=max(1, min(2, len(self.points) - 3)),
                           cv_folds=self.base["surrogate"]["cv_folds"])
        with atomic_path(round_path) as tmp:
            tmp.write_text(yaml.safe_dump(cfg, sort_keys=False))
        table = self.run_table(points, self.resolved(cfg))
        runs = [run.name for run in table]
        out = f"results/{self.level}"
        targets = [f"{out}/runs/{run}/metrics.json" for run in runs]
        log_path = self.workdir / f"results/logs/{self.level}/adaptive/{self.outdir.name}_round{self.calls}.log"
        log_path.parent.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, "-m", "snakemake", *targets, "-s", str(ROOT / "Snakefile"),
               "-d", str(self.workdir), "--configfile", str(self.configfile), str(round_path),
               "--cores", str(self.cores), "--rerun-incomplete"]
        t0 = time.perf_counter()
        with open(log_path, "w") as f:
            proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
        if proc.returncode != 0:
            tail = "".join(log_path.read_text().splitlines(keepends=True)[-25:])
            raise RuntimeError(f"snakemake failed for round {self.calls} (log {log_path}):\n{tail}")
        done = log_path.read_text().count("rule spread:")
        self.log(f"  snakemake: {len(runs)} run(s) requested, {done} simulated, "
                 f"{time.perf_counter() - t0:.0f} s (config {round_path.name})")
        bench = f"results/benchmarks/{self.level}"
        base = self.workdir
        data = build_dataset([base / f"{out}/runs/{r}/metrics.json" for r in runs],
                             [base / f"{out}/runs/{r}/health.json" for r in runs],
                             [base / f"{bench}/spread/{r}.tsv" for r in runs],
                             self.outdir / f"runs_round{self.calls}.csv", points=[run.point for run in table])
        self.calls += 1
        return data



def main(argv=None):
    """Command line: the adaptive loop through the workflow (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m analysis.adaptive_workflow",
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
        axes = sweep_axes(config)
        check_settings(settings, replicates, axes)
        bounds, resolution = sweep_bounds(config), sweep_resolution(config, settings)
        check_design_box(bounds, resolution, design_inputs(config))
        if args.cores < 1:
            raise ValueError(f"--cores must be at least 1, got {args.cores}")
    except USER_ERRORS as err:  # ConfigError is a ValueError
        parser.exit(2, f"{parser.prog}: error: {error_line(err)}\n")
    outdir = args.workdir / f"results/{level}/adaptive/{args.name}"
    print(f"adaptive design at level {level}: {describe_box(bounds, design_inputs(config))}; "
          f"{settings['initial_points']} initial "
          f"points, batches of {settings['batch_size']}, budget {settings['max_runs']} runs; "
          f"writing {outdir}", flush=True)
    evaluator = WorkflowEvaluator(level, outdir, args.workdir, args.cores, replicates, args.config,
                                  log=lambda line: print(line, flush=True))
    try:
        result = run_adaptive(evaluator, bounds, settings, axes=axes, resolution=resolution,
                              replicates=replicates, log=lambda line: print(line, flush=True))
        write_result(result, outdir, level, surrogate_params=config["surrogate"])
    except USER_ERRORS as err:
        print(f"{parser.prog}: error: {error_line(err)}", file=sys.stderr)
        return 1
    print(f"wrote {outdir}/design.csv, rounds.csv, dataset.csv, model.joblib")
    return 0


if __name__ == "__main__":
    sys.exit(main())
