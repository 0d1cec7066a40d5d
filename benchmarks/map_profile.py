"""Where two maps' spreading CPU goes, side by side: LIGGGHTS' own loop breakdown, particle-steps, rate.

Run from the repository root (no simulation; it reads two finished maps' datasets)::

    .venv/bin/python benchmarks/map_profile.py BEFORE/dataset.csv AFTER/dataset.csv \
        [--labels "before,after"] [--name spread_profile_maps] [--out benchmarks/measured]

For each map and each group of runs (forward rolling omega < 0, still, counter-rotating omega > 0, all):
the runs, LIGGGHTS' CPU seconds (``cpu_s``, summed and per run), the particle-steps integrated
(``particle_steps``: steps x particles integrated, the frozen ones left out), their rate per CPU second,
and the shares of LIGGGHTS' loop (``time_<part>_s`` over ``time_loop_s``: Pair = particle-particle
contacts, Neigh = neighbour lists, Comm = MPI and the periodic images, Other = the fixes: mesh walls,
their motion, the feed, integration; output is the rest). Then, over the points both maps ran, the
ratio of their CPU per group (before / after). The loop's seconds are elapsed ones (a shared core
inflates them), so read its shares, not its seconds. Writes ``<name>.csv`` and ``<name>.md``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` importable

from benchmarks.machine import commit, machine  # noqa: E402
from benchmarks.travel_time import GROUPS  # noqa: E402

PARTS = ("pair", "neigh", "comm", "other")
ROUND = {"cpu_s": 0, "cpu_s_per_run": 0, "particle_steps_G": 2, "M_particle_steps_per_cpu_s": 2,
         "frozen_particles_mean": 0, **{f"{p}_pct": 1 for p in PARTS + ("output",)}}
NEEDED = ["U_mm_s", "omega_rad_s", "cpu_s", "particle_steps", "time_loop_s"] + [f"time_{p}_s" for p in PARTS]


def groups(omega: pd.Series):
    """(name, mask) of each group of runs by the sign of omega (travel_time's groups), then all runs."""
    sign = np.sign(omega.to_numpy())
    yield from ((name, sign == s) for s, name in GROUPS.items())
    yield "all runs", np.ones(len(sign), dtype=bool)


def read_map(path: Path) -> pd.DataFrame:
    """A map's ``dataset.csv``, refused with the missing columns named."""
    if not path.is_file():
        raise SystemExit(f"error: {path}: no such dataset")
    data = pd.read_csv(path)
    missing = [c for c in NEEDED if c not in data]
    if missing:
        raise SystemExit(f"error: {path} lacks the columns {', '.join(missing)} (a map from an older commit?)")
    if "frozen_particles" not in data:
        data["frozen_particles"] = 0
    return data


def profile(data: pd.DataFrame) -> pd.DataFrame:
    """One row per group of runs: CPU [s], particle-steps, their rate [M per CPU s], loop shares [%]."""
    rows = []
    for group, keep in groups(data["omega_rad_s"]):
        runs = data[keep]
        if runs.empty:
            continue
        loop = runs["time_loop_s"].sum()
        row = {"runs": group, "n": len(runs), "cpu_s": runs["cpu_s"].sum(), "cpu_s_per_run": runs["cpu_s"].mean(),
               "particle_steps_G": runs["particle_steps"].sum() / 1e9,
               "M_particle_steps_per_cpu_s": runs["particle_steps"].sum() / runs["cpu_s"].sum() / 1e6,
               "frozen_particles_mean": runs["frozen_particles"].mean()}
        row.update({f"{part}_pct": 100 * runs[f"time_{part}_s"].sum() / loop for part in PARTS})
        row["output_pct"] = 100 - sum(row[f"{part}_pct"] for part in PARTS)
        rows.append(row)
    return pd.DataFrame(rows)


def ratios(before: pd.DataFrame, after: pd.DataFrame) -> pd.DataFrame:
    """Over the (U, omega) points both ran: CPU and particle-steps, before / after, per group."""
    keys = ["U_mm_s", "omega_rad_s"]
    both = pd.merge(*(m.groupby(keys)[["cpu_s", "particle_steps"]].mean().reset_index() for m in (before, after)),
                    on=keys, suffixes=("_before", "_after"))
    rows = []
    for group, keep in groups(both["omega_rad_s"]):
        runs = both[keep]
        if runs.empty:
            continue
        rows.append({"runs": group, "points": len(runs),
                     "cpu_ratio": runs["cpu_s_before"].sum() / runs["cpu_s_after"].sum(),
                     "particle_steps_ratio": runs["particle_steps_before"].sum() / runs["particle_steps_after"].sum()})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", type=Path, help="the earlier map's dataset.csv")
    parser.add_argument("after", type=Path, help="the later map's dataset.csv")
    parser.add_argument("--labels", default="before,after", help="the two maps' names, comma-separated")
    parser.add_argument("--name", default="spread_profile_maps", help="output files' stem")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks/measured", help="output folder")
    args = parser.parse_args(argv)
    labels = [s.strip() for s in args.labels.split(",")]
    if len(labels) != 2 or not all(labels):
        parser.error(f"--labels {args.labels!r}: give two names, comma-separated")
    maps = [read_map(args.before), read_map(args.after)]
    table = pd.concat([profile(m).assign(map=label) for m, label in zip(maps, labels)], ignore_index=True)
    table = table[["map"] + [c for c in table if c != "map"]]
    ratio = ratios(*maps)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / f"{args.name}.csv", index=False)
    (args.out / f"{args.name}.md").write_text(
        f"# Where two maps' spreading CPU goes: {labels[0]} and {labels[1]}\n\n"
        f"Read on {machine()} at commit {commit()} (no DEM: the maps' datasets), by\n"
        f"`.venv/bin/python benchmarks/map_profile.py {args.before} {args.after} --labels \"{args.labels}\""
        f" --name {args.name}`.\n\n"
        "Per group: LIGGGHTS' CPU seconds, the particle-steps it integrated (frozen particles left out) and their"
        " rate, and the shares of its loop (Pair: particle-particle contacts; Neigh: neighbour lists; Comm: the"
        " periodic images; Other: the fixes, i.e. mesh walls and their motion, the feed, integration; output the"
        " rest). Shares are of elapsed loop seconds.\n\n"
        f"{table.round(ROUND).to_markdown(index=False, floatfmt='g')}\n\n"
        f"CPU and particle-steps, {labels[0]} / {labels[1]}, over the points both maps ran (means over"
        f" replicates):\n\n{ratio.to_markdown(index=False, floatfmt='.3f')}\n")
    print(f"wrote {args.out / args.name}.md and .csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
