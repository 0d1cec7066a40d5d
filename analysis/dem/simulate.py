"""One scene, run for real: make its geometry, settle its heap, spread it.

Each step renders a template from ``templates/``, runs LIGGGHTS through
:mod:`analysis.dem.liggghts` and checks the result's health; an unsound run
raises :class:`~analysis.dem.liggghts.LiggghtsError`, never passes a result on.

Command line (the workflow's rules call the same functions)::

    python -m analysis.dem.simulate geometry --level smoke --out results/smoke/meshes
    python -m analysis.dem.simulate settle   --level smoke --meshes results/smoke/meshes --out results/smoke/settle
    python -m analysis.dem.simulate spread   --level smoke --U 70 --omega -5 --meshes ... --settled ... --out ...
"""
from __future__ import annotations

import argparse
import errno
import hashlib
import json
import math
import os
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from analysis.config.checks import MAX_RUN_STEPS
from analysis.config.errors import ConfigError
from analysis.config.fidelity import Scene, scene
from analysis.config.load import load_config
from analysis.config.sweep import resolve
from analysis.dem import geometry
from analysis.dem.health import (
    MAX_STRAYS,
    SQUEEZE_FACTOR,
    blowup_limit,
    check_kinetic_energy,
    check_timestep,
    feed_health,
    feed_landings,
    feed_pile_fraction,
    heap_supply,
    inrun_health,
    layer_health,
    squeeze_out_speed,
    squeeze_threshold,
    through_roller,
)
from analysis.dem.inputs import (
    THERMO_EVERY,
    binsize,
    checkpoint_plan,
    contact_model,
    feed_plan,
    feed_zone,
    processors_grid,
    rest_loop,
    seeds,
    skin,
    stop_checks,
    travel_segments,
)
from analysis.dem.liggghts import LiggghtsError, UnstableRunError, input_path, render, run
from analysis.io import USER_ERRORS, error_line, write_json
from analysis.metrics.dump import read_dump, write_dump
from analysis.physics import MAX_OVERLAP, liggghts_seeds, roller_motion

#: Length [m] over which the rough substrate ramps to flat outside the sampling region.
ROUGH_TAPER = 0.5e-3


def substrate_seed(config: dict, replicate: int = 0) -> int:
    """Seed of the substrate's random field for ``replicate``: every replicate is a new
    heap packing *and* a new realisation of the same rough surface (same Sq and
    correlation length), so the seed-to-seed spread includes the substrate's."""
    return config["substrate"]["seed"] + replicate


def make_geometry(config: dict, level: str, outdir: str | Path, base_dir: Path = Path("."),
                  replicate: int = 0) -> dict:
    """Write ``substrate.stl``, ``roller.stl`` (closed) and ``roller_shell.stl``
    (its lateral surface, what the periodic strip loads) into ``outdir``.

    The generated substrate is realisation :func:`substrate_seed` of ``replicate``.
    A user's surface (``substrate.mesh`` in the config, any format meshio reads, metres) replaces it for every
    replicate; it must cover the bed, and no substrate peak may reach the roller.
    """
    s, out = scene(config, level), Path(outdir)
    if s.substrate["mesh"]:
        try:
            substrate = geometry.load_surface(base_dir / s.substrate["mesh"])
        except ValueError as err:
            raise ConfigError(f"config key 'substrate.mesh': {err}") from None
        lo, hi = substrate.bounds
        need = (s.substrate_x[0], s.substrate_x[1], 0.0, s.strip_width)
        _check_units(substrate, s)
        if lo[0] > need[0] + COVER_TOL or hi[0] < need[1] - COVER_TOL or lo[1] > COVER_TOL or \
                hi[1] < s.strip_width - COVER_TOL:
            raise ConfigError(f"config key 'substrate.mesh' = {s.substrate['mesh']!r}: "
                              f"covers x {lo[0]:.4g}..{hi[0]:.4g} m,"
                              f" y {lo[1]:.4g}..{hi[1]:.4g} m; the bed needs x {need[0]:.4g}..{need[1]:.4g},"
                              f" y 0..{s.strip_width:.4g} m")
    else:
        sub = s.substrate
        substrate = geometry.rough_substrate(s.substrate_x, s.strip_width, sub["grid_spacing"],
                                             sub["correlation_length"], sub["sq"], substrate_seed(config, replicate),
                                             rough_x=s.rough_x, taper=ROUGH_TAPER,
                                             peak_cap=sub["peak_cap"], rms_x=s.sampling_region[:2])
    peak = substrate.vertices[:, 2].max()
    mean, sq = geometry.substrate_rms(substrate, s.sampling_region[:2])  # the gap's datum, the measured Sq
    if peak >= mean + s.roller_gap:
        raise ConfigError(f"config key 'roller.gap_um' = {s.roller_gap * 1e6:g}: the substrate's highest peak "
                          f"({(peak - mean) * 1e6:.0f} um above the sampling region's mean plane) reaches the roller")
    if substrate.vertices[:, 2].min() <= s.box[4]:
        raise ConfigError(f"substrate reaches below the simulation box (z = {s.box[4]:.4g} m)")
    paths = {"substrate": geometry.write_stl(substrate, out / "substrate.stl"),
             "roller": geometry.write_stl(geometry.roller(2 * s.roller_radius, s.strip_width, s.roller_facets),
                                          out / "roller.stl"),
             "roller_shell": geometry.write_stl(
                 geometry.roller(2 * s.roller_radius, s.strip_width, s.roller_facets, capped=False),
                 out / "roller_shell.stl")}
    return {**{k: str(v) for k, v in paths.items()}, "substrate_seed": None if s.substrate["mesh"] else
            substrate_seed(config, replicate), "substrate_mean_m": mean, "substrate_sq_m": sq,
            "substrate_peak_m": float(peak), "substrate_triangles": len(substrate.faces)}


