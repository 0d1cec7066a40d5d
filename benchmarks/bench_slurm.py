"""The SLURM path end to end on a real one-node SLURM cluster on this machine.

Run from the repository root, as root, after ``apt-get install slurm-wlm munge libpmix-dev
slurmdbd mariadb-server`` (Debian 12: SLURM 22.05.8)::

    .venv/bin/python benchmarks/bench_slurm.py [--keep] [--scratch DIR] [--limit-point 20:-5]
    .venv/bin/python benchmarks/bench_slurm.py --dry-run   # its Snakemake commands resolve; no cluster

1. **A failing job is seen**: on a one-node cluster with accounting (munge, MariaDB,
   slurmdbd, slurmctld, slurmd; :mod:`benchmarks.slurm_cluster`), a settle that cannot
   start MPI (the launcher forced to plain ``srun``, which Debian's Open MPI cannot use)
   through ``profiles/slurm``: the job fails at once, is retried twice (the profile's
   ``retries``), and Snakemake must stop with an error; status by ``sacct``.
2. **Workflow to maps**: the CI's smoke workflow (``.test/config.yaml``, 6 runs) through
   ``profiles/slurm`` as it is, with 2-rank settle and spreads (``fidelity.smoke.mpi_ranks=2``).
3. **Time limit**: in the same folder one more spread (``--limit-point``, a point not in
   the sweep, slow enough for a travel of a few minutes: U = 20 mm/s takes about 5 times the
   smoke sweep's U = 100 mm/s) with ``runtime_min: 1`` and ``--limit-checkpoints`` checkpoints: SLURM kills
   it at its limit (TIMEOUT), Snakemake's retries resubmit it (``--limit-retries``: the
   profile's 2 are for real limits, which a spread rarely meets; a 1-minute limit on a
   spread of several minutes needs more), and each attempt resumes from its newest checkpoint.
4. The failing settle again on a second cluster **without accounting** (no slurmdbd:
   ``sacct`` answers "accounting storage is disabled"); status by ``squeue``, the profile's.
5. **Local reference**: the same workflow and the time-limited point with ``--cores 2``
   (mpirun, 2 ranks), no scheduler.

Checks: the SLURM workflow made the maps and a dataset with every run; each SLURM run's
metrics within 4 sds of a two-run difference of the local run's (4 x sqrt 2 pooled seed sds
of the smoke scene, benchmarks/measured/noise_smoke.csv; resume.md); the time-limited spread
was killed at least once with TIMEOUT, resumed from a checkpoint (``resumed_from_step`` >
0), its roller ended its travel within 1e-6 m of the local run's and every particle is
accounted for (in the box, removed ahead of the roller, or fed); no half-written file; each
failure was seen by Snakemake within 60 s of SLURM's end of the job; the failing settle's
log names the launcher. Every daemon is stopped by its process id, also on an error.

Writes ``benchmarks/measured/slurm.md`` and ``slurm.csv`` (one row per SLURM run with its
local twin); exits 1 if a check fails.
"""
import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from analysis.columns import METRICS  # noqa: E402
from analysis.metrics.noise_floor import pooled_seed_sd, two_run_tolerance  # noqa: E402
from benchmarks.faults import compare_runs, half_written_files  # noqa: E402
from benchmarks.machine import commit, machine  # noqa: E402
from benchmarks.slurm_cluster import OneNodeCluster, job_table, missing_commands, snakemake_job_events  # noqa: E402

RANKS = {"smoke": {"mpi_ranks": 2}}
SEEN_WITHIN_S = 60


def snakemake(workdir, *extra, profile=True):
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "-d", str(workdir),
           "--configfile", str(ROOT / "config.yaml"), str(ROOT / ".test/config.yaml")]
    return cmd + (["--profile", str(ROOT / "profiles/slurm")] if profile else ["--cores", "2"]) + list(extra)


def run(cmd, env, log):
    start = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.run(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT, timeout=5400)
    return proc.returncode, time.perf_counter() - start, Path(log).read_text()


def fresh(path):
    """``path``, or ``path-2``, ``path-3``... if it is taken (a cluster's folder is never reused)."""
    n, candidate = 1, path
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.name}-{n}")
    return candidate


def failure_latencies(jobs, events):
    """Seconds from SLURM's end of each failed or timed-out job to Snakemake's error report."""
    failed = jobs[jobs.state.isin(["FAILED", "TIMEOUT", "CANCELLED", "OUT_OF_MEMORY", "NODE_FAIL"])]
    seen = events[events.event == "error"].set_index("job")["seen"]
    return {int(j.job): (j.state, (seen[j.job] - j.end).total_seconds() if j.job in seen.index else None)
            for j in failed.itertuples()}


