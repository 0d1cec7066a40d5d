"""Benchmarks and the machinery the tests share with them (a package, so that one import style serves both).

Each ``bench_*.py`` runs as a script from the repository root (``.venv/bin/python benchmarks/bench_x.py``)
and imports its siblings as ``from benchmarks.x import ...``; the tests, run from the repository root,
import them the same way. :mod:`benchmarks.faults` (fault injection), :mod:`benchmarks.slurm_cluster`
(a one-node SLURM cluster) and :mod:`benchmarks.restitution_drop` (one sphere's bounce) are test and
benchmark machinery, not part of a user's run: they live here, not in :mod:`analysis`.
"""