#: How far [m] a user's mesh may fall short of the bed's edges: float32 rounding (binary STL,
#: PLY) moves them by nanometres.
COVER_TOL = 1e-7


def _check_units(substrate, s: Scene) -> None:
    """A ConfigError if the user's mesh looks like millimetres or micrometres, not metres
    (:func:`geometry.units_slip` against the bed and the simulation box)."""
    slip = geometry.units_slip(substrate, (s.substrate_x[1] - s.substrate_x[0], s.strip_width), s.box[5] - s.box[4])
    if slip:
        raise ConfigError(f"config key 'substrate.mesh' = {s.substrate['mesh']!r}: {slip}: in millimetres or "
                          "micrometres? the mesh must be in metres")


def ran(log: dict, input_file: Path) -> dict:
    """``log`` if LIGGGHTS ran time steps (printed thermo rows); else a LiggghtsError naming the run folder."""
    if log["thermo"].empty or "KinEng" not in log["thermo"]:
        raise LiggghtsError(f"LIGGGHTS on {input_file.name} exited 0 without running a time step (no thermo "
                            f"output in its log); run folder: {input_file.parent}")
    return log


def need_files(*files) -> None:
    """Raise FileNotFoundError (``<file>: No such file or directory (<what>)``) for the first of
    ``(path, what)`` that is not a file: before LIGGGHTS, which would end in an MPI_ABORT."""
    for path, what in files:
        if not Path(path).is_file():
            raise FileNotFoundError(errno.ENOENT, f"No such file or directory ({what})", str(path))


def _publish(out: Path, summary: dict, *names: str) -> None:
    """Rename the run's ``<name>.part`` files to ``<name>``, then write
    ``health.json``: a run killed or refused earlier leaves nothing that looks finished."""
    for name in names:
        os.replace(out / f"{name}.part", out / name)
    write_json(summary, out / "health.json")