def failing_settle(cluster, workdir, status_command, log):
    """A settle that cannot start MPI, through the profile: (exit code, wall s, latencies, rule log)."""
    extra = ["--precommand", "export SPREADMAP_MPI_LAUNCHER=srun", "--config", f"fidelity={json.dumps(RANKS)}"]
    if status_command:
        extra += ["--slurm-status-command", status_command]
    code, wall, text = run(snakemake(workdir, *extra, "--", "results/smoke/settle/r0/health.json"), cluster.env(), log)
    jobs = job_table(cluster.env(), cluster.accounting)
    rule_log = (workdir / "results/logs/smoke/settle/r0.log")
    return {"returncode": code, "wall_s": wall, "latencies": failure_latencies(jobs, snakemake_job_events(text)),
            "rule_error": rule_log.read_text().strip().splitlines()[-1] if rule_log.exists() else ""}


def roller_end_difference(run_dir, ref):
    """Largest distance [m] between the roller's facet centres at the end of two runs' travel (their
    ``roller_<travel steps>.vtk``: the rest phase after it, which ends when the powder is at rest,
    may differ in length between runs that are not bit-identical)."""
    import pyvista as pv
    from scipy.spatial import cKDTree

    last = max(ref.glob("roller_*.vtk"), key=lambda p: int(p.stem.split("_")[-1]))
    a, b = (pv.read(d / last.name).cell_centers().points for d in (run_dir, ref))
    # matched by position, not by index: with 2 ranks the facets are written in the order their
    # ranks own them, which differs between a resumed run and an uninterrupted one
    return float(max(cKDTree(b).query(a)[0].max(), cKDTree(a).query(b)[0].max()))


def compare(slurm_runs, local_runs, tolerance):
    """Each SLURM run against its local twin: bit identity and metric differences
    (:func:`benchmarks.faults.compare_runs`, as for the kill campaign), plus the launcher, wall
    times, particle balance and the roller's end."""
    names = [p.name for p in sorted(Path(slurm_runs).glob("U*_w*_r*"))
             if (p / "health.json").is_file() and (Path(local_runs) / p.name / "health.json").is_file()]
    runs = compare_runs(slurm_runs, local_runs, names, tolerance)
    rows = []
    for name in names:
        run_dir, ref = Path(slurm_runs) / name, Path(local_runs) / name
        h, hr = (json.loads((p / "health.json").read_text()) for p in (run_dir, ref))
        same = runs[name]
        row = {"run": name, "slurm_launcher": h.get("mpi_launcher"), "local_launcher": hr.get("mpi_launcher"),
               "resumed_from_step": same["resumed_from_step"], "steps": h["steps"], "local_steps": hr["steps"],
               "bit_identical": same["identical"], "slurm_wall_s": h["wall_s"], "local_wall_s": hr["wall_s"]}
        # nothing lost over a resume: every particle accounted for, the roller where its motion took it
        whole = lambda h: h["atoms"] + h["removed_ahead_of_roller"] - h["fed_particles"]  # noqa: E731
        row["particles_balance"] = whole(h) - whole(hr)
        row["lost"] = h["lost"]
        row["roller_end_dm"] = roller_end_difference(run_dir, ref)
        row.update({f"d_{k}": same.get("differences", {}).get(k, 0.0) for k in tolerance})
        row["within_4_sd"] = same.get("within_tolerance", True)
        rows.append(row)
    return pd.DataFrame(rows)

