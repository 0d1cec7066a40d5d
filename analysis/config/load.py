"""Load and check ``config.yaml``: read it (:mod:`analysis.config.reading`), then check it twice:
by its JSON Schema (types, ranges, unknown keys) and by :func:`~analysis.config.checks.check_config`
(facts that relate two keys). Both raise :class:`~analysis.config.errors.ConfigError` with the
dotted key and the offending value, before any simulation starts.
"""
from __future__ import annotations

import copy
from pathlib import Path

from analysis.config.checks import check_config
from analysis.config.errors import ConfigError
from analysis.config.reading import check_finite, read_config_file, validate_schema


def load_config(source: str | Path | dict, base_dir: str | Path | None = None) -> dict:
    """Read (if a path), validate and return the configuration.

    Parameters
    ----------
    source : path or dict
        ``config.yaml`` or an already-parsed mapping (e.g. Snakemake's ``config``).
    base_dir : path, optional
        Folder that a relative ``substrate.mesh`` is resolved against; defaults to
        the config file's folder, or the working directory for a mapping.
    """
    if isinstance(source, (str, Path)):
        path = Path(source)
        if not path.is_file():
            raise ConfigError(f"config file {str(path)!r} does not exist")
        config = read_config_file(path)
        base_dir = path.parent if base_dir is None else base_dir
    else:
        config = copy.deepcopy(source)
    check_finite(config)
    validate_schema(config)
    check_config(config, Path(base_dir or "."))
    return config
