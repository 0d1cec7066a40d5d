"""The sweep's table of runs: its axes and points, each :class:`Run` and its folders, the config a run
or its heap computes with (:func:`run_config`, :func:`heap_config`), and the physics fingerprint that
Snakemake re-runs a simulation on (:func:`simulation_fingerprint`)."""
from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
from dataclasses import dataclass
from pathlib import Path

from analysis.physics import polygon_bottom_range

#: The sweep's keys that are not extra axes.
SWEEP_KEYS = ("U_mm_s", "omega_rad_s", "replicates", "points_mm_s_rad_s", "points")

#: The spreader's speeds: the two axes of every sweep (mm/s, rad/s).
SPEED_AXES = ("U_mm_s", "omega_rad_s")

#: Swept keys that the heap and the substrate do not depend on: their values share the
#: settle (and geometry) of the config's own value. Every other axis settles its own heap.
SPREAD_ONLY_AXES = ("roller.gap_um",)

#: Fidelity keys that say how a run is executed, not what it computes.
EXECUTION_KEYS = ("mpi_ranks", "runtime_min", "mem_mb_per_rank", "checkpoints_per_run", "profilometer_lines")


#: Top-level sections whose values a settle or spread computes with.
SIMULATION_SECTIONS = ("random_seed", "material", "psd", "roller", "substrate", "rest_rms_speed_mm_s", "timestep")


def sweep_axes(config: dict) -> list[str]:
    """The sweep's extra axes: config keys by dotted path (``roller.gap_um``), in the order written."""
    return [k for k in config["sweep"] if k not in SWEEP_KEYS]


def config_value(config: dict, key: str):
    """The config's value at a dotted key (``roller.gap_um``); None where there is none."""
    node = config
    for part in key.split("."):
        node = node.get(part) if isinstance(node, dict) else None
    return node


def resolve(config: dict, values: dict) -> dict:
    """A copy of ``config`` with each dotted key of ``values`` set to its value
    (the speeds, ``U_mm_s`` and ``omega_rad_s``, are not config keys and are left out)."""
    out = copy.deepcopy(config)
    for key, value in values.items():
        if key in SPEED_AXES:
            continue
        *path, last = key.split(".")
        node = out
        for k in path:
            node = node[k]
        if isinstance(node[last], int) and not isinstance(node[last], bool) and float(value).is_integer():
            value = int(value)      # a swept count stays an integer (the sweep reads its values as floats)
        if node[last] != value:     # the config's own value keeps its type (300, not 300.0): same fingerprint
            node[last] = value
    return out