def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keep", action="store_true", help="keep the scratch folder")
    parser.add_argument("--scratch", type=Path, help="a scratch folder of an earlier run: the phases it "
                        "finished (its out.json) are not run again")
    parser.add_argument("--limit-point", default="20:-5", help="U:omega of the time-limited spread (mm/s:rad/s); "
                        "slow enough that its travel needs a few minutes (SLURM's smallest limit is 1 minute) "
                        "but fewer than about --limit-retries")
    parser.add_argument("--limit-checkpoints", type=int, default=20, help="its checkpoints_per_run")
    parser.add_argument("--limit-retries", type=int, default=8, help="Snakemake's --retries for it")
    parser.add_argument("--dry-run", action="store_true", help="only check that the phases' Snakemake commands "
                        "resolve (snakemake -n; no cluster, no SLURM tools needed), then exit")
    args = parser.parse_args(argv)
    try:
        U, omega = (float(v) for v in args.limit_point.split(":"))
    except ValueError:
        parser.error(f"--limit-point {args.limit_point!r}: give U:omega in mm/s:rad/s, e.g. 100:-5")
    limited_run = f"U{U:g}_w{omega:g}_r0"
    limited_target = f"results/smoke/runs/{limited_run}/metrics.json"  # its spread, then its layer metrics
    limited_config = {"smoke": {**RANKS["smoke"], "runtime_min": 1, "checkpoints_per_run": args.limit_checkpoints}}
    if args.dry_run:
        return dry_run(limited_target, limited_config, args.limit_retries)
    # a SIGTERM (or SIGINT, which a background job ignores) unwinds: every daemon is stopped on the way out
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    missing = missing_commands(accounting=True)
    if missing:
        print(f"error: {', '.join(missing)} not found: apt-get install slurm-wlm munge libpmix-dev slurmdbd "
              "mariadb-server", file=sys.stderr)
        return 2
    scratch = args.scratch or Path(tempfile.mkdtemp(prefix="spreadmap-slurm-"))
    slurm_wd, local_wd, fail_wd, fail_noacct_wd = (scratch / n for n in ("slurm", "local", "fail", "fail-noacct"))
    tolerance = two_run_tolerance(pooled_seed_sd(pd.read_csv(ROOT / "benchmarks/measured/noise_smoke.csv")))
    saved = scratch / "out.json"
    out = json.loads(saved.read_text()) if saved.exists() else {}
    out.setdefault("stopped", {})
    out.setdefault("commit", commit())
    out["limit_setup"] = {"run": limited_run, "checkpoints": args.limit_checkpoints, "retries": args.limit_retries}
    out["args"] = f" --limit-point {args.limit_point} --limit-checkpoints {args.limit_checkpoints} " \
                  f"--limit-retries {args.limit_retries}"

    def save():
        saved.write_text(json.dumps(out, default=str, indent=1))

    print(f"scratch: {scratch}", flush=True)
    try:
        if not {"fail_sacct", "workflow", "limit"} <= set(out):
            with OneNodeCluster(fresh(scratch / "cluster"), accounting=True) as cluster:
                out["versions"] = cluster.versions()
                if "fail_sacct" not in out:
                    print("1. a failing job, accounting on, status by sacct ...", flush=True)
                    out["fail_sacct"] = failing_settle(cluster, fail_wd, "sacct", scratch / "fail.log")
                    print(f"   {out['fail_sacct']}", flush=True)
                    save()
                if "workflow" not in out:
                    print("2. smoke workflow to maps through profiles/slurm ...", flush=True)
                    code, wall, text = run(snakemake(slurm_wd, "--config", f"fidelity={json.dumps(RANKS)}"),
                                           cluster.env(), scratch / "slurm.log")
                    out["workflow"] = {"returncode": code, "wall_s": wall}
                    print(f"   exit {code} after {wall:.0f} s", flush=True)
                    save()
                print(f"3. a spread over its time limit ({limited_run}) ...", flush=True)
                before = job_table(cluster.env(), True).job.max()
                before = 0 if pd.isna(before) else before
                code, wall, text = run(snakemake(slurm_wd, "--config", f"fidelity={json.dumps(limited_config)}",
                                                 "--retries", str(args.limit_retries), "--", limited_target),
                                       cluster.env(), scratch / "limit.log")
                jobs = job_table(cluster.env(), True)
                jobs = jobs[jobs.job > before]
                out["limit"] = {"returncode": code, "wall_s": wall, "states": list(jobs.state),
                                "elapsed_s": [(j.end - j.start).total_seconds() for j in jobs.itertuples()],
                                "latencies": failure_latencies(jobs, snakemake_job_events(text))}
                print(f"   exit {code} after {wall:.0f} s, jobs {out['limit']['states']}", flush=True)
                out["stopped"]["accounting"] = cluster.stop()
                save()
        if "fail_squeue" not in out:
            with OneNodeCluster(fresh(scratch / "cluster-noacct"), accounting=False) as cluster:
                print("4. a failing job, no accounting, status by squeue (the profile's) ...", flush=True)
                probe = subprocess.run(["sacct", "-X"], env=cluster.env(), capture_output=True, text=True)
                out["sacct_without_accounting"] = (probe.stdout + probe.stderr).strip().splitlines()[-1]
                out["fail_squeue"] = failing_settle(cluster, fail_noacct_wd, None, scratch / "fail-noacct.log")
                print(f"   {out['fail_squeue']}", flush=True)
                out["stopped"]["no accounting"] = cluster.stop()
                save()
    finally:
        print(f"daemons stopped (exit codes): {out.get('stopped')}", flush=True)
    if "local" not in out:
        print("5. local reference (mpirun, 2 ranks) ...", flush=True)
        code, wall, _ = run(snakemake(local_wd, "--config", f"fidelity={json.dumps(RANKS)}", "--", "all",
                                      limited_target, profile=False), None, scratch / "local.log")
        out["local"] = {"returncode": code, "wall_s": wall}
        print(f"   exit {code} after {wall:.0f} s", flush=True)
        save()
    table = compare(slurm_wd / "results/smoke/runs", local_wd / "results/smoke/runs", tolerance)
    checks = evaluate(out, table, slurm_wd, limited_run)
    write(out, checks, table, tolerance)
    if not args.keep:
        shutil.rmtree(scratch, ignore_errors=True)
    failed = [name for name, ok in checks.items() if not ok]
    print("all checks passed" if not failed else "FAILED: " + "; ".join(failed))
    return 1 if failed else 0


