"""How big the calibration's characterisation tests must be: their result against their size, per seed.

Usage::

    .venv/bin/python benchmarks/bench_calibration_size.py [--level default] [--seeds 0,1,2]
        [--repose 2,3,4,5,6] [--cups 1.5,2,2.5,3] [--name calibration_size] [--append]
        [--set material.rolling_friction=0.556 ...]

Runs the angle-of-repose heap on each base diameter [mm] and the bulk-density cup on each
diameter (= height) [mm] with the config's material and the level's PSD, one packing per seed
index, one LIGGGHTS at a time, and appends a row per run to ``benchmarks/measured/<name>.csv`` as
it finishes (``--append`` keeps the rows already there, so an invocation may add seeds or sizes;
``--set`` overrides a config key, dotted, its value read as YAML);
``<name>.md`` summarises every row: mean and seed sd per size, wall time. A size is big enough
when the means of it and of every bigger size agree within the seed sd (docs/calibration.md).
"""
from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import yaml

from analysis.calibration.characterise import bulk_density_test, repose_test
from analysis.config.load import load_config
from analysis.config.reading import PROJECT_DIR
from analysis.config.sweep import config_value, resolve

OUT = PROJECT_DIR / "benchmarks" / "measured"


def _floats(text):
    return [float(v) for v in text.split(",") if v]


def _ints(text):
    return [int(v) for v in text.split(",") if v]


def override(config: dict, assignments: list[str]) -> dict:
    """A copy of ``config`` with each ``dotted.key=value`` applied (the value read as YAML; set as the
    sweep sets its axes, :func:`analysis.config.sweep.resolve`); a key the config lacks is refused."""
    values = {}
    for item in assignments:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item!r}: expected dotted.key=value")
        *path, last = key.split(".")
        parent = config_value(config, ".".join(path)) if path else config
        if not isinstance(parent, dict) or last not in parent:
            raise SystemExit(f"--set {item!r}: no key {key!r} in the config")
        values[key] = yaml.safe_load(value)
    return resolve(config, values)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--level", default="default")
    p.add_argument("--seeds", type=_ints, default=[0, 1, 2])
    p.add_argument("--repose", type=_floats, default=[2, 3, 4, 5, 6])
    p.add_argument("--cups", type=_floats, default=[1.5, 2, 2.5, 3])
    p.add_argument("--name", default="calibration_size")
    p.add_argument("--append", action="store_true")
    p.add_argument("--note", default="", help="a line for the summary (e.g. how its rows were run)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config key, e.g. material.rolling_friction=0.556")
    a = p.parse_args(argv)
    config = load_config(override(load_config(PROJECT_DIR / "config.yaml"), a.set))
    csv = OUT / f"{a.name}.csv"
    OUT.mkdir(parents=True, exist_ok=True)
    if not a.append and csv.exists():
        csv.unlink()

    def record(row):
        pd.DataFrame([row]).to_csv(csv, mode="a", header=not csv.exists(), index=False)
        print(row, flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        for seed in a.seeds:
            for d in a.cups:
                r = bulk_density_test(config, a.level, Path(tmp) / f"cup_{d}_{seed}", d, d, seed_index=seed)
                for kind in ("core", "cup"):
                    record({"test": f"bulk_density_{kind}", "size_mm": d, "seed": seed, "value": r[f"{kind}_kg_m3"],
                            "fit_se": float("nan"), "particles": r["particles"], "wall_s": r["wall_s"]})
            for d in a.repose:
                r = repose_test(config, a.level, Path(tmp) / f"repose_{d}_{seed}", d, seed_index=seed)
                record({"test": "repose", "size_mm": d, "seed": seed, "value": r["angle_of_repose_deg"],
                        "fit_se": r["angle_se_deg"], "particles": r["particles"], "wall_s": r["wall_s"]})
    df = pd.read_csv(csv)
    table = df.groupby(["test", "size_mm"]).agg(mean=("value", "mean"), seed_sd=("value", "std"),
                                                 runs=("value", "size"), particles=("particles", "first"),
                                                 wall_s=("wall_s", "mean"))
    seeds = ", ".join(map(str, sorted(df.seed.unique())))
    argv = sys.argv[1:] if argv is None else list(argv)
    shown = [v for i, v in enumerate(argv) if "--note" not in argv[max(i - 1, 0):i + 1]]
    lines = [f"# Characterisation tests against their size ({a.level} level, seeds {seeds})", "",
             f"`.venv/bin/python {' '.join(['benchmarks/bench_calibration_size.py', *shown])}`, "
             f"{time.strftime('%Y-%m-%d')}, {platform.node()}, one LIGGGHTS at a time. {a.note}", "",
             "repose: angle of repose [deg] on a base of size_mm diameter; bulk_density_core: the cup's "
             "wall-free core [kg/m^3], bulk_density_cup: the whole struck-off cup [kg/m^3], cup diameter = "
             "height = size_mm.", "", "| test | size (mm) | mean | seed sd | runs | particles | wall (s) |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {t} | {s:g} | {r['mean']:.4g} | {r['seed_sd']:.3g} | {int(r['runs'])} | {int(r['particles'])} | "
              f"{r['wall_s']:.1f} |"
              for (t, s), r in table.iterrows()]
    (OUT / f"{a.name}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
