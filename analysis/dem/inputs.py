"""What a LIGGGHTS input of one scene needs besides the config: seeds, the
contact model, neighbour bins and skin, the MPI grid, and the plans of the
spreading pass (checkpoints, feeds of the pile, travel segments). Plain
functions of a :class:`~analysis.config.fidelity.Scene`, in SI units; the templates in
``templates/`` print what they return.
"""
from __future__ import annotations

from math import ceil, sqrt

import numpy as np

from analysis.config.fidelity import Scene
from analysis.physics import liggghts_seeds

THERMO_EVERY = 1000


def seeds(config: dict, s: Scene, replicate: int = 0) -> list[int]:
    """LIGGGHTS seeds of a replicate: one per size class, the distribution, the insertion."""
    return liggghts_seeds(config["random_seed"] + 1000 * replicate, len(s.diameters) + 2)


def contact_model(s: Scene) -> str:
    """The granular contact model: Hertz with tangential history, plus rolling
    friction and cohesion only where their coefficients are non-zero."""
    model = "model hertz tangential history"
    if s.rolling_friction > 0:
        model += " rolling_friction epsd2"
    if s.cohesion_energy_density > 0:
        model += " cohesion sjkr"
    return model


SKIN_DIAMETERS = 0.2


REST_CHUNK_S = 0.005  # [s] between two at-rest checks


def rest_loop(s: Scene, max_time: float, stop_at_rest: bool = True) -> dict:
    """Template values for ``_until_rest.j2``: chunks of REST_CHUNK_S up to ``max_time``,
    stopping early (``stop_at_rest``) once the kinetic energy per particle [J] is
    that of the RMS speed ``rest_rms_speed_mm_s``."""
    chunk = THERMO_EVERY * max(1, round(REST_CHUNK_S / s.timestep / THERMO_EVERY))
    return {"chunk_steps": chunk, "max_chunks": max(1, ceil(max_time / (chunk * s.timestep))),
            "rest_speed": s.rest_speed, "rest_ke": 0.5 * s.mean_particle_mass * s.rest_speed**2,
            "stop_at_rest": stop_at_rest}


def binsize(s: Scene) -> float:
    """Neighbour bin size [m]: the neighbour cutoff (largest diameter + skin).

    Each rebuild tests every particle in the bins a mesh facet's box touches,
    and the rotating roller forces a rebuild every ~10-20 steps: these bins
    are 9 % faster than bins of 4 largest diameters, and LIGGGHTS' own (half
    the cutoff) 28 % slower than those (benchmarks/measured/spread_profile.md)."""
    return max(s.diameters) + skin(s)


def skin(s: Scene) -> float:
    """Neighbour-list skin [m]: 20 % of the mean class diameter. Each particle
    checks every substrate triangle within its radius + skin, every step."""
    return SKIN_DIAMETERS * float(np.mean(s.diameters))


def processors_grid(s: Scene) -> str:
    """LIGGGHTS ``processors`` grid for ``s.mpi_ranks`` ranks.

    The powder is a thin bed under a box as tall as the roller, so z is never
    split. LIGGGHTS 3.8 has no load balancing (no ``balance`` command), and
    along the travel the particles crowd into the heap: a cut across x leaves
    ranks idle. A narrow periodic strip is uniform across its width, so it is
    cut across y into equal shares, each at least the ghost cutoff (largest
    diameter + skin) wide; a wide scene (the paper level) lets LIGGGHTS
    choose the grid in x and y.
    """
    slab = max(s.diameters) + skin(s)  # the ghost cutoff
    if s.mpi_ranks <= 1:
        return "1 1 1"
    if s.strip_width / s.mpi_ranks >= slab and s.strip_width < 0.1 * (s.box[1] - s.box[0]):
        return f"1 {s.mpi_ranks} 1"
    return "* * 1"


def checkpoint_plan(travel_steps: int, count: int, resume_step: int = 0) -> list[tuple[int, int | None]]:
    """(step, previous checkpoint's step) of the checkpoints still to write after ``resume_step``:
    ``count`` evenly spaced over the travel (none at its end)."""
    if not count:
        return []
    every = ceil(travel_steps / (count + 1))
    steps = [k * every for k in range(1, count + 1) if resume_step < k * every < travel_steps]
    return list(zip(steps, [resume_step or None] + steps[:-1]))


