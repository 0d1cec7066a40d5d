"""A run or a heap found by its folder name (:func:`find_run`, :func:`find_heap`): the sweep's, or a
point outside it named by its folder, checked as a swept one is."""
from __future__ import annotations

import copy
import re
from pathlib import Path

from analysis.config.checks import check_speeds, check_swept_gap, check_variant
from analysis.config.errors import ConfigError
from analysis.config.reading import check_finite, validate_schema
from analysis.config.sweep import (
    SPEED_AXES,
    SPREAD_ONLY_AXES,
    Run,
    config_value,
    heaps_by_name,
    runs_by_name,
    sweep_axes,
    sweep_runs,
)

_AXIS_FOLDER = re.compile(r"([A-Za-z_][A-Za-z0-9_.]*)=([^/]+)")
_RUN_FOLDER = re.compile(r"U([^_/]+)_w([^_/]+)_r(\d+)")


def find_run(config: dict, name: str, table: dict | None = None, base_dir: str | Path = ".") -> Run:
    """The run of folder ``name`` (its path under ``runs/``): the sweep's (``table``, default
    :func:`runs_by_name`), or a point outside the sweep named by its folder, e.g.
    ``U100_w-7_r0`` or ``roller.gap_um=350/U70_w-5_r1``: its speeds, replicate and the extra axes'
    values, each checked as a swept one is (the axes not named take the config's own values).

    Raises :class:`ConfigError` naming the folder and what is wrong with it, in one line."""
    table = runs_by_name(config) if table is None else table
    if name in table:
        return table[name]
    *folders, leaf = name.split("/")
    match = _RUN_FOLDER.fullmatch(leaf)
    if not match:
        raise ConfigError(f"run folder {name!r}: not a run's folder name, U<mm/s>_w<rad/s>_r<replicate> "
                          "(e.g. U70_w-5_r0), after a folder <axis>=<value>/ for each extra sweep axis")
    U, omega = (_folder_number(name, key, text) for key, text in (("U_mm_s", match[1]), ("omega_rad_s", match[2])))
    values = _folder_values(config, name, folders, SPEED_AXES)
    trial = copy.deepcopy(config)
    trial["sweep"] = {"U_mm_s": [U], "omega_rad_s": [omega], "replicates": int(match[3]) + 1,
                      **{axis: [value] for axis, value in values.items()}}
    try:
        check_finite(trial["sweep"], "sweep")
        validate_schema(trial)
        if values:
            check_variant(config, values, Path(base_dir), "sweep", values)
        if "roller.gap_um" in values:
            check_swept_gap(config, values["roller.gap_um"])
        check_speeds(trial)
    except ConfigError as err:
        raise ConfigError(f"run folder {name!r}: {err}") from None
    return _named(config, name, Run(U, omega, int(match[3]), tuple(values.items()), _own(config)), "name")


def find_heap(config: dict, name: str, table: dict | None = None, base_dir: str | Path = ".") -> Run:
    """The first run of heap folder ``name`` (``r0``, ``psd.mean_diameter_um=150/r1``): the sweep's
    (``table``, default :func:`heaps_by_name`), or a heap outside it named by its folder (a new
    replicate, or values of the axes the heap depends on). Raises :class:`ConfigError` naming it."""
    table = heaps_by_name(config) if table is None else table
    if name in table:
        return table[name]
    *folders, leaf = name.split("/")
    if not re.fullmatch(r"r\d+", leaf):
        raise ConfigError(f"heap folder {name!r}: not a heap's folder name, r<replicate> (e.g. r0), after a "
                          "folder <axis>=<value>/ for each extra sweep axis the heap depends on")
    values = _folder_values(config, name, folders, (*SPEED_AXES, *SPREAD_ONLY_AXES))
    if values:
        try:
            check_variant(config, values, Path(base_dir), "sweep", values)
        except ConfigError as err:
            raise ConfigError(f"heap folder {name!r}: {err}") from None
    first = sweep_runs(config)[0]
    return _named(config, name, Run(first.U, first.omega, int(leaf[1:]), tuple(values.items()), _own(config)),
                  "heap")


def _own(config: dict) -> tuple:
    return tuple((a, config_value(config, a)) for a in sweep_axes(config))


def _named(config: dict, name: str, run: Run, attribute: str) -> Run:
    """``run`` if its folder is spelt ``name``; else a ConfigError giving its spelling."""
    if getattr(run, attribute) != name:
        raise ConfigError(f"{'run' if attribute == 'name' else 'heap'} folder {name!r}: its point's folder is "
                          f"{getattr(run, attribute)!r} (numbers as :g writes them, the sweep's axes in order)")
    return run


def _folder_number(name: str, key: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"folder {name!r}: {key} = {text!r} is not a number") from None


def _folder_values(config: dict, name: str, folders: list, excluded) -> dict:
    """The extra axes' values named by the ``<axis>=<value>`` folders of ``name``, in sweep order."""
    axes = [a for a in sweep_axes(config) if a not in excluded]
    values = {}
    for folder in folders:
        match = _AXIS_FOLDER.fullmatch(folder)
        if not match or match[1] not in axes:
            raise ConfigError(f"folder {name!r}: {folder!r} does not name an axis of the sweep as <axis>=<value> "
                              f"(its axes here: {', '.join(axes) or 'none'})")
        values[match[1]] = _folder_number(name, match[1], match[2])
    return {a: values[a] for a in axes if a in values}