def dry_run(limited_target, limited_config, retries):
    """``snakemake -n`` of phases 2, 3 and 5 in a scratch folder: the workflow through
    ``profiles/slurm``, the time-limited spread (a point outside the sweep, asked for by its
    path) and the local reference. Returns 0 if each resolves, else 1 (its output's tail printed)."""
    phases = {
        "2. workflow through profiles/slurm": ("--config", f"fidelity={json.dumps(RANKS)}"),
        "3. time-limited spread": ("--config", f"fidelity={json.dumps(limited_config)}", "--retries", str(retries),
                                   "--", limited_target),
        "5. local reference": ("--config", f"fidelity={json.dumps(RANKS)}", "--", "all", limited_target),
    }
    failed = 0
    with tempfile.TemporaryDirectory(prefix="spreadmap-slurm-dry-") as tmp:
        for name, extra in phases.items():
            cmd = snakemake(Path(tmp), "-n", *extra, profile=not name.startswith("5."))
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
            failed += proc.returncode != 0
            print(f"{name}: {'resolves' if proc.returncode == 0 else 'FAILED'}", flush=True)
            if proc.returncode:
                print("\n".join((proc.stdout + proc.stderr).strip().splitlines()[-10:]), flush=True)
    return 1 if failed else 0


def evaluate(out, table, slurm_wd, limited_run):
    """The benchmark's checks, by name: True where passed."""
    checks = {"SLURM workflow finished (exit 0) with the maps": (
        out["workflow"]["returncode"] == 0 and (slurm_wd / "results/smoke/maps/process_map.png").exists())}
    states = out["limit"]["states"]
    checks["time-limited spread: killed (TIMEOUT), resubmitted, finished"] = (
        out["limit"]["returncode"] == 0 and "TIMEOUT" in states and states[-1] == "COMPLETED")
    for name in ("fail_sacct", "fail_squeue"):
        f = out[name]
        lat = [s for _, s in f["latencies"].values()]
        checks[f"{name}: workflow stopped with an error after 3 failed attempts"] = (
            f["returncode"] != 0 and len(lat) == 3)
        checks[f"{name}: each failure seen within {SEEN_WITHIN_S} s"] = bool(lat) and all(
            s is not None and s <= SEEN_WITHIN_S for s in lat)
        checks[f"{name}: the rule's error names the launcher and the fix"] = (
            "MPI could not start" in f["rule_error"] and "'srun'" in f["rule_error"] and "Fix:" in f["rule_error"])
    dataset = slurm_wd / "results/smoke/dataset.csv"
    checks["dataset.csv from SLURM has the 6 runs"] = dataset.is_file() and len(pd.read_csv(dataset)) == 6
    checks["every SLURM run within 4 sds of a two-run difference of its local twin"] = (
        len(table) > 0 and bool(table.within_4_sd.all()))
    limited = table[table.run == limited_run]
    if len(limited):
        limited = limited.iloc[0]
        checks["time-limited spread resumed from a checkpoint"] = bool(limited.resumed_from_step > 0)
        checks["time-limited spread: roller at the end of its travel within 1e-6 m, every particle accounted for"] = (
            bool(limited.roller_end_dm < 1e-6 and limited.particles_balance == 0 and limited.lost == 0))
    else:
        checks["time-limited spread resumed from a checkpoint"] = False
    checks["SLURM spreads launched with srun --mpi=pmix"] = (
        len(table) > 0 and bool((table.slurm_launcher == "srun --mpi=pmix").all()))
    checks["no half-written file"] = half_written_files(slurm_wd / "results") == []
    return checks


