"""Pile size: how the layer laid under forward rolling depends on the fed pile.

Usage (after the fed_default level's reference-study runs, benchmarks/README.md)::

    .venv/bin/python benchmarks/bench_pile_size.py [--U 70 --omega -15 --replicates 3 --jobs 2]

Spreads the ``fed_default`` scene (benchmarks/scene_size.yaml) with each level of
``benchmarks/pile_size.yaml`` (the same scene, another ``feed_pile_mg_per_mm``) from its
settled heaps and substrates (``results/fed_default/settle/r<k>``, ``meshes/r<k>``), so
replicate k differs from its replicate k by the pile alone. Writes ``results/<level>/runs/``
and ``benchmarks/measured/pile_size.csv`` (one row per run, fed_default's included) and
``pile_size.md`` (mean and seed-to-seed sd per pile, cost).
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd
import yaml

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.config.sweep import run_name
from analysis.dem.simulate import spread
from analysis.metrics.dump import read_dump
from analysis.metrics.spread_layer import spread_layer_metrics, to_report_units

ROOT = Path(__file__).resolve().parent.parent

#: The scene whose settled heaps and substrates every pile spreads from (benchmarks/scene_size.yaml).
BASE_LEVEL = "fed_default"
METRICS = ["mass_mg_mm2", "throughput_mm2_s", "roughness_um", "porosity_pct", "thickness_um"]


def config_with_levels() -> dict:
    config = load_config(ROOT / "config.yaml")
    for name in ("scene_size.yaml", "pile_size.yaml"):
        config["fidelity"].update(yaml.safe_load((ROOT / "benchmarks" / name).read_text())["fidelity"])
    return config


def one_run(level: str, U: float, omega: float, replicate: int) -> dict:
    """Spread (unless already done) and measure one run; returns its row."""
    config = config_with_levels()
    s = scene(config, level)
    base = ROOT / "results" / BASE_LEVEL
    out = ROOT / "results" / level / "runs" / run_name(U, omega, replicate)
    meshes = base / "meshes" / f"r{replicate}"
    if not (out / "health.json").is_file():
        spread(config, level, U, omega, meshes, base / "settle" / f"r{replicate}", out, replicate=replicate)
    health = json.loads((out / "health.json").read_text())
    m = to_report_units(spread_layer_metrics(read_dump(out / "final.dump"), s.sampling_region, U * 1e-3, s.density,
                                             substrate=meshes / "substrate.stl", n_lines=s.profilometer_lines,
                                             seed=config["profilometer"]["seed"]))
    x0, x1, y0, y1 = s.sampling_region
    return {"level": level, "pile_mg_mm": s.feed_pile_mass / s.strip_width * 1e3, "U_mm_s": U, "omega_rad_s": omega,
            "replicate": replicate, "cpu_s": health["cpu_s"], "fed_particles": health["fed_particles"], **m,
            "mass_mg_mm2": m["mass_g"] * 1e3 / ((x1 - x0) * (y1 - y0) * 1e6)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--U", type=float, default=70.0, help="mm/s")
    parser.add_argument("--omega", type=float, default=-15.0, help="rad/s")
    parser.add_argument("--replicates", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2, help="runs at once")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    levels = [BASE_LEVEL, *yaml.safe_load((ROOT / "benchmarks" / "pile_size.yaml").read_text())["fidelity"]]
    jobs = [(lv, args.U, args.omega, k) for lv in levels for k in range(args.replicates)]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(one_run, *zip(*jobs)))
    table = pd.DataFrame(rows).sort_values(["pile_mg_mm", "replicate"])
    out = ROOT / "benchmarks" / "measured"
    table.to_csv(out / "pile_size.csv", index=False)
    summary = table.groupby("pile_mg_mm")[[*METRICS, "cpu_s"]].agg(["mean", "std"])
    summary.columns = [f"{m} {stat}" for m, stat in summary.columns]
    lines = ["# Pile size under forward rolling", "",
             f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()}, in "
             f"{time.perf_counter() - started:.0f} s ({args.jobs} runs at once), by "
             "`.venv/bin/python benchmarks/bench_pile_size.py "
             f"{' '.join(argv if argv is not None else sys.argv[1:])}`.",
             "", f"The fed_default scene at U = {args.U:g} mm/s, omega = {args.omega:g} rad/s, "
             f"{args.replicates} replicates "
             "(its heap packings and substrates) per pile; mean and seed-to-seed sd; cost in LIGGGHTS CPU "
             "seconds per run. M_s per area in mg/mm^2, Q_s mm^2/s, R_q and thickness um, Phi %.", "",
             summary.reset_index().to_markdown(index=False, floatfmt=".3g"), ""]
    (out / "pile_size.md").write_text("\n".join(lines))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