def settle(config: dict, level: str, meshes: str | Path, outdir: str | Path, replicate: int = 0,
           max_steps: int | None = None) -> dict:
    """Insert the heap and let it settle on the substrate; writes ``settled.restart``,
    ``settled.dump``, ``settle.in``, ``settle.log`` and ``health.json`` into ``outdir``.

    ``max_steps`` cuts each settling phase to that many steps: a start-up check
    of a big scene (benchmarks/bench_scaling.py), not a settled heap."""
    s, out, meshes = scene(config, level), Path(outdir), Path(meshes).resolve()
    if s.timestep > s.max_rayleigh_fraction * s.rayleigh_time:
        raise LiggghtsError(f"time step {s.timestep:.3g} s exceeds the allowed fraction of the Rayleigh time")
    need_files((meshes / "substrate.stl", "the geometry step's substrate: --meshes"))
    out.mkdir(parents=True, exist_ok=True)
    text = render("settle.in.j2", s=s, contact=contact_model(s), seeds=seeds(config, s, replicate),
                  box=[f"{v:.6g}" for v in s.box],
                  processors=processors_grid(s),
                  skin=skin(s), binsize=binsize(s), thermo_every=THERMO_EVERY,
                  **(rest_loop(s, s.settle_time) if max_steps is None else
                     {**rest_loop(s, s.settle_time), "chunk_steps": max_steps, "max_chunks": 1}),
                  substrate_stl=input_path(meshes / "substrate.stl", out),
                  restart="settled.restart.part", dump="settled.dump.part",
                  stray_x=s.sampling_region[0] - max(s.diameters), max_strays=MAX_STRAYS)
    (out / "settle.in").write_text(text)
    squeeze_speed = squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio)
    log = ran(run(out / "settle.in", out / "settle.log", ranks=s.mpi_ranks,
                  abort_speed=blowup_limit(squeeze_speed=squeeze_speed)), out / "settle.in")
    check_timestep(log, s)
    peak = check_kinetic_energy(log, squeeze_speed=squeeze_speed)
    if log["inserted"] != s.heap_particles:
        raise LiggghtsError(f"inserted {log['inserted']} of {s.heap_particles} particles: the heap region is too "
                            "small for heap_particles (see fidelity level)")
    atoms = read_dump(out / "settled.dump.part").atoms
    before_strays = int(log["thermo"]["Atoms"].iloc[-2])  # the last row is the `run 0` after delete_atoms
    strays = before_strays - len(atoms)
    if strays > MAX_STRAYS * s.heap_particles:
        raise LiggghtsError(f"{strays} of {s.heap_particles} particles rolled ahead of the slumped heap into the "
                            f"sampling region (from {s.sampling_region[0] * 1e3:.2f} mm; at most "
                            f"{MAX_STRAYS:.0%} may): raise fidelity.{level}.sampling_start_mm or heap_length_mm")
    health = layer_health(atoms, s, meshes / "substrate.stl", s.heap_particles - strays)
    health["strays_removed"] = strays
    health["heap_toe_m"] = float(atoms["x"].max() + atoms["radius"].max())
    summary = {"wall_s": log["wall_s"], "cpu_s": log["cpu_s"], "steps": int(log["thermo"]["Step"].iloc[-1]),
               "mpi_launcher": log["launcher"], "timestep_s": s.timestep,
               "rayleigh_fraction": log["measured_max_rayleigh_fraction"],
               "hertz_fraction": log["measured_max_hertz_fraction"], "inserted": log["inserted"], **peak, **health}
    _publish(out, summary, "settled.restart", "settled.dump")
    return summary


CHECKPOINT_DIR = "checkpoint"


#: Where ``spread.in.j2`` writes each top-up's landed particles (``feed_landings.csv`` keeps them).
FEED_DIR = "feed"
#: Where a run with ``freeze_lag_mm`` writes the frozen layer it drops (restored to the final dump).
LAID_DIR = "laid"
#: Frozen particles this many largest diameters behind the freezing cut stay, as the free ones' support;
#: those farther back leave the run (``freeze_lag_mm``).
FROZEN_BAND_DIAMETERS = 2


