"""The one error of a configuration: :class:`ConfigError`, whose message names the key and the value."""
from __future__ import annotations


class ConfigError(ValueError):
    """A configuration value is wrong; the message names its key and value."""


def refuse(key: str, value, why: str):
    """Raise :class:`ConfigError`: ``config key '<key>' = <value>: <why>``."""
    raise ConfigError(f"config key {key!r} = {value!r}: {why}")
