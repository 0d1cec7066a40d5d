"""How far a spread resumed from a checkpoint lands from the same spread run straight through.

Run from the repository root::

    .venv/bin/python benchmarks/bench_resume.py [--point 100:-5] [--ranks 2] [--checkpoints 20]
        [--resumes 10] [--seeds 4] [--keep] [--scratch DIR]

A time limit (SLURM's, or any kill) stops a spread; the workflow reruns it and it resumes
from its newest checkpoint (:func:`analysis.dem.simulate.spread`). A resumed run is not
bit-identical to a straight one: the roller is re-placed under new fix IDs and the wall
contacts' tangential history starts afresh, and the granular flow amplifies that
perturbation. The tests and ``bench_slurm.py`` accept a resumed run whose metrics are
within 4 pooled seed sds of its straight twin's; this measures how the differences are
actually distributed, against the scatter of independent heaps at the same point.

At one point of the smoke level (``--ranks`` MPI ranks, ``--checkpoints`` checkpoints):

1. the straight run, and a second straight run (are repeats bit-identical?);
2. ``--resumes`` runs of the same input, each stopped by SIGTERM to its process group (as
   SLURM's time limit does) right after its 1st, ..., last-but-one checkpoint (spread evenly),
   then rerun to its end (it resumes from that checkpoint);
3. ``--seeds`` more replicates (their own heap and substrate) run straight: the seed
   scatter at this very point.

Writes ``benchmarks/measured/resume.csv`` (one row per run) and ``resume.md`` (per metric:
the sd of resumed-minus-straight differences and the largest, in units of the smoke
scene's pooled seed sd from ``noise_smoke.csv``, and the same point's seed sd).
"""
import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.columns import METRICS  # noqa: E402
from analysis.config.load import load_config  # noqa: E402
from analysis.dem.simulate import CHECKPOINT_DIR  # noqa: E402
from analysis.metrics.noise_floor import pooled_seed_sd  # noqa: E402
from benchmarks.bench_fidelity import measure_layer  # noqa: E402
from benchmarks.machine import machine  # noqa: E402

LEVEL = "smoke"


def simulate(config, *args):
    """The ``spreadmap-simulate`` command line for ``args`` (a list of strings)."""
    return [sys.executable, "-m", "analysis.dem.simulate", *args, "--config", str(config), "--level", LEVEL]