def feed_plan(s: Scene, x0: float, speed: float, travel_steps: int, heap_toe: float) -> list[int]:
    """Steps of the travel at which a fed pile is topped up: every ``s.feed_every`` [m]
    of travel (``feed_every_mm``), from the step at which the feed zone (``s.feed_length`` ahead of the
    roller axis, which starts at ``x0`` [m]) first covers the settled heap's toe
    ``heap_toe`` [m], so the heap itself is counted before anything is added.
    Empty without a feed."""
    if s.feed_pile_mass is None:
        return []
    every = max(1, round(s.feed_every / (speed * s.timestep)))
    first = max(0, ceil((heap_toe - s.feed_length - x0) / (speed * s.timestep)))
    return list(range(first, travel_steps, every))


#: The pile's front is where it is at least this many mean diameters deep: single
#: particles rolled ahead on the bed are not the pile.
PILE_FRONT_DEPTH_DIAMETERS = 1.0


#: Fed particles are placed at most this many largest diameters ahead of the pile's front: on
#: its front slope and toe, where a forward-rolling roller, which packs the pile into the wedge
#: under it, leaves the only free room (docs/scene.md: Feed).
FEED_AHEAD_OF_FRONT_DIAMETERS = 1.0


def feed_zone(s: Scene, x_axis: float, floor: float, axis_z: float) -> dict:
    """The feed zone [m] when the roller axis is at ``x_axis`` (height ``axis_z``).

    ``pile``: the wedge between the bed (from ``floor``, above the substrate's highest
    point) and the roller, from its axis to ``s.feed_length`` ahead: the pile is the powder
    there. ``body``: its part at least :data:`PILE_FRONT_DEPTH_DIAMETERS` mean diameters
    above the floor; the pile's front is the farthest particle in it, measured by LIGGGHTS at
    each top-up. New particles are placed at rest in free places of the wedge from the axis
    to :data:`FEED_AHEAD_OF_FRONT_DIAMETERS` largest diameters ahead of that front (``ahead``),
    clear of the roller (a cylinder of its radius plus the largest particle's), so they land
    on the pile or its toe, never on bare bed farther ahead; ``x1`` bounds that reach from above."""
    r = s.roller_radius
    top = axis_z - sqrt(r**2 - s.feed_length**2)
    d_max = max(s.diameters)
    clear = r + d_max / 2
    # the zone reaches at least where a largest particle fits under the roller (insert/pack
    # needs a region with room in it), however short the pile
    room = sqrt(max(clear**2 - (axis_z - floor - d_max) ** 2, 0.0))
    return {"x0": x_axis, "x1": x_axis + s.feed_length, "z0": floor, "z1": top,
            "body_z0": floor + PILE_FRONT_DEPTH_DIAMETERS * float(np.mean(s.diameters)),
            "ahead": FEED_AHEAD_OF_FRONT_DIAMETERS * d_max, "min_x1": x_axis + min(room, s.feed_length),
            "axis_z": axis_z, "radius": clear}


def stop_checks(s: Scene, x0: float, speed: float) -> tuple[int, list[int], int]:
    """Where a roller starting at ``x0`` [m] and moving at ``speed`` [m/s] stops: the steps of its
    fixed travel (to ``s.travel_end``), of the checks after it (every ``s.laid_check_every`` [m],
    before ``s.travel_end_max``) at which it stops once the sampling region's layer is laid
    (``layer_laid``), and of its longest travel (to ``s.travel_end_max``). No checks when the
    level's stop is fixed."""
    fixed = ceil((s.travel_end - x0) / speed / s.timestep)
    last = ceil((s.travel_end_max - x0) / speed / s.timestep)
    every = max(1, round(s.laid_check_every / (speed * s.timestep)))
    return fixed, list(range(fixed, last, every)) if last > fixed else [], last


def travel_segments(travel_steps: int, checkpoints: list, feeds: list, resume_step: int = 0,
                    checks: list = ()) -> list[dict]:
    """The travel after ``resume_step`` cut at every checkpoint, feed step and stop check: a list of
    ``{"end", "feed", "checkpoint", "check"}`` in order; ``feed`` is true if the pile is topped up at
    the segment's start, ``checkpoint`` the ``(step, previous)`` written at its end or None, ``check``
    true if the roller may stop at its end (:func:`stop_checks`)."""
    at_end = {step: (step, previous) for step, previous in checkpoints}
    feeds = [f for f in feeds if f >= resume_step]
    checks = {c for c in checks if c > resume_step}
    cuts = sorted(set(at_end) | {f for f in feeds if f > resume_step} | checks | {travel_steps})
    segments, start = [], resume_step
    for end in cuts:
        segments.append({"start": start, "end": end, "feed": start in feeds, "checkpoint": at_end.get(end),
                         "check": end in checks})
        start = end
    return segments
