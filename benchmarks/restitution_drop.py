"""A single sphere dropped on a flat substrate, through the same material and
contact templates as the spreading scene: checks that the material reaches
LIGGGHTS with the right units (free-fall time, coefficient of restitution)."""
from __future__ import annotations

from dataclasses import replace
from math import ceil, sqrt
from pathlib import Path

import numpy as np

from analysis.config.fidelity import Scene
from analysis.dem import geometry
from analysis.dem.inputs import contact_model, skin
from analysis.dem.liggghts import render, run

GRAVITY = 9.81


def drop_sphere(s: Scene, outdir: str | Path, diameter: float, height: float, duration: float,
                print_every: int = 5) -> dict:
    """Drop a sphere of ``diameter`` [m] from ``height`` [m] (gap between its
    bottom and the plane z = 0) for ``duration`` [s].

    Returns ``t`` [s], ``z`` [m] and ``vz`` [m/s] traces and the log.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    width = 4 * diameter
    flat = geometry.rough_substrate((-width, width), width, width / 4, width, 0.0, 0)
    geometry.write_stl(flat, out / "flat.stl")
    flat_scene = replace(s, rolling_friction=0.0)  # no rolling in a normal impact
    box = [-width, width, 0.0, width, -diameter, height + 2 * diameter]
    text = render("drop.in.j2", s=flat_scene, contact=contact_model(flat_scene), box=box, skin=skin(s),
                  thermo_every=1000, substrate_stl="flat.stl", diameter=diameter,
                  position=[0.0, width / 2, height + diameter / 2], steps=ceil(duration / s.timestep),
                  print_every=print_every, trace="trace.txt")
    (out / "drop.in").write_text(text)
    log = run(out / "drop.in", out / "drop.log")
    z, vz = np.loadtxt(out / "trace.txt", skiprows=1, unpack=True)
    t = np.arange(len(z)) * print_every * s.timestep
    return {"t": t, "z": z, "vz": vz, "log": log}


def first_bounce(t, z, vz, radius: float) -> dict:
    """Impact time [s] and the coefficient of restitution of the first bounce:
    speed leaving the plane over speed reaching it (gravity during the
    contact, a few microseconds, is negligible)."""
    contact = z < radius
    first = int(np.argmax(contact))
    after = first + int(np.argmax(~contact[first:]))
    return {"impact_time": t[first], "v_in": -vz[first - 1], "v_out": vz[after],
            "restitution": vz[after] / -vz[first - 1]}


def free_fall_time(height: float) -> float:
    return sqrt(2 * height / GRAVITY)
