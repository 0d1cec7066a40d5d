"""The record of one finished map: what it cost, how sound its runs were, and what it found.

Run from the repository root after ``make map`` (or any level's workflow)::

    .venv/bin/python benchmarks/map_record.py [--results results] [--level default] [--wall-min M]

Reads ``<results>/<level>/`` (``dataset.csv``, ``trends.md``, ``surrogate/scores.json``,
``surrogate/model_choice.md``, ``surrogate/noise_floor.md``) and the per-job benchmark files
``<results>/benchmarks/<level>/<rule>/*.tsv`` that Snakemake wrote, and writes
``benchmarks/measured/map_<level>.md``: the one place the whole map's cost and its findings are
recorded (the docs link to it), and beside it ``map_<level>_dataset.csv``, the map's points and
metrics, so that the next map can be compared with it point by point (``compare_maps.py``).
The wall time is the span from the first job's start to the last
job's end (their benchmark files), unless ``--wall-min`` gives the measured one.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.columns import METRICS  # noqa: E402
from benchmarks.machine import commit, machine  # noqa: E402

#: The dataset's columns kept beside the record (with the metrics): enough to compare two maps.
KEPT = ["U_mm_s", "omega_rad_s", "replicate", "cpu_s", "supply_margin", "feed_pile_min_fraction"]


def job_times(bench_dir: Path) -> pd.DataFrame:
    """One row per finished job: rule, job, wall seconds, CPU seconds, end time (the file's mtime)."""
    rows = []
    for tsv in sorted(bench_dir.glob("*/*.tsv")):
        t = pd.read_csv(tsv, sep="\t")
        rows.append({"rule": tsv.parent.name, "job": tsv.stem, "s": float(t["s"].iloc[-1]),
                     "cpu_s": float(t["cpu_time"].iloc[-1]), "end": tsv.stat().st_mtime})
    return pd.DataFrame(rows, columns=["rule", "job", "s", "cpu_s", "end"])


def cost_table(jobs: pd.DataFrame) -> str:
    """Markdown: per rule, jobs and wall seconds (sum, largest)."""
    by = jobs.groupby("rule")["s"].agg(["count", "sum", "max"]).sort_values("sum", ascending=False)
    lines = ["| rule | jobs | wall s, summed | largest |", "|---|---:|---:|---:|"]
    lines += [f"| {rule} | {int(r['count'])} | {r['sum']:.0f} | {r['max']:.0f} |" for rule, r in by.iterrows()]
    return "\n".join(lines)


def soundness(df: pd.DataFrame) -> str:
    """Markdown bullets of the runs' health: supply, lost particles, speeds, overlaps."""
    out = [f"- runs supply-limited (`heap_exhausted`): {int(df['heap_exhausted'].sum())} of {len(df)}; "
           f"smallest `supply_margin` {df['supply_margin'].min():.2f}",
           f"- particles lost: {int(df['lost'].sum())}; through the roller: {int(df['through_roller'].sum())}; "
           f"through the substrate: {int(df['through_substrate'].sum())}",
           f"- fastest particle at the end: {df['peak_speed_m_s'].max():.2f} m/s; "
           f"Rayleigh fraction at most {df['rayleigh_fraction'].max():.3f}"]
    if "frozen_particles" in df:
        out.append(f"- the layer laid before the region, frozen and dropped from the run: "
                   f"{df['frozen_particles'].min():.0f}-{df['frozen_particles'].max():.0f} particles a run; intruders "
                   f"removed (landed where dropped ones were): {int(df['freeze_intruders_removed'].sum())} in all, "
                   f"at most {int(df['freeze_intruders_removed'].max())} in a run")
    out.append(f"- largest overlap during a run: particle-particle {df['inrun_max_overlap_um'].max():.0f} um "
               f"({df['inrun_max_overlap_fraction'].max():.2f} of the smaller radius), against a wall "
               f"{df['inrun_max_wall_overlap_um'].max():.0f} um ({df['inrun_max_wall_overlap_fraction'].max():.2f}); "
               f"squeeze-outs at once at most {int(df['squeeze_outs_max'].max())} in a run")
    out.append(f"- the gap as built: {df['effective_gap_um'].min():.1f}-{df['effective_gap_um'].max():.1f} um "
               f"(over a turn {df['gap_min_um'].min():.1f}-{df['gap_max_um'].max():.1f} um)")
    out.append(f"- fed powder: its share of the sampling region's layer {df['fed_share_of_region_layer'].min():.2f}-"
               f"{df['fed_share_of_region_layer'].max():.2f}; farthest landed ahead of the pile's front "
               f"{df['fed_max_ahead_of_front_mm'].max():.3f} mm; the pile at its lightest top-up "
               f"{df['feed_pile_min_fraction'].min():.2f} of its set mass (runs below 0.9: "
               f"{int((df['feed_pile_min_fraction'] < 0.9).sum())})")
    return "\n".join(out)


def scores_table(scores: dict) -> str:
    """Markdown: the paper's network's test R on the seeded split, and over the repeated splits."""
    lines = ["| metric | test R (seeded 35/10 split) | test R over " f"{scores['test_spread']['n_splits']} splits: "
             "mean +- sd (min-max) | 5-fold CV R |", "|---|---:|---:|---:|"]
    for m in METRICS:
        t, s, cv = scores["test"][m], scores["test_spread"][m], scores["cv"][m]
        lines.append(f"| {METRICS[m][0]} | {t['R']:.3f} | {s['R_mean']:.3f} +- {s['R_sd']:.3f} "
                     f"({s['R_min']:.3f}-{s['R_max']:.3f}) | {cv['R']:.3f} |")
    return "\n".join(lines)


def section(path: Path, title: str, drop_title: bool = True) -> str:
    """A generated Markdown file of the workflow, under a heading of this record."""
    if not path.is_file():
        return f"## {title}\n\nnot written ({path.name} missing)\n"
    text = path.read_text().strip()
    if drop_title and text.startswith("# "):
        text = text.split("\n", 1)[1].strip()
    return f"## {title}\n\n{text}\n"


def record(results: Path, level: str, wall_min: float | None = None, command: str = "make map",
           made_at: str | None = None) -> str:
    """The record's Markdown text."""
    study = results / level
    df = pd.read_csv(study / "dataset.csv")
    jobs = job_times(results / "benchmarks" / level)
    if jobs.empty:
        raise SystemExit(f"error: no job benchmark files under {results / 'benchmarks' / level}")
    span_min = (jobs["end"].max() - (jobs["end"] - jobs["s"]).min()) / 60
    wall = f"{wall_min:.0f} min (measured)" if wall_min else f"{span_min:.0f} min (first job's start to last job's end)"
    cpu = df["cpu_s"]
    per_u = ", ".join(f"{u:g} mm/s {c:.0f} s" for u, c in df.groupby("U_mm_s")["cpu_s"].mean().items())
    share = {k: df[f"time_{k}_s"].sum() / df["time_loop_s"].sum() for k in ("pair", "neigh")}
    loop = (f"contacts {share['pair']:.0%}, neighbour lists {share['neigh']:.0%}, the rest (the fixes: walls, "
            f"motion, insertion, integration; output) {1 - sum(share.values()):.0%}")
    scores = json.loads((study / "surrogate/scores.json").read_text())
    return f"""# The `{level}` map: its cost, its runs' soundness, its findings

Generated by `.venv/bin/python benchmarks/map_record.py --level {level}` from the results of `{command}`
at commit {made_at or commit()}; {machine()}.

## Cost

- wall time: **{wall}**; {len(df)} spreads
- LIGGGHTS' CPU: {cpu.sum():.0f} s in all, {cpu.min():.0f}-{cpu.max():.0f} s a run; mean by U: {per_u}
- {df['particle_steps'].sum() / cpu.sum() / 1e6:.2f} M particle-steps per CPU second; LIGGGHTS' loop: {loop}

Wall seconds per Snakemake rule (its benchmark files; jobs ran 2 at a time):

{cost_table(jobs)}

## Soundness of the runs

{soundness(df)}

## The surrogate

Chosen model: **{scores['model']['name']}**. The paper's network:

{scores_table(scores)}

{section(study / "trends.md", "The paper's trends (section 3)", drop_title=False)}
{section(study / "surrogate/model_choice.md", "Model choice")}
{section(study / "surrogate/noise_floor.md", "Noise floor")}"""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=ROOT / "results", help="the workflow's results folder")
    parser.add_argument("--level", default="default", help="the fidelity level whose map is recorded")
    parser.add_argument("--wall-min", type=float, help="the map's measured wall time [min], if known")
    parser.add_argument("--commit", help="the commit the map was made at (default: this checkout's HEAD)")
    parser.add_argument("--out", type=Path, help="where to write (default benchmarks/measured/map_<level>.md)")
    args = parser.parse_args(argv)
    if not (args.results / args.level / "dataset.csv").is_file():
        parser.error(f"--results {args.results}: no {args.level}/dataset.csv there; run the workflow first")
    out = args.out or ROOT / "benchmarks/measured" / f"map_{args.level}.md"
    out.write_text(record(args.results, args.level, args.wall_min, made_at=args.commit))
    kept = out.with_name(f"{out.stem}_dataset.csv")
    data = pd.read_csv(args.results / args.level / "dataset.csv")
    data[[c for c in KEPT if c in data] + list(METRICS)].to_csv(kept, index=False)
    print(f"wrote {out} and {kept}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
