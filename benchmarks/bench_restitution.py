"""Realised coefficient of restitution against the time step, through real LIGGGHTS.

Usage: .venv/bin/python benchmarks/bench_restitution.py [--fractions 0.1,0.2,0.3,0.4,0.5]

Drops one sphere of the smallest, mean and largest PSD diameter from 1 mm
onto a flat wall (the tests' drop: the level's material and Hertz contact,
rolling friction off) at each time step (a fraction of the Rayleigh time of
the smallest particle) and measures the restitution of the first bounce
(rebound over impact speed). A coarser step resolves the short contact with
fewer steps: this is how much of the configured restitution the integration
loses. Writes ``benchmarks/measured/restitution_dt.csv`` and ``.md``.
"""
from __future__ import annotations

import argparse
import copy
import platform
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.fidelity import scene  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from benchmarks.restitution_drop import drop_sphere, first_bounce  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fractions", default="0.1,0.2,0.3,0.4,0.5")
    parser.add_argument("--level", default="smoke")
    args = parser.parse_args(argv)
    config = load_config(ROOT / "config.yaml")
    psd = config["psd"]
    diameters_um = [psd["min_diameter_um"], psd["mean_diameter_um"], psd["max_diameter_um"]]
    rows = []
    for fraction in (float(f) for f in args.fractions.split(",")):
        c = copy.deepcopy(config)
        c["timestep"].update(rayleigh_fraction=fraction, max_rayleigh_fraction=max(fraction, 1.0))
        s = scene(c, args.level)
        for d_um in diameters_um:
            with tempfile.TemporaryDirectory() as tmp:
                trace = drop_sphere(s, Path(tmp), d_um * 1e-6, 1e-3, 0.02)
            bounce = first_bounce(trace["t"], trace["z"], trace["vz"], d_um * 1e-6 / 2)
            rows.append({"rayleigh_fraction": fraction, "diameter_um": d_um,
                         "restitution": round(bounce["restitution"], 4),
                         "error_pct": round(100 * (bounce["restitution"] / config["material"]["restitution"] - 1), 1)})
            print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    out = ROOT / "benchmarks" / "measured"
    table.to_csv(out / "restitution_dt.csv", index=False)
    wide = table.pivot(index="rayleigh_fraction", columns="diameter_um", values="error_pct")
    wide.columns = [f"{d:g} um: error %" for d in wide.columns]
    text = (f"# Realised restitution against the time step\n\n"
            f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, by\n"
            "`.venv/bin/python benchmarks/bench_restitution.py "
            f"{' '.join(argv if argv is not None else sys.argv[1:])}`.\n\n"
            f"One sphere dropped 1 mm onto a flat wall, configured restitution "
            f"{config['material']['restitution']}; error of the first bounce's rebound/impact speed.\n"
            f"The time step is the fraction x the Rayleigh time of the smallest particle.\n\n"
            + wide.reset_index().to_markdown(index=False) + "\n")
    (out / "restitution_dt.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
