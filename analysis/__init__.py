"""spreadmap: LIGGGHTS simulations of powder spreading turned into spreading process maps.

Sub-packages follow the pipeline: :mod:`analysis.dem` (geometry, LIGGGHTS
inputs and runs, health), :mod:`analysis.metrics` (dumps, the virtual
profilometer, the dataset, noise floor, trends, deposit profiles),
:mod:`analysis.surrogate` (regression of the metrics over (U, omega), model
choice, adaptive design, recommendation), :mod:`analysis.viz` (process maps,
3-D views). :mod:`analysis.config` reads the configuration, :mod:`analysis.io`
writes files atomically, :mod:`analysis.rule` is the glue of ``scripts/``.
"""