def run_to_end(cmd, what):
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(f"bench_resume: {what} failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return time.perf_counter() - start


def stopped_then_resumed(cmd, out, after_checkpoints):
    """Start ``cmd``, SIGTERM its process group once ``out`` has written ``after_checkpoints``
    checkpoints (a moment in the run that does not depend on how busy the machine is), wait,
    then run it to its end: it resumes from that checkpoint."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    seen = set()
    while proc.poll() is None and len(seen) < after_checkpoints:
        seen.update(p.name for p in (out / CHECKPOINT_DIR).glob("travel.*.restart"))
        time.sleep(0.1)
    stopped = proc.poll() is None
    if stopped:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=120)
    return stopped, run_to_end(cmd, "resume")


def layer_metrics(config_path, run, meshes):
    """The run's step counts and its four metrics (bench_fidelity's measure_layer)."""
    health = json.loads((run / "health.json").read_text())
    return {"steps": health["steps"], "resumed_from_step": health["resumed_from_step"],
            **measure_layer(load_config(config_path), LEVEL, run, meshes, health["U_mm_s"])}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--point", default="100:-5", help="U mm/s : omega rad/s")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--checkpoints", type=int, default=20, help="checkpoints_per_run")
    parser.add_argument("--resumes", type=int, default=10)
    parser.add_argument("--seeds", type=int, default=4, help="replicates 1..N run straight (0: none)")
    parser.add_argument("--scratch", type=Path, help="a scratch folder of an earlier call: its finished runs are kept")
    parser.add_argument("--keep", action="store_true")
    args = parser.parse_args()
    U, omega = (float(v) for v in args.point.split(":"))
    scratch = args.scratch or Path(tempfile.mkdtemp(prefix="spreadmap-resume-"))
    scratch.mkdir(parents=True, exist_ok=True)
    raw = yaml.safe_load((ROOT / "config.yaml").read_text())
    raw["level"] = LEVEL
    raw["fidelity"][LEVEL].update(mpi_ranks=args.ranks, checkpoints_per_run=args.checkpoints)
    config = scratch / "config.yaml"
    config.write_text(yaml.safe_dump(raw, sort_keys=False))
    print(f"scratch: {scratch}", flush=True)

    def prepare(rep):
        meshes, settled = scratch / f"meshes_r{rep}", scratch / f"settle_r{rep}"
        if not (settled / "health.json").is_file():
            run_to_end(simulate(config, "geometry", "--out", str(meshes), "--replicate", str(rep)), "geometry")
            run_to_end(simulate(config, "settle", "--meshes", str(meshes), "--out", str(settled),
                                "--replicate", str(rep)), "settle")
        return meshes, settled

    def spread_cmd(rep, out):
        meshes, settled = prepare(rep)
        return simulate(config, "spread", "--meshes", str(meshes), "--settled", str(settled), "--out", str(out),
                        "--U", str(U), "--omega", str(omega), "--replicate", str(rep))

    rows = []

    def done(run):
        """The row of a run an earlier, interrupted call of this benchmark finished (``--scratch``)."""
        saved = run / "bench_row.json"
        if saved.is_file():
            rows.append(json.loads(saved.read_text()))
            return True
        return False

    def record(kind, rep, run, wall, after=np.nan, stopped=False):
        row = {"kind": kind, "replicate": rep, "run": run.name, "stopped_after_checkpoint": after, "stopped": stopped,
               "wall_s": wall, **layer_metrics(config, run, scratch / f"meshes_r{rep}")}
        rows.append(row)
        (run / "bench_row.json").write_text(json.dumps(row))
        print(f"{kind} {run.name}: " + ", ".join(f"{k} {row[k]:.4g}" for k in ["resumed_from_step", *METRICS]),
              flush=True)

    straight = scratch / "straight"
    if not done(straight):
        record("straight", 0, straight, run_to_end(spread_cmd(0, straight), "straight run"))
    again = scratch / "straight_again"
    if not done(again):
        record("straight", 0, again, run_to_end(spread_cmd(0, again), "repeat"))
    # stopped after checkpoint 1, 3, 5, ...: spread evenly over the travel
    stops = np.round(1 + np.arange(args.resumes) * (args.checkpoints - 2) / max(args.resumes - 1, 1)).astype(int)
    for i, after in enumerate(stops):
        out = scratch / f"resumed_{i}"
        if not done(out):
            shutil.rmtree(out, ignore_errors=True)
            stopped, wall_i = stopped_then_resumed(spread_cmd(0, out), out, after)
            record("resumed", 0, out, wall_i, int(after), stopped)
    for rep in range(1, args.seeds + 1):
        out = scratch / f"seed_r{rep}"
        if not done(out):
            record("seed", rep, out, run_to_end(spread_cmd(rep, out), f"replicate {rep}"))

    df = pd.DataFrame(rows)
    ref_dump = (straight / "final.dump").read_bytes()
    df["bit_identical"] = [(scratch / r / "final.dump").read_bytes() == ref_dump for r in df["run"]]
    report(df, args, scratch)
    if not args.keep and not args.scratch:
        shutil.rmtree(scratch, ignore_errors=True)


def report(df, args, scratch):
    sd = pooled_seed_sd(pd.read_csv(ROOT / "benchmarks/measured/noise_smoke.csv"))
    base = df[df["run"] == "straight"].iloc[0]
    resumed = df[(df["kind"] == "resumed") & (df["resumed_from_step"] > 0)]
    seeds = df[(df["kind"] == "seed") | (df["run"] == "straight")]
    lines = []
    for m in METRICS:
        d = resumed[m] - base[m]
        df[f"d_{m}"] = df[m] - base[m]
        point_sd = seeds[m].std(ddof=1) if len(seeds) > 1 else np.nan
        lines.append({"metric": m, "pooled_seed_sd": sd[m], "point_seed_sd": point_sd,
                      "resumed_minus_straight_sd": float(np.sqrt(np.mean(d**2))) if len(d) else np.nan,
                      "largest_abs": float(d.abs().max()) if len(d) else np.nan,
                      "largest_in_pooled_sd": float(d.abs().max() / sd[m]) if len(d) else np.nan,
                      "beyond_4_pooled_sd": int((d.abs() > 4 * sd[m]).sum())})
    table = pd.DataFrame(lines)
    out = ROOT / "benchmarks/measured"
    df.to_csv(out / "resume.csv", index=False)
    cmd = (f".venv/bin/python benchmarks/bench_resume.py --point {args.point} --ranks {args.ranks} "
           f"--checkpoints {args.checkpoints} --resumes {args.resumes} --seeds {args.seeds}")
    n_res, n_id = len(resumed), int(df.loc[df["kind"] == "resumed", "bit_identical"].sum())
    text = [
        "# A spread resumed from a checkpoint against the same spread run straight",
        "",
        f"Measured {machine()} by `{cmd}`.",
        "",
        f"- Smoke level, U = {args.point.split(':')[0]} mm/s, omega = {args.point.split(':')[1]} rad/s, "
        f"{args.ranks} MPI ranks (mpirun), {args.checkpoints} checkpoints per run.",
        f"- A second straight run bit-identical to the first: "
        f"{'yes' if df.loc[df['run'] == 'straight_again', 'bit_identical'].iloc[0] else 'NO'}.",
        f"- {len(df[df['kind'] == 'resumed'])} runs stopped by SIGTERM and rerun; {n_res} resumed from a "
        f"checkpoint (steps {', '.join(str(int(v)) for v in resumed['resumed_from_step'])}); "
        f"bit-identical to the straight run: {n_id}. Every run's steps: "
        f"{sorted(set(int(v) for v in df['steps']))}.",
        f"- Seed scatter at this point: the straight run and {args.seeds} more replicates (own heap and "
        "substrate), sd `point_seed_sd`; `pooled_seed_sd`: the smoke scene's, noise_smoke.csv (the tolerance's unit).",
        "- `resumed_minus_straight_sd`: root mean square of the resumed runs' differences from the straight run. "
        "Were a resumed run an independent heap, it would be about sqrt(2) seed sds.",
        "",
        table.to_markdown(index=False, floatfmt=".4g"),
        "",
        "Per run (`resume.csv`):",
        "",
        df[["kind", "run", "stopped_after_checkpoint", "resumed_from_step", "bit_identical", *METRICS]].to_markdown(
            index=False, floatfmt=".4g"),
        "",
    ]
    (out / "resume.md").write_text("\n".join(text))
    print("\n".join(text))


if __name__ == "__main__":
    main()
