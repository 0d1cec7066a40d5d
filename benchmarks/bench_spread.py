"""Cost of one spreading run per fidelity level, measured through real LIGGGHTS.

Usage: .venv/bin/python benchmarks/bench_spread.py [LEVEL ...]   (default: smoke default)

For each level: make the geometry, settle the heap, spread it once at
U = 70 mm/s with omega = 0 and -10 rad/s (rotation costs extra); writes a
Markdown table with machine and date to benchmarks/measured/spread_cost.md.
"""
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.load import load_config  # noqa: E402
from analysis.dem.simulate import make_geometry, settle, spread  # noqa: E402
from benchmarks.machine import cpu_model  # noqa: E402


def main(levels):
    config = load_config(ROOT / "config.yaml")
    rows = ["| level | run | particles | time steps | wall s | particle-steps/s |", "|---|---|---:|---:|---:|---:|"]
    for level in levels:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            make_geometry(config, level, tmp / "meshes")
            h = settle(config, level, tmp / "meshes", tmp / "settle")
            rows.append(f"| {level} | settle | {h['atoms']} | {h['steps']} | {h['wall_s']:.1f} | "
                        f"{h['atoms'] * h['steps'] / h['wall_s']:.3g} |")
            for omega in (0.0, -10.0):
                r = spread(config, level, 70.0, omega, tmp / "meshes", tmp / "settle", tmp / f"run{omega:g}")
                rows.append(f"| {level} | spread U=70 mm/s, omega={omega:g} rad/s | {r['atoms']} | {r['steps']} | "
                            f"{r['wall_s']:.1f} | {r['particle_steps_per_s']:.3g} |")
            print("\n".join(rows[-3:]), flush=True)
    text = (f"# Cost of one spreading run\n\nMeasured {time.strftime('%Y-%m-%d')} on {platform.machine()}, "
            f"{cpu_model()}, one run at a time on one core (LIGGGHTS 3.8.0, Debian), "
            f"by `.venv/bin/python benchmarks/bench_spread.py {' '.join(levels)}`.\n\n" + "\n".join(rows) + "\n")
    out = ROOT / "benchmarks/measured/spread_cost.md"
    out.write_text(text)
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["smoke", "default"])