def simulation_fingerprint(config: dict, level: str, sections=SIMULATION_SECTIONS,
                           base_dir: str | Path = ".") -> str:
    """A short hash of everything in ``config`` that a simulation of ``level``
    computes with (``sections`` and the level's fidelity keys but
    EXECUTION_KEYS), a user's ``substrate.mesh`` (relative to ``base_dir``) by its content.
    The workflow passes it as a rule parameter, so that
    Snakemake re-runs the simulations when the physics changes (and not when
    only the MPI ranks or the cluster limits do)."""
    relevant = {key: config.get(key) for key in sections}
    relevant["fidelity"] = {k: v for k, v in config["fidelity"][level].items() if k not in EXECUTION_KEYS}
    mesh = config["substrate"]["mesh"] if "substrate" in sections else None
    if mesh is not None:
        relevant["substrate_mesh_sha256"] = file_digest(Path(base_dir) / mesh)
    return hashlib.sha256(json.dumps(relevant, sort_keys=True, default=str).encode()).hexdigest()[:16]


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's content (cached by path, size and modification time); '' if it is missing."""
    path = Path(path).resolve()
    try:
        stat = path.stat()
    except OSError:
        return ""
    return _digest(path, stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _digest(path: Path, size: int, mtime_ns: int) -> str:
    sha = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            sha.update(block)
    return sha.hexdigest()


def run_name(U: float, omega: float, replicate: int) -> str:
    """Folder name of one run: U in mm/s, omega in rad/s, replicate index (``U70_w-2.5_r0``)."""
    return f"U{U:g}_w{omega:g}_r{replicate}"


def variant_path(values: dict) -> str:
    """Folders of the extra axes' values, outer first: ``roller.gap_um=200/`` ('' for none)."""
    return "".join(f"{k}={v:g}/" for k, v in values.items())


def design_points(config: dict) -> list[tuple[float, float]]:
    """The sweep's distinct (U [mm/s], omega [rad/s]) points, in order of first appearance:
    ``sweep.points_mm_s_rad_s`` or ``sweep.points`` if given, else the grid ``U_mm_s x omega_rad_s``
    (U outer)."""
    return list(dict.fromkeys((p["U_mm_s"], p["omega_rad_s"]) for p in sweep_points(config)))


def sweep_points(config: dict) -> list[dict]:
    """Every point of the sweep over all its axes: ``{"U_mm_s": U, "omega_rad_s": omega,
    <axis>: value, ...}`` (mm/s, rad/s, the axes' config units). ``sweep.points`` or
    ``sweep.points_mm_s_rad_s`` if given, else the full grid: U outer, then omega, then
    the extra axes (:func:`sweep_axes`) in the order written."""
    sweep, axes = config["sweep"], sweep_axes(config)
    if sweep.get("points_mm_s_rad_s"):
        return [{"U_mm_s": float(U), "omega_rad_s": float(w)} for U, w in sweep["points_mm_s_rad_s"]]
    if sweep.get("points"):
        return [{k: float(p[k]) for k in (*SPEED_AXES, *axes)} for p in sweep["points"]]
    grids = [sweep[k] for k in (*SPEED_AXES, *axes)]
    return [dict(zip((*SPEED_AXES, *axes), map(float, combo))) for combo in itertools.product(*grids)]


def variants(config: dict) -> list[dict]:
    """The distinct combinations of the extra axes' values the sweep runs (``[{}]`` for none)."""
    axes = sweep_axes(config)
    seen = {tuple(p[a] for a in axes): None for p in sweep_points(config)}
    return [dict(zip(axes, combo)) for combo in seen]


@dataclass(frozen=True)
class Run:
    """One run of the sweep: its speeds, replicate and extra axes' values, and where it lives.

    A value equal to the config's own (``own``) is left out of the folder names, so a run at the
    config's values of every extra axis is the plain (U, omega) run: adding an axis to a finished
    study reuses its runs and heaps (their physics fingerprints guard the reuse)."""
    U: float                # mm/s
    omega: float            # rad/s
    replicate: int
    values: tuple           # ((axis, value), ...) of the extra axes, in sweep order
    own: tuple = ()         # ((axis, the config's own value), ...)

    def _folders(self, values: dict) -> str:
        return variant_path({k: v for k, v in values.items() if (k, v) not in self.own})

    @property
    def name(self) -> str:
        """Its folder under ``runs/``: ``U70_w-10_r0``, or ``roller.gap_um=400/U70_w-10_r0``."""
        return self._folders(dict(self.values)) + run_name(self.U, self.omega, self.replicate)

    @property
    def heap(self) -> str:
        """Its heap's (geometry's and settle's) folder: ``r0``, or the values of the axes the heap
        depends on (all but :data:`SPREAD_ONLY_AXES`) before it: ``psd.mean_diameter_um=150/r0``."""
        return self._folders(self.heap_values) + f"r{self.replicate}"

    @property
    def heap_values(self) -> dict:
        """The extra axes' values its heap and substrate depend on."""
        return {k: v for k, v in self.values if k not in SPREAD_ONLY_AXES}

    @property
    def point(self) -> dict:
        """``{"U_mm_s": U, "omega_rad_s": omega, <axis>: value, ...}``."""
        return {"U_mm_s": self.U, "omega_rad_s": self.omega, **dict(self.values)}


def sweep_runs(config: dict) -> list[Run]:
    """Every run: each point of :func:`sweep_points` times ``sweep.replicates``."""
    axes = sweep_axes(config)
    own = tuple((a, config_value(config, a)) for a in axes)
    return [Run(p["U_mm_s"], p["omega_rad_s"], r, tuple((a, p[a]) for a in axes), own)
            for p in sweep_points(config) for r in range(config["sweep"]["replicates"])]


def runs_at(config: dict, points) -> list[Run]:
    """The runs of :func:`sweep_runs` at ``points``: every replicate of each, in the order of ``points``.

    Parameters
    ----------
    config : dict
        A loaded config whose sweep runs the points.
    points : iterable of dict
        ``{"U_mm_s": U, "omega_rad_s": omega, <axis>: value, ...}`` over every axis of the sweep
        (mm/s, rad/s, the axes' config units), as :func:`sweep_points` gives them; matched to
        6 decimals.

    Raises
    ------
    KeyError
        A point the sweep does not run (named).
    """
    inputs = (*SPEED_AXES, *sweep_axes(config))

    def key(point):
        return tuple(round(float(point[a]), 6) for a in inputs)

    table = {}
    for run in sweep_runs(config):
        table.setdefault(key(run.point), []).append(run)
    runs = []
    for point in points:
        if key(point) not in table:
            raise KeyError(f"the sweep does not run the point {point}")
        runs += table[key(point)]
    return runs


def run_config(config: dict, run: Run) -> dict:
    """``config`` with the run's extra axes' values in place: what its spread computes with."""
    return resolve(config, dict(run.values))


def heap_config(config: dict, run: Run) -> dict:
    """``config`` with the values its heap depends on in place: what its geometry and settle compute with
    (a spread-only axis, e.g. the gap, keeps the config's own value)."""
    return resolve(config, run.heap_values)


def run_parameters(config: dict, run: Run, base_dir: str | Path = ".") -> dict:
    """Everything a run computes with, resolved (its extra axes' values in place), JSON/YAML-ready:
    ``run`` (folder), ``U_mm_s``, ``omega_rad_s``, ``replicate``, ``swept`` (the extra axes'
    values), ``heap`` (its settle's folder), ``level``, ``roller_gap`` (the gap as built, um),
    ``physics`` (the fingerprint Snakemake re-runs on), and ``config``: the sections of
    :data:`SIMULATION_SECTIONS`, ``profilometer`` and the level's ``fidelity`` keys."""
    resolved, level = run_config(config, run), config["level"]
    roller = resolved["roller"]
    near, far = polygon_bottom_range(roller["diameter_mm"] / 2, roller["facets_around"])
    radius_mm, gap_um, mm_to_um = roller["diameter_mm"] / 2, roller["gap_um"], 1e3
    gap = {"datum": "the substrate's mean plane under the sampling region", "mean_over_a_turn_um": gap_um,
           "still_roller_um": gap_um, "min_um": gap_um - (far - radius_mm) * mm_to_um,
           "max_um": gap_um + (radius_mm - near) * mm_to_um}
    return {"run": run.name, "U_mm_s": run.U, "omega_rad_s": run.omega, "replicate": run.replicate,
            "swept": dict(run.values), "heap": run.heap, "level": level, "roller_gap": gap,
            "physics": simulation_fingerprint(resolved, level, base_dir=base_dir),
            "config": {**{k: resolved[k] for k in (*SIMULATION_SECTIONS, "profilometer")},
                       "fidelity": {level: resolved["fidelity"][level]}}}


def runs_by_name(config: dict) -> dict[str, Run]:
    """:func:`sweep_runs` by folder name (``Run.name``)."""
    return {run.name: run for run in sweep_runs(config)}


def heaps_by_name(config: dict) -> dict[str, Run]:
    """The first run of each heap folder (``Run.heap``): what the geometry and settle of that heap need."""
    table = {}
    for run in sweep_runs(config):
        table.setdefault(run.heap, run)
    return table
