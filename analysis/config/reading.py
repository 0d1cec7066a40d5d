"""Reading a configuration: YAML as its 1.2 core schema reads it, Snakemake's ``--config`` values
(:func:`coerce_cli_values`), and the JSON Schema (types, ranges, unknown keys, finite numbers).

Each raises :class:`~analysis.config.errors.ConfigError` in one line naming the source or the key.
"""
from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import jsonschema
import yaml

from analysis.config.errors import ConfigError, refuse

#: The project folder: config.yaml, templates/, Snakefile (the package is installed in place).
PROJECT_DIR = Path(__file__).resolve().parents[2]
SCHEMA_PATH = Path(__file__).resolve().parents[1] / "schemas" / "config.schema.yaml"


class StrictLoader(yaml.SafeLoader):
    """YAML as its 1.2 core schema reads it: ``true``/``false`` are the only booleans (``yes``,
    ``on``, ``y`` stay strings, which the schema then refuses where a boolean is wanted), and
    ``1e9`` is a number (YAML 1.1 wants ``1.0e+9``)."""


StrictLoader.yaml_implicit_resolvers = {
    first: [(tag, regex) for tag, regex in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()}
StrictLoader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                                   list("tTfF"))
StrictLoader.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9]+[eE][-+]?[0-9]+$"),
                                   list("-+0123456789"))


def parse_yaml(text: str, source: str):
    """``text`` parsed by :class:`StrictLoader`; a syntax error is one :class:`ConfigError` line
    naming ``source`` (a file, or a ``--config`` argument) and the line and column."""
    try:
        return yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = " ".join(str(getattr(err, "problem", None) or err).split())
        raise ConfigError(f"{source}: YAML syntax error{where}: {what}") from None


def coerce_cli_values(value, key: str = ""):
    """Numbers, booleans and nulls from strings, recursively.

    Snakemake parses nested ``--config key='{...}'`` values with YAML's
    BaseLoader, which leaves every scalar a string; this restores the types
    so that ``--config sweep='{"U_mm_s": [40, 70]}'`` works. A value that is
    not YAML raises :class:`ConfigError` naming ``--config <key>=<value>``.
    """
    if isinstance(value, dict):
        return {k: coerce_cli_values(v, f"{key}.{k}" if key else str(k)) for k, v in value.items()}
    if isinstance(value, list):
        return [coerce_cli_values(v, key) for v in value]
    if isinstance(value, str):
        return parse_yaml(value, f"--config {key}={value}".replace("\n", "\\n")) if value.strip() else value
    return value


@functools.cache
def load_schema() -> dict:
    """The config's JSON Schema (read once; not to be changed in place)."""
    return yaml.safe_load(SCHEMA_PATH.read_text())


def read_config_file(path: str | Path) -> dict:
    """The mapping in a YAML config file; an empty file, a syntax error or a top level that is
    not a mapping raises one :class:`ConfigError` line naming the file (and the line, column)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not a YAML text file ({err.reason} at byte {err.start})") from None
    config = parse_yaml(text, str(path))
    if not isinstance(config, dict):
        raise ConfigError(f"{path}: " + ("empty: no config keys" if config is None else
                                         f"holds a {type(config).__name__}, not a mapping of config keys"))
    return config


def check_finite(config, key: str = "") -> None:
    """Raise :class:`ConfigError` naming the first NaN or infinite number in ``config``.

    JSON Schema cannot say "finite": NaN fails no ``minimum`` and infinity passes
    every ``minimum``, so this walks the mapping before the schema does.
    """
    if isinstance(config, dict):
        for k, v in config.items():
            check_finite(v, f"{key}.{k}" if key else str(k))
    elif isinstance(config, list):
        for i, v in enumerate(config):
            check_finite(v, f"{key}[{i}]")
    elif isinstance(config, float) and not math.isfinite(config):
        refuse(key or "<top level>", config, "must be a finite number")


#: JSON Schema counts 2.0 as an integer; a count or a seed written 2.0 is refused instead
#: (``range(2.0)`` and a seed of '11027.0' fail later, far from the key).
_Validator = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine(
        "integer", lambda _, value: isinstance(value, int) and not isinstance(value, bool)))


@functools.cache
def _validator():
    return _Validator(load_schema())


def _non_text_key(node, path=()):
    """The dotted path of the first mapping key that is not text (YAML's ``null:``, ``1:``), or None."""
    if isinstance(node, dict):
        for key, value in node.items():
            if not isinstance(key, str):
                return ".".join([*path, repr(key)])
            found = _non_text_key(value, (*path, key))
            if found:
                return found
    elif isinstance(node, list):
        for item in node:
            found = _non_text_key(item, path)
            if found:
                return found
    return None


def validate_schema(config: dict) -> None:
    """Raise :class:`ConfigError` on the first schema violation, naming key and value."""
    bad = _non_text_key(config)
    if bad:
        raise ConfigError(f"config key {bad!r}: a key must be a name (text), e.g. U_mm_s")
    validator = _validator()
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if errors:
        error = errors[0]
        key = ".".join(str(p) for p in error.absolute_path) or "<top level>"
        raise ConfigError(f"config key {key!r}: {error.message} (value: {error.instance!r})")