def restore_dropped(out: Path) -> tuple[int, int]:
    """Put the frozen layer that a run with ``freeze_lag_mm`` dropped (``laid/dropped.<step>.dump``, at rest
    where it was frozen) back into its ``final.dump.part``. A particle that landed where dropped ones had been
    (an intruder: it overlaps one dropped earlier by more than ``MAX_OVERLAP`` of the smaller radius, no
    resting contact) fell into a hole the frozen layer would have held it above, and is removed: a free
    particle of the final state, or one frozen and dropped itself later. The drops stay in ``laid/`` until the
    run is published, so that a run resumed from a checkpoint after a failed check restores them again; a
    dump that already holds them is left as it is.
    Returns (particles restored, intruders removed)."""
    parts = sorted((out / LAID_DIR).glob("dropped.*.dump"), key=_drop_step)
    dropped = [a for a in (read_dump(p).atoms for p in parts) if len(a)]
    final = read_dump(out / "final.dump.part")
    if not dropped or np.isin(dropped[0]["id"], final.atoms["id"]).any():
        return 0, 0
    frames = [a[final.atoms.columns] for a in dropped] + [final.atoms]
    atoms = pd.concat(frames, ignore_index=True)
    order = np.repeat(np.arange(len(frames)), [len(a) for a in frames])  # when each left the run; the final last
    xyz, radius = atoms[["x", "y", "z"]].to_numpy(), atoms["radius"].to_numpy()
    pairs = cKDTree(xyz).query_pairs(2 * radius.max(), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    overlap = (radius[i] + radius[j] - np.linalg.norm(xyz[i] - xyz[j], axis=1)) / np.minimum(radius[i], radius[j])
    hit = (overlap > MAX_OVERLAP) & (order[i] != order[j])
    intruder = np.zeros(len(atoms), dtype=bool)
    intruder[np.where(order[i] > order[j], i, j)[hit]] = True
    write_dump(out / "final.dump.part", atoms[~intruder].sort_values("id", kind="stable"), final.box,
               final.timestep, periodic=final.periodic)
    return int(np.sum(~intruder[order < len(dropped)])), int(intruder.sum())


def forget_drops_after(out: Path, step: int) -> None:
    """Delete the frozen layer a killed attempt dropped after ``step`` (``laid/dropped.<step>.dump``): those
    particles are in the checkpoint of ``step`` that the run resumes from, and are dropped again."""
    for later in (out / LAID_DIR).glob("dropped.*.dump"):
        if _drop_step(later) > step:
            later.unlink()


def _drop_step(path: Path) -> int:
    """The step at which ``laid/dropped.<step>.dump`` was written."""
    return int(path.name.split(".")[1])


def _checkpoints(out: Path, fingerprint: str) -> list[tuple[int, Path]]:
    """(step, restart file) of an earlier, killed attempt at this same input, newest first."""
    folder = out / CHECKPOINT_DIR
    stamp = folder / "input.sha256"
    if not stamp.is_file() or stamp.read_text() != fingerprint:
        return []
    found = [(int(p.name.split(".")[1]), p) for p in folder.glob("travel.*.restart")]
    return sorted(found, reverse=True)


#: What a spreading run leaves out because its scene does not need it (README:
#: skips): the wait for a fixed duration once the layer is at rest, the powder
#: pushed past the stopped roller, and every dump but the final one. (Settling
#: once per replicate is the workflow's: rules/simulate.smk.) The empty set is
#: the "no skips" baseline of benchmarks/bench_skips.py.
SKIPS = frozenset({"stop_at_rest", "remove_ahead", "final_dump_only"})


#: Dump interval [s of simulated time] of the baseline without ``final_dump_only``.
BASELINE_DUMP_EVERY_S = 0.002


@dataclass(frozen=True)
class SpreadPlan:
    """A spread ready to run (:func:`plan_spread`): its scene, where the roller starts and how long it
    travels, the feed's top-ups, and what the input template is rendered with (:meth:`render`)."""
    s: Scene
    out: Path               # the run folder
    meshes: Path
    settled: Path
    U_mm_s: float
    omega_rad_s: float
    speed: float            # U [m/s]
    x0: float               # the roller axis' start [m]
    travel_steps: int       # steps of the longest travel (to ``s.travel_end_max``)
    fixed_steps: int        # steps of the travel before the roller may stop (to ``s.travel_end``)
    checks: list            # steps after it at which it stops if the region's layer is laid (inputs.stop_checks)
    gap: dict               # :func:`geometry.roller_gap`: the axis height and the gap as built
    settled_particles: int  # particles of the settled heap
    first_fed_id: int       # the id of the first particle the feed adds
    feeds: list             # travel steps of the feed's top-ups (empty: no feed)
    feed: dict | None       # the feed's template values
    wall_speed: float       # the roller surface's fastest speed [m/s]
    skips: frozenset
    context: dict           # what every rendering of ``spread.in.j2`` shares

    @property
    def squeeze_out_speed(self) -> float:
        """The speed [m/s] a particle leaves an overlap of a radius with (:func:`squeeze_out_speed`):
        with ``wall_speed``, what the run's blow-up limit is made of, during the run and after it."""
        s = self.s
        return squeeze_out_speed(s.density, s.youngs_modulus, s.poisson_ratio)

    def render(self, step: int = 0, restart: Path | None = None) -> str:
        """``spread.in``: the input starting at ``step`` of the travel (0: from the settled heap), from
        ``restart`` (a checkpoint) when resumed."""
        s, feed = self.s, self.feed
        elapsed = step * s.timestep
        segments = travel_segments(self.travel_steps, checkpoint_plan(self.fixed_steps, s.checkpoints_per_run, step),
                                   self.feeds, step, self.checks)
        for seg in segments:
            if seg["feed"]:
                seg["zone"] = feed_zone(s, self.x0 + self.speed * seg["start"] * s.timestep, feed["floor"],
                                        self.gap["axis_z_m"])
                seg["seed"] = feed["seeds"][seg["start"]]
            # the laid layer before the region that the roller has left behind (freeze_lag_mm)
            cut = None if s.freeze_lag is None else min(s.freeze_x_max, self.step_x(seg["end"]) - s.freeze_lag)
            seg["freeze_x"] = cut if cut is not None and cut > s.box[0] else None
        return render("spread.in.j2", resume=restart and input_path(restart, self.out), resume_step=step,
                      sfx="_resumed" if step else "",
                      roller_x=self.x0 + self.speed * elapsed,
                      roller_angle_deg=np.degrees(abs(self.omega_rad_s) * elapsed) % 360,
                      segments=segments, feed=feed, **self.context)

    def step_x(self, step: int) -> float:
        """x [m] of the roller axis at ``step`` of the travel."""
        return self.x0 + self.speed * step * self.s.timestep


def plan_spread(config: dict, level: str, U_mm_s: float, omega_rad_s: float, meshes: str | Path,
                settled: str | Path, outdir: str | Path, movie_every: int = 0, skips=SKIPS,
                replicate: int = 0) -> SpreadPlan:
    """The spread of :func:`spread`, planned but not run: the speeds, the meshes and the settled heap
    checked, the roller placed behind the heap, the travel and the feed laid out. Nothing is written;
    ``plan_spread(...).render()`` is the ``spread.in`` a fresh run starts from."""
    s, out = scene(config, level), Path(outdir)
    meshes, settled = Path(meshes).resolve(), Path(settled).resolve()
    if not (math.isfinite(U_mm_s) and U_mm_s > 0 and math.isfinite(omega_rad_s)):
        raise ConfigError(f"spreader speeds U = {U_mm_s} mm/s, omega = {omega_rad_s} rad/s: U must be a positive "
                          "finite number, omega a finite one")
    need_files((meshes / "substrate.stl", "the geometry step's substrate: --meshes"),
               (meshes / "roller_shell.stl", "the geometry step's roller: --meshes"),
               (settled / "settled.restart", "the settled heap: --settled"),
               (settled / "settled.dump", "the settled heap: --settled"))
    speed = U_mm_s * 1e-3
    substrate = geometry.load_stl(meshes / "substrate.stl")
    peak = float(substrate.vertices[:, 2].max())
    gap = geometry.roller_gap(s, substrate, geometry.load_stl(meshes / "roller_shell.stl"))
    # a swept gap spreads over the substrate made under roller.gap_um
    if peak >= gap["axis_z_m"] - gap["circumradius_m"]:
        raise ConfigError(f"config key 'roller.gap_um' = {s.roller_gap * 1e6:g}: the substrate's highest peak "
                          f"({peak * 1e6:.0f} um) reaches the roller")
    atoms0 = read_dump(settled / "settled.dump").atoms
    x0 = geometry.roller_start(atoms0, s, axis_z=gap["axis_z_m"])
    if x0 - s.roller_radius <= s.box[0]:
        raise LiggghtsError(f"roller start x = {x0:.4g} m puts the roller outside the box (x >= {s.box[0]:.4g} m)")
    fixed_steps, checks, travel_steps = stop_checks(s, x0, speed)
    if not 1 <= travel_steps <= MAX_RUN_STEPS:
        raise ConfigError(f"spreader speed U = {U_mm_s:g} mm/s: the travel takes {travel_steps:.3g} time steps of "
                          f"{s.timestep:.3g} s; a LIGGGHTS run takes 1 to {MAX_RUN_STEPS}")
    unknown = set(skips) - SKIPS
    if unknown:
        raise ValueError(f"unknown skip(s) {sorted(unknown)}; known: {sorted(SKIPS)}")
    if not movie_every and "final_dump_only" not in skips:
        movie_every = max(1, round(BASELINE_DUMP_EVERY_S / s.timestep))
    motion = roller_motion(speed, omega_rad_s, s.roller_radius)
    heap_toe = float((atoms0["x"] + atoms0["radius"]).max())
    feeds = feed_plan(s, x0, speed, travel_steps, heap_toe)  # (those after where the roller stops are not run)
    feed, fall_height = None, 0.0
    first_fed_id = int(atoms0["id"].max()) + 1
    if feeds:
        floor = peak + max(s.diameters) / 2
        feed_seeds = liggghts_seeds(config["random_seed"] + 1000 * replicate + 500, len(s.diameters) + 1 + len(feeds))
        feed = {"mass": s.feed_pile_mass, "floor": floor, "template_seeds": feed_seeds[:len(s.diameters) + 1],
                "seeds": dict(zip(feeds, feed_seeds[len(s.diameters) + 1:])),
                "id_offset": first_fed_id - 1 - len(atoms0),
                "trace": s.mean_particle_mass}
        fall_height = feed_zone(s, x0, floor, gap["axis_z_m"])["z1"] - floor
    wall_speed = speed + abs(omega_rad_s) * s.roller_radius
    context = dict(s=s, contact=contact_model(s), box=[f"{v:.6g}" for v in s.box], U_mm_s=U_mm_s,
                   omega_rad_s=omega_rad_s, motion=motion, restart=input_path(settled / "settled.restart", out),
                   skin=skin(s),
                   binsize=binsize(s), thermo_every=THERMO_EVERY, processors=processors_grid(s),
                   substrate_stl=input_path(meshes / "substrate.stl", out),
                   roller_stl=input_path(meshes / "roller_shell.stl", out),
                   roller_z=gap["axis_z_m"], fixed_steps=fixed_steps, checks=checks,
                   laid_ke=0.5 * s.mean_particle_mass * s.laid_speed**2,
                   roller_x0=x0, step_dx=speed * s.timestep,
                   **rest_loop(s, s.rest_time, stop_at_rest="stop_at_rest" in skips),
                   remove_ahead="remove_ahead" in skips,
                   freeze=None if s.freeze_lag is None else {"band": FROZEN_BAND_DIAMETERS * max(s.diameters)},
                   laid_dir=LAID_DIR,
                   movie_every=movie_every, movie="movie.dump",
                   squeeze_speed=squeeze_threshold(wall_speed, fall_height), squeeze={"factor": SQUEEZE_FACTOR},
                   dump="final.dump.part", checkpoint_dir=CHECKPOINT_DIR)
    return SpreadPlan(s=s, out=out, meshes=meshes, settled=settled, U_mm_s=U_mm_s, omega_rad_s=omega_rad_s,
                      speed=speed, x0=x0, travel_steps=travel_steps, fixed_steps=fixed_steps, checks=checks,
                      gap=gap, settled_particles=len(atoms0),
                      first_fed_id=first_fed_id, feeds=feeds, feed=feed, wall_speed=wall_speed,
                      skips=frozenset(skips), context=context)


def run_with_resume(plan: SpreadPlan) -> dict:
    """Run the plan's ``spread.in`` in its folder and return LIGGGHTS' log (:func:`run`).

    With ``checkpoints_per_run`` > 0, LIGGGHTS writes restart files to ``checkpoint/`` during the
    travel, stamped with the fresh input's hash; a later call for the same input resumes from the
    newest one that loads (e.g. after a cluster's time limit killed the job). A checkpoint that fails
    to load is skipped; a fresh start clears the checkpoints and feed records of any other input."""
    out, s = plan.out, plan.s
    fresh = plan.render(0, None)
    fingerprint = hashlib.sha256(fresh.encode()).hexdigest()
    limit = blowup_limit(plan.wall_speed, plan.squeeze_out_speed)
    for step, restart in _checkpoints(out, fingerprint) + [(0, None)]:
        if restart is None:  # a fresh start: forget any other input's checkpoints and feed records
            for folder in (CHECKPOINT_DIR, FEED_DIR, LAID_DIR):
                shutil.rmtree(out / folder, ignore_errors=True)
                (out / folder).mkdir()
            (out / CHECKPOINT_DIR / "input.sha256").write_text(fingerprint)
        else:
            forget_drops_after(out, step)
        (out / "spread.in").write_text(fresh if restart is None else plan.render(step, restart))
        try:
            return ran(run(out / "spread.in", out / "spread.log", ranks=s.mpi_ranks, abort_speed=limit),
                       out / "spread.in")
        except UnstableRunError:  # the physics, not the checkpoint: an older one would blow up too
            raise
        except LiggghtsError as err:
            if restart is None:
                raise
            print(f"warning: resuming from {restart} failed, trying an older checkpoint or a fresh start:\n{err}",
                  file=sys.stderr)
    raise AssertionError("unreachable: the fresh start returns or raises")


def check_spread(plan: SpreadPlan, log: dict) -> dict:
    """The health of a finished spread (its log and ``final.dump.part``) and its cost: the summary
    ``health.json`` holds. An unsound run raises :class:`~analysis.dem.liggghts.LiggghtsError`."""
    s, out, skips = plan.s, plan.out, plan.skips
    check_timestep(log, s)
    health = check_kinetic_energy(log, wall_speed=plan.wall_speed, squeeze_speed=plan.squeeze_out_speed)
    health.update(inrun_health(log, s))
    if not (out / "final.dump.part").is_file():
        tail = "\n".join((out / "spread.log.screen").read_text(errors="replace").strip().splitlines()[-8:])
        raise LiggghtsError(f"LIGGGHTS ended (exit 0, no ERROR line) without writing {out / 'final.dump.part'}; "
                            f"last screen lines:\n{tail}")
    restored, intruders = restore_dropped(out)
    atoms = read_dump(out / "final.dump.part").atoms
    stop = int(log["printed"]["roller_stop_step"])  # where the roller stopped (layer_laid)
    inside = through_roller(atoms, plan.step_x(stop), plan.context["roller_z"], s.roller_radius)
    if inside:
        raise UnstableRunError(f"unsound run: {inside} particles passed through the roller (centre inside it): "
                            "lower the time step or stiffen the particles")
    ahead = int(log["printed"]["particles_ahead_of_roller"])
    # the powder ahead of the stopped roller, and what rolled on under it during the rest phase
    removed = ahead + int(log["printed"]["escaped_past_roller"]) if "remove_ahead" in skips else 0
    # particles fed before a resumed attempt are in its first thermo row
    fed = int(log["thermo"]["Atoms"].iloc[0]) - plan.settled_particles + int(log["inserted"])
    expected = plan.settled_particles + fed - removed - intruders
    health.update(through_roller=inside, fed_particles=fed,
                  **layer_health(atoms, s, plan.meshes / "substrate.stl", expected,
                                 roller=(plan.step_x(stop), plan.context["roller_z"], s.roller_radius)))
    health.update(heap_supply(ahead, s.heap_particles), removed_ahead_of_roller=removed,
                  mass_ahead_of_roller_kg=float(log["printed"]["mass_ahead_of_roller_kg"]))
    feeds = [f for f in plan.feeds if f < stop]
    if feeds:
        landings = feed_landings(out / FEED_DIR, log["printed"], plan.step_x,
                                 dict(zip(feeds, feeds[1:] + [stop])))
        landings.to_csv(out / "feed_landings.csv", index=False)
        health.update(feed_topups=len(feeds),
                      feed_pile_min_fraction=feed_pile_fraction(log["printed"], s.feed_pile_mass),
                      **feed_health(landings, atoms, plan.first_fed_id, s.sampling_region))
    laid_checks = [k for k in log["printed"] if k.startswith("laid_check_")]
    thermo = log["thermo"]
    first, last = int(thermo["Step"].iloc[0]), int(thermo["Step"].iloc[-1])
    # particle-steps of every particle integrated during the run (the pile included, the frozen not), per CPU second
    integrated = thermo["Atoms"].to_numpy() - (thermo["frozen"].to_numpy() if "frozen" in thermo else 0)
    particle_steps = float(np.sum(np.diff(thermo["Step"].to_numpy()) * integrated[1:]))
    return {"U_mm_s": plan.U_mm_s, "omega_rad_s": plan.omega_rad_s, "wall_s": log["wall_s"], "cpu_s": log["cpu_s"],
            "steps": last, "resumed_from_step": first, "timestep_s": s.timestep, "ranks": s.mpi_ranks,
            "mpi_launcher": log["launcher"], "processors": plan.context["processors"],
            "roller_start_m": plan.x0, "roller_travel_m": plan.speed * stop * s.timestep,
            "run_out_m": plan.step_x(stop) - s.sampling_region[1], "layer_laid_checks": len(laid_checks),
            "layer_laid_at_stop": bool(plan.checks) and stop < plan.travel_steps,
            "rayleigh_fraction": log["measured_max_rayleigh_fraction"],
            "hertz_fraction": log["measured_max_hertz_fraction"],
            "frozen_particles": restored + (int(thermo["frozen"].iloc[-1]) if "frozen" in thermo else 0),
            "freeze_intruders_removed": intruders,
            "particle_steps": particle_steps, "particle_steps_per_s": particle_steps / max(log["cpu_s"], 1e-9),
            **{f"time_{part}_s": seconds for part, seconds in log["timing_s"].items()},
            **{k: v for k, v in plan.gap.items() if k != "circumradius_m"}, **health}


def spread(config: dict, level: str, U_mm_s: float, omega_rad_s: float, meshes: str | Path,
           settled: str | Path, outdir: str | Path, movie_every: int = 0, skips=SKIPS, replicate: int = 0) -> dict:
    """Spread the settled heap at ``U_mm_s`` [mm/s] and ``omega_rad_s`` [rad/s]: plan it
    (:func:`plan_spread`), run it, resuming a killed attempt (:func:`run_with_resume`), check it
    (:func:`check_spread`).

    Writes ``spread.in``, ``spread.log``, ``final.dump`` and ``health.json``
    into ``outdir`` and returns the health figures (with wall time and steps).

    With ``checkpoints_per_run`` > 0 in the fidelity level, LIGGGHTS writes
    restart files to ``outdir/checkpoint/`` during the travel; a later call
    for the same input (same rendered text) resumes from the newest one that
    loads, e.g. after a cluster's time limit killed the job. Continuing the
    roller's motion from a restart is LIGGGHTS' own (``fix move/mesh`` stores
    it); a checkpoint that fails to load is skipped, and the run starts over.

    With ``feed_pile_mg_per_mm`` in the fidelity level, the pile ahead of the
    roller is topped up to that mass every ``feed_every_mm`` of travel
    (:func:`feed_plan`, :func:`feed_zone`): the layer is laid from a pile of
    a set size, however much the roller lays; ``fed_particles`` in the
    health counts what was added. ``replicate`` seeds the feed.

    A run that breaks down (:class:`~analysis.dem.liggghts.UnstableRunError`: a kinetic-energy
    blow-up, particles through the roller) runs once more from the start at
    ``timestep.unstable_retry_fraction`` of the Rayleigh time; ``health.json`` records it
    (``unstable_retries``, ``unstable_error``, ``timestep_s``). A second breakdown is refused.
    """
    plan = plan_spread(config, level, U_mm_s, omega_rad_s, meshes, settled, outdir, movie_every, skips, replicate)
    out = plan.out
    out.mkdir(parents=True, exist_ok=True)
    try:
        summary = check_spread(plan, run_with_resume(plan))
        summary.update(unstable_retries=0, unstable_error="")
    except UnstableRunError as err:
        step = config["timestep"]
        retry = step.get("unstable_retry_fraction")
        if retry is None or retry >= step["rayleigh_fraction"]:
            raise
        print(f"warning: {err}\nrunning it again from the start at timestep.unstable_retry_fraction = {retry:g} "
              f"of the Rayleigh time (was {step['rayleigh_fraction']:g})", file=sys.stderr)
        config = resolve(config, {"timestep.rayleigh_fraction": retry})
        plan = plan_spread(config, level, U_mm_s, omega_rad_s, meshes, settled, outdir, movie_every, skips,
                           replicate)
        summary = check_spread(plan, run_with_resume(plan))
        summary.update(unstable_retries=1, unstable_error=str(err).splitlines()[0])
    _publish(out, summary, "final.dump")
    for folder in (CHECKPOINT_DIR, FEED_DIR, LAID_DIR):
        shutil.rmtree(out / folder, ignore_errors=True)
    for forced in out.glob("restart_forced_liggghts_*.data"):  # LIGGGHTS' own, written when a kill stopped it
        forced.unlink()
    return summary


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Run one step of a spreading scene with LIGGGHTS.")
    parser.add_argument("step", choices=["geometry", "settle", "spread"])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--level", help="fidelity level (default: the config's `level`)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--meshes", type=Path)
    parser.add_argument("--settled", type=Path)
    parser.add_argument("--U", type=float, help="spreader translation speed, mm/s")
    parser.add_argument("--omega", type=float, help="roller angular speed, rad/s (+: counter-rotation)")
    parser.add_argument("--replicate", type=int, default=0, help="replicate: its heap, substrate and feed seeds")
    args = parser.parse_args(argv)
    try:
        config = load_config(args.config)
        level = args.level or config["level"]
        if args.step == "geometry":
            result = make_geometry(config, level, args.out, base_dir=args.config.parent, replicate=args.replicate)
        elif args.step == "settle":
            result = settle(config, level, args.meshes, args.out, replicate=args.replicate)
        else:
            if args.U is None or args.omega is None:
                parser.error("spread needs --U and --omega")
            result = spread(config, level, args.U, args.omega, args.meshes, args.settled, args.out,
                            replicate=args.replicate)
    except USER_ERRORS as err:
        print(f"spreadmap-simulate: error: {error_line(err)}", file=sys.stderr)
        return 2 if isinstance(err, ConfigError) else 1
    print(json.dumps(result, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
