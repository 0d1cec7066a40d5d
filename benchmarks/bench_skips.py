"""Skip what a scene does not need: each skip's saving and its effect on the layer.

Usage::

    .venv/bin/python benchmarks/bench_skips.py [--level default] [--points 40:-10,40:0,...] [--jobs 2]
        [--name skips]

Two arms over the same (U [mm/s], omega [rad/s]) points, measured in one invocation:

* **all skips** (what the workflow does): the heap is settled once and every
  run starts from that restart; a run ends when the roller has passed the
  sampling region and the layer has come to rest; the powder pushed past the
  stopped roller is removed; only the final state is dumped
  (``analysis.dem.simulate.SKIPS``).
* **no skips**: every run settles its own heap (the same seed, so the same
  heap), waits the full ``rest_time_s`` after the travel, keeps the powder
  ahead of the roller and dumps every 2 ms of simulated time.

Both arms of a point run back to back in one task, so they share the
machine's load. The settle of the all-skips arm is counted once, spread over
the points. The layer's four metrics are compared point by point; the
seed-to-seed spread (another heap packing) of the same level is the yardstick
(``--noise``: the level's noise-floor CSV, its pooled row).

Writes ``benchmarks/measured/<name>.csv`` (one row per run) and ``<name>.md``.
"""
from __future__ import annotations

import argparse
import platform
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.config.load import load_config  # noqa: E402
from analysis.dem.simulate import SKIPS, make_geometry, settle, spread  # noqa: E402
from benchmarks.bench_fidelity import METRICS, children_cpu, measure_layer  # noqa: E402

DEFAULT_POINTS = ",".join(f"{U}:{w}" for U in (40, 70, 100) for w in (-10, 0, 10))


def run_point(task) -> list[dict]:
    config, level, meshes, settled, (U, omega) = task
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cpu0 = children_cpu()
        own = settle(config, level, meshes, tmp / "settle")
        settle_cpu = children_cpu() - cpu0
        for arm, skips, heap in (("no skips", frozenset(), tmp / "settle"), ("all skips", SKIPS, settled)):
            cpu0 = children_cpu()
            health = spread(config, level, U, omega, meshes, heap, tmp / arm.replace(" ", "_"), skips=skips)
            cpu = children_cpu() - cpu0
            rows.append({"arm": arm, "U_mm_s": U, "omega_rad_s": omega, "spread_wall_s": health["wall_s"],
                         "spread_cpu_s": cpu, "steps": health["steps"], "final_atoms": health["atoms"],
                         "settle_wall_s": own["wall_s"] if arm == "no skips" else 0.0,
                         "settle_cpu_s": settle_cpu if arm == "no skips" else 0.0,
                         **measure_layer(config, level, tmp / arm.replace(" ", "_"), meshes, U)})
        print(f"U={U:g} omega={omega:g}: " + ", ".join(
            f"{r['arm']} {r['spread_wall_s'] + r['settle_wall_s']:.1f} s" for r in rows[-2:]), flush=True)
    return rows


