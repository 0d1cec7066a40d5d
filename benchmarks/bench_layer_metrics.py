"""Benchmark of analysis.metrics.profilometer: time and peak memory vs particles and probes.

Run from the repository root::

    .venv/bin/python benchmarks/bench_layer_metrics.py

A layer of polydisperse spheres (Gaussian radii, mean 87.5 um, sd 12.5 um,
cut to 50-125 um) is scattered over a 25 mm x 25 mm sampling region and
the full `spread_layer_metrics` call is timed (probe lines, substrate, layer
top, metrics), best of a few runs; peak memory is the peak of memory traced
by ``tracemalloc`` (NumPy's allocations included) in a separate run. The
requirement is the 100k-particle, 1000 x 1000-probe case under 3 s on one
core. Prints a Markdown table and writes it, with the machine, to
``benchmarks/measured/layer_metrics.md``; exits 1 if the requirement fails.
"""

import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.metrics.dump import read_dump, write_dump  # noqa: E402
from analysis.metrics.spread_layer import spread_layer_metrics  # noqa: E402
from benchmarks.machine import machine  # noqa: E402

SIDE = 25e-3  # region side [m]
REGION = (0.0, SIDE, 0.0, SIDE)
SPEED, DENSITY = 0.05, 4430.0  # [m/s], [kg/m3]
LIMIT_S = 3.0  # requirement for the 100k / 1000-line case [s]
# (particles, lines, substrate)
CASES = [
    (10_000, 1000, "flat"),
    (100_000, 1000, "flat"),
    (400_000, 1000, "flat"),
    (100_000, 100, "flat"),
    (100_000, 2000, "flat"),
    (100_000, 1000, "stl"),
]
OUT = ROOT / "benchmarks" / "measured" / "layer_metrics.md"


def polydisperse_layer(n, seed=0):
    """n spheres [m] over the region, about 5 particle layers per 100k."""
    rng = np.random.default_rng(seed)
    r = rng.normal(87.5e-6, 12.5e-6, 2 * n)
    r = r[(r >= 50e-6) & (r <= 125e-6)][:n]
    depth = 0.8e-3 * n / 100_000
    return pd.DataFrame({
        "id": np.arange(1, n + 1),
        "x": rng.uniform(-100e-6, SIDE + 100e-6, n),
        "y": rng.uniform(-100e-6, SIDE + 100e-6, n),
        "z": r + rng.uniform(0, depth, n),
        "radius": r,
    })


def wavy_substrate(path, cells=250):
    """A sinusoidal height-field STL over the region, ``2 cells^2`` triangles [m]."""
    import trimesh

    g = np.linspace(-0.5e-3, SIDE + 0.5e-3, cells + 1)
    gx, gy = np.meshgrid(g, g, indexing="ij")
    z = 40e-6 * np.sin(2 * np.pi * gx / 2e-3) * np.cos(2 * np.pi * gy / 3e-3)
    idx = np.arange(gx.size).reshape(gx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    trimesh.Trimesh(np.column_stack([gx.ravel(), gy.ravel(), z.ravel()]), faces, process=False).export(path)
    return path, len(faces)


def measure(fn, repeats):
    """Best wall time of ``repeats`` calls [s], and peak traced memory of one call [MB]."""
    best = min(_timed(fn) for _ in range(repeats))
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return best, peak / 2**20


def _timed(fn):
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def main():
    rows, verdict = [], None
    with tempfile.TemporaryDirectory() as tmp:
        stl, n_faces = wavy_substrate(Path(tmp) / "substrate.stl")
        layers = {}
        for n, lines, sub in CASES:
            atoms = layers.setdefault(n, polydisperse_layer(n))
            substrate = str(stl) if sub == "stl" else None

            def run(atoms=atoms, substrate=substrate, lines=lines):
                return spread_layer_metrics(atoms, REGION, SPEED, DENSITY, substrate=substrate, n_lines=lines)

            seconds, peak = measure(run, repeats=3 if n * lines <= 1e8 else 1)
            label = f"STL, {n_faces:,} triangles" if sub == "stl" else "flat plane"
            rows.append(f"| {n:,} | {lines} x {lines} | {label} | {seconds:.3f} | {peak:.0f} |")
            print(rows[-1], flush=True)
            if (n, lines, sub) == (100_000, 1000, "flat"):
                verdict = seconds
        dump = Path(tmp) / "layer.dump"
        write_dump(dump, layers[100_000], [[-1e-3, SIDE + 1e-3]] * 2 + [[0, 2e-3]])
        read_s, read_mb = measure(lambda: read_dump(dump), repeats=3)

    ok = verdict < LIMIT_S
    table = "\n".join([
        "| particles | probe lines | substrate | time [s] | peak traced memory [MB] |",
        "|---:|---:|---|---:|---:|",
        *rows,
    ])
    text = f"""# Benchmark: spread-layer metrics (`analysis/metrics/spread_layer.py`)

Machine: {machine()}. One process, threads as the environment left them.
Measured by `.venv/bin/python benchmarks/bench_layer_metrics.py`: the whole
`spread_layer_metrics` call over a 25 mm x 25 mm region, polydisperse spheres
(radii 50-125 um, Gaussian), best of 3 runs (1 run for the 400k-particle and
2000-line cases); peak memory traced by `tracemalloc` in a separate run. The
STL case includes loading the STL file (binary, sinusoidal height field).
Cost grows linearly with particles x probes per particle (sphere-probe pairs)
plus the probe grid itself.

{table}

Reading the 100,000-particle dump (`read_dump`, {dump.name} plain text): {read_s:.3f} s, {read_mb:.0f} MB peak.

Requirement, 100,000 particles and 1000 x 1000 probes under {LIMIT_S:.0f} s: \
{'met' if ok else 'NOT met'} ({verdict:.3f} s).
"""
    print(f"\nread_dump, 100k particles: {read_s:.3f} s, {read_mb:.0f} MB")
    print(f"100k / 1000 lines: {verdict:.3f} s ({'OK' if ok else 'FAIL'}, limit {LIMIT_S} s)")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