def write(out, checks, table, tolerance):
    dest = ROOT / "benchmarks/measured"
    table.to_csv(dest / "slurm.csv", index=False)
    v, ls = out["versions"], out["limit_setup"]
    lat = lambda f: ", ".join(f"job {j} {s}: {t:.0f} s" if t is not None else f"job {j} {s}: not seen"  # noqa: E731
                              for j, (s, t) in f["latencies"].items())
    lines = [
        "# The SLURM path on a real one-node cluster",
        "",
        f"Measured at commit {out.get('commit', 'unknown')}, {machine()} by `.venv/bin/python "
        f"benchmarks/bench_slurm.py{out.get('args', '')}`, on 2 cores shared with other work (times are inflated "
        "and noisy).",
        "",
        f"- Debian 12 packages: slurm-wlm {v['slurm-wlm']}, munge {v['munge']}, PMIx (libpmix2) {v['libpmix2']}, "
        f"Open MPI (openmpi-bin) {v['openmpi-bin']}, MariaDB {v['mariadb-server']}, LIGGGHTS {v['liggghts']}; "
        "snakemake 9.27.1, snakemake-executor-plugin-slurm 2.8.0 (jobstep 0.6.1).",
        "- The cluster: munged, MariaDB, slurmdbd, slurmctld, slurmd on 127.0.0.1, 2 CPUs, "
        "`TaskPlugin=task/affinity`, `ProctrackType=proctrack/linuxproc`, `KillWait=10`, `MinJobAge=300`; "
        "configuration written to a scratch folder (`benchmarks/slurm_cluster.py`).",
        f"- Smoke workflow to maps through `profiles/slurm` (6 spreads + 1 settle, 2 ranks each): exit "
        f"{out['workflow']['returncode']}, {out['workflow']['wall_s']:.0f} s; the same locally (`--cores 2`, "
        f"mpirun) with the time-limited point: {out['local']['wall_s']:.0f} s.",
        f"- Time limit: the {ls['run']} spread with `runtime_min: 1`, {ls['checkpoints']} checkpoints, "
        f"`--retries {ls['retries']}`: SLURM job states "
        f"{', '.join(out['limit']['states'])} (elapsed {', '.join(f'{s:.0f}' for s in out['limit']['elapsed_s'])} s), "
        f"exit {out['limit']['returncode']}, {out['limit']['wall_s']:.0f} s; "
        f"seen after the job's end: {lat(out['limit']) or 'n/a'}.",
        f"- A settle that cannot start MPI (launcher forced to plain `srun`), accounting on, status by sacct: "
        f"exit {out['fail_sacct']['returncode']} after {out['fail_sacct']['wall_s']:.0f} s; seen after each "
        f"job's end: {lat(out['fail_sacct'])}.",
        f"- The same without accounting (`sacct`: \"{out['sacct_without_accounting']}\"), status by squeue "
        f"(the profile's): exit {out['fail_squeue']['returncode']} after {out['fail_squeue']['wall_s']:.0f} s; "
        f"seen: {lat(out['fail_squeue'])}.",
        f"- The rule's error line: `{out['fail_squeue']['rule_error']}`",
        "- Tolerance: 4 sds of a two-run difference, 4 x sqrt(2) pooled seed sds of the smoke scene (resume.md): "
        + ", ".join(f"{k} {t:.3g}" for k, t in tolerance.items()) + ".",
        f"- Daemons stopped by process id (exit codes): {out['stopped']}.",
        "",
        "| check | passed |",
        "|---|---|",
        *[f"| {name} | {'yes' if ok else 'NO'} |" for name, ok in checks.items()],
        "",
        "Per run, SLURM minus local (`slurm.csv`):",
        "",
        table[["run", "slurm_launcher", "resumed_from_step", "steps", "particles_balance", "roller_end_dm",
               "bit_identical", "slurm_wall_s",
               "local_wall_s", *[f"d_{k}" for k in METRICS], "within_4_sd"]].to_markdown(index=False, floatfmt=".3g")
        if len(table) else "(no run finished both on SLURM and locally)",
        "",
    ]
    (dest / "slurm.md").write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