def noise_floor(path: Path) -> pd.Series | None:
    """Pooled seed-to-seed spread of each metric [fraction of its mean], from a
    noise-floor CSV of the workflow (``analysis.metrics.noise_floor``)."""
    if not path.exists():
        return None
    pooled = pd.read_csv(path).set_index("point").loc["pooled"]
    return pd.Series({k: pooled[f"{k}_rel_pct"] / 100 for k in METRICS})


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--level", default="default")
    parser.add_argument("--points", default=DEFAULT_POINTS, help="U:omega pairs, mm/s:rad/s")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--noise", default=str(ROOT / "benchmarks/measured/noise_default.csv"),
                        help="noise-floor CSV of the level (results/<level>/surrogate/noise_floor.csv)")
    parser.add_argument("--name", default="skips")
    parser.add_argument("--summarise", action="store_true",
                        help="only re-write <name>.md from the runs in <name>.csv")
    args = parser.parse_args(argv)
    out = ROOT / "benchmarks" / "measured"
    if args.summarise:
        runs = pd.read_csv(out / f"{args.name}.csv")
        text = summarise(runs, args, elapsed=None)
        (out / f"{args.name}.md").write_text(text)
        print(text)
        return 0
    config = load_config(ROOT / "config.yaml")
    points = [tuple(float(v) for v in p.split(":")) for p in args.points.split(",")]
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_geometry(config, args.level, tmp / "meshes")
        cpu0 = children_cpu()
        shared = settle(config, args.level, tmp / "meshes", tmp / "settle")
        shared_cpu = children_cpu() - cpu0
        tasks = [(config, args.level, tmp / "meshes", tmp / "settle", p) for p in points]
        with ProcessPoolExecutor(args.jobs) as pool:
            runs = pd.DataFrame([row for rows in pool.map(run_point, tasks) for row in rows])
    share = runs["arm"] == "all skips"
    runs.loc[share, "settle_wall_s"] = shared["wall_s"] / len(points)
    runs.loc[share, "settle_cpu_s"] = shared_cpu / len(points)
    runs["wall_s"] = runs["spread_wall_s"] + runs["settle_wall_s"]
    runs["cpu_s"] = runs["spread_cpu_s"] + runs["settle_cpu_s"]
    runs.to_csv(out / f"{args.name}.csv", index=False)
    text = summarise(runs, args, elapsed=time.perf_counter() - started)
    (out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


def summarise(runs: pd.DataFrame, args, elapsed: float | None) -> str:
    """The Markdown table: totals per arm, the ratios, the metric changes per point."""
    points = runs[["U_mm_s", "omega_rad_s"]].drop_duplicates()
    totals = runs.groupby("arm")[["wall_s", "cpu_s", "settle_cpu_s", "spread_cpu_s", "steps", "final_atoms"]].agg(
        {"wall_s": "sum", "cpu_s": "sum", "settle_cpu_s": "sum", "spread_cpu_s": "sum", "steps": "mean",
         "final_atoms": "mean"})
    ratio = lambda col: totals.loc["no skips", col] / totals.loc["all skips", col]  # noqa: E731
    pivot = runs.pivot_table(index=["U_mm_s", "omega_rad_s"], columns="arm", values=list(METRICS))
    diff = pd.DataFrame({METRICS[k]: (pivot[(k, "all skips")] - pivot[(k, "no skips")]).abs()
                         / runs[k].abs().mean() for k in METRICS})
    floor = noise_floor(Path(args.noise))
    lines = [f"# Skips at the `{args.level}` level",
             "",
             f"Machine: {platform.node()} ({platform.machine()}, 2 cores), date: {time.strftime('%Y-%m-%d')}, "
             f"{args.jobs} jobs" + (f", {elapsed:.0f} s in all" if elapsed else "") + ". Command: "
             f"`.venv/bin/python benchmarks/bench_skips.py --level {args.level} --points {args.points}`",
             "",
             f"{len(points)} points; both arms of a point ran back to back in one job. CPU time is LIGGGHTS' own "
             "(the children's user + system time): it does not depend on what else the machine runs, wall time does.",
             "",
             totals.round(1).to_markdown(),
             "",
             f"**All skips: {ratio('cpu_s'):.2f}x less CPU time than none** (wall: {ratio('wall_s'):.2f}x; "
             f"settling: {ratio('settle_cpu_s'):.0f}x; spreading: {ratio('spread_cpu_s'):.2f}x).",
             "",
             "Metric change, |all skips - no skips| / mean |metric|, per point:",
             "",
             diff.map(lambda v: f"{v:.1%}").to_markdown(),
             "",
             "Mean: " + ", ".join(f"{m} {v:.1%}" for m, v in diff.mean().items())]
    if floor is not None:
        lines += ["", "Seed-to-seed spread of the same level (pooled noise floor, from "
                  f"`{Path(args.noise).name}`): " + ", ".join(f"{METRICS[k]} {v:.1%}" for k, v in floor.items())]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
