"""The cluster and workstation profiles: dry runs plan the sweep with the fidelity level's
MPI ranks, memory and wall-clock limit, as config.yaml gives them. No sbatch, no LIGGGHTS."""
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.dem.liggghts import mpi_command

ROOT = Path(__file__).resolve().parent.parent
CLUSTER_RULES = {"settle", "spread"}   # submitted to SLURM; every other rule is a localrule


def dry_run(workdir, profile, *config):
    """Snakemake's printed plan of ``snakemake -n --profile profiles/<profile>``, run in ``workdir``."""
    cmd = [sys.executable, "-m", "snakemake", "-n", "--profile", f"profiles/{profile}",
           "-s", str(ROOT / "Snakefile"), "-d", str(workdir), "--configfile", str(ROOT / "config.yaml")]
    if config:
        cmd += ["--config", *config]
    env = {k: v for k, v in os.environ.items() if k != "SNAKEMAKE_PROFILE"}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout + proc.stderr


def planned_jobs(plan):
    """(rule, resources) of every job in a dry run's plan; numeric resources as ints."""
    jobs = []
    for rule, body in re.findall(r"^(?:local)?rule (\w+):\n((?:    .*\n?)*)", plan, re.M):
        line = re.search(r"^    resources: (.*)$", body, re.M)
        resources = dict(item.split("=", 1) for item in line.group(1).split(", ")) if line else {}
        jobs.append((rule, {k: int(v) if v.isdigit() else v for k, v in resources.items()}))
    return jobs


def sweep_size(config):
    sweep = config["sweep"]
    return len(sweep["U_mm_s"]) * len(sweep["omega_rad_s"]) * sweep["replicates"]


def sbatch_call(resources, threads):
    """The sbatch command line the SLURM plugin would build for a job with these resources."""
    from snakemake_executor_plugin_slurm.submit_string import get_submit_command

    class Resources(dict):
        __getattr__ = dict.__getitem__

    job = SimpleNamespace(resources=Resources(resources), threads=threads)
    return get_submit_command(job, dict(run_uuid="id", slurm_logfile="slurm.log", comment_str="rule",
                                        account="", partition="", workdir="/work"))


@pytest.fixture(scope="module")
def config():
    return load_config(ROOT / "config.yaml")


def test_slurm_profile_plans_the_paper_sweep_with_the_levels_resources(tmp_path, config):
    paper = scene(config, "paper")
    assert paper.mpi_ranks > 1 and paper.runtime_min and paper.mem_mb_per_rank
    jobs = planned_jobs(dry_run(tmp_path, "slurm", "level=paper"))
    spreads = [res for rule, res in jobs if rule == "spread"]
    assert len(spreads) == sweep_size(config) == 45
    settles = [res for rule, res in jobs if rule == "settle"]
    assert len(settles) == config["sweep"]["replicates"]
    for res in spreads + settles:
        assert res["mpi"] == res["tasks"] == paper.mpi_ranks          # 32 ranks
        assert res["cpus_per_task"] == 1                               # from the profile
        assert res["runtime"] == paper.runtime_min                     # 240 min
        assert res["mem_mb_per_cpu"] == paper.mem_mb_per_rank          # 4000 MB a rank
        assert res["mem_mb"] == paper.mem_mb_per_rank * paper.mpi_ranks
    # What sbatch gets for one spread job: one CPU and its memory per rank, the time limit.
    call = sbatch_call(spreads[0], threads=paper.mpi_ranks)
    for flag in (f"--ntasks={paper.mpi_ranks}", "--cpus-per-task=1",
                 f"--mem-per-cpu {paper.mem_mb_per_rank}", f"-t {paper.runtime_min}"):
        assert re.search(rf"(^| ){re.escape(flag)}( |$)", call), (flag, call)
    # Every rule but settle and spread runs on the submitting host.
    # (snakefmt writes the list one rule a line)
    localrules = re.search(r"^localrules:((?:\s*\w+,)+)", (ROOT / "Snakefile").read_text(), re.M).group(1)
    names = {name.strip() for name in localrules.split(",") if name.strip()}
    assert names == {rule for rule, _ in jobs} - CLUSTER_RULES


def test_local_profile_plans_the_default_sweep(tmp_path, config):
    default = scene(config, "default")
    jobs = planned_jobs(dry_run(tmp_path, "local"))
    spreads = [res for rule, res in jobs if rule == "spread"]
    assert len(spreads) == sweep_size(config) == 45
    for res in spreads:
        assert "mpi" not in res                    # one rank: no MPI job for the SLURM plugin
        assert res["tasks"] == default.mpi_ranks == 1
        assert res["runtime"] == default.runtime_min
        assert res["mem_mb"] == default.mem_mb_per_rank
    # The same single-rank job on SLURM is a plain one-task job (mpi=1 would be refused).
    call = sbatch_call({**spreads[0], "cpus_per_task": 1}, threads=1)
    for flag in ("--ntasks=1", "--cpus-per-task=1", f"-t {default.runtime_min}"):
        assert re.search(rf"(^| ){re.escape(flag)}( |$)", call), (flag, call)


def test_cluster_keys_are_optional(config):
    level = {k: v for k, v in config["fidelity"]["smoke"].items() if k not in ("runtime_min", "mem_mb_per_rank")}
    bare = load_config({**config, "fidelity": {**config["fidelity"], "bare": level}})
    s = scene(bare, "bare")
    assert s.runtime_min is None and s.mem_mb_per_rank is None


def test_slurm_profile_leaves_the_launcher_to_the_job_and_polls_with_squeue(monkeypatch):
    """The profile forces no launcher (each job picks and checks one at start-up: srun --mpi=pmix
    where SLURM offers pmix, else mpirun) and asks squeue for job states, which works without an
    accounting database too (benchmarks/measured/slurm.md)."""
    profile = yaml.safe_load((ROOT / "profiles/slurm/config.yaml").read_text())
    assert profile["executor"] == "slurm" and profile["rerun-incomplete"] is True
    assert "SPREADMAP_MPI_LAUNCHER" not in profile.get("precommand", "")
    assert profile["slurm-status-command"] == "squeue" and profile["retries"] >= 1
    assert profile["slurm-init-seconds-before-status-checks"] <= 60
    monkeypatch.setenv("SPREADMAP_MPI_LAUNCHER", "srun --mpi=pmix")
    assert mpi_command(32) == ["srun", "--mpi=pmix", "-n", "32"]
    assert mpi_command(1) == []
    monkeypatch.delenv("SPREADMAP_MPI_LAUNCHER")
    monkeypatch.delenv("SLURM_JOB_ID", raising=False)
    assert mpi_command(32)[:3] == ["mpirun", "-np", "32"]
