"""spreadmap: LIGGGHTS simulations of powder spreading turned into spreading process maps.

Sub-packages follow the pipeline: :mod:`analysis.dem` (geometry, LIGGGHTS
inputs and runs, health), :mod:`analysis.metrics` (dumps, the virtual
profilometer, the layer metrics, the dataset, noise floor, trends, deposit
profiles), :mod:`analysis.surrogate` (regression of the metrics over (U, omega),
model choice, adaptive design, recommendation), :mod:`analysis.viz` (process
maps, 3-D views). :mod:`analysis.columns` names the dataset's columns,
:mod:`analysis.physics` holds physical helpers and limits, :mod:`analysis.config`
reads the configuration, :mod:`analysis.io` writes files atomically,
:mod:`analysis.rule` is the glue of ``scripts/``; :mod:`analysis.measure` (the
layer metrics of a dump) and :mod:`analysis.adaptive_workflow` (the adaptive
design through Snakemake) are command lines over several sub-packages.
"""
