"""The configuration: read ``config.yaml``, check it, and derive from it what a run computes with.

One concern a module, in the order a config goes through them:

- :mod:`~analysis.config.errors`: :class:`ConfigError`, whose message names the key and the value;
- :mod:`~analysis.config.reading`: YAML as its 1.2 core schema reads it, Snakemake's ``--config``
  values, the JSON Schema; :data:`PROJECT_DIR`;
- :mod:`~analysis.config.checks`: the facts that relate two keys (physics, run bounds, sweep, maps);
- :mod:`~analysis.config.load`: :func:`load_config`, reading and both checks;
- :mod:`~analysis.config.fidelity`: the :class:`Scene` of a fidelity level, in SI units;
- :mod:`~analysis.config.sweep`: the sweep's runs (:class:`Run`), their folders and configs, the
  physics fingerprint;
- :mod:`~analysis.config.folders`: a run or a heap found by its folder name.

Import a name from the module that owns it.
"""
