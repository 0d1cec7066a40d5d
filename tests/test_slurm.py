"""The SLURM path's own pieces without a scheduler: the MPI launcher's start-up check and its
error, the one-node cluster's configuration, and reading Snakemake's log for when it saw a job
end. The real-scheduler run is ``benchmarks/bench_slurm.py`` (benchmarks/measured/slurm.md)."""
import signal
import stat
import subprocess
import sys
import time

import psutil
import pytest

from analysis.dem.liggghts import MpiStartError, check_launcher, run
from benchmarks.slurm_cluster import OneNodeCluster, snakemake_job_events


def test_a_launcher_that_cannot_start_mpi_is_named_with_the_fix(tmp_path, monkeypatch):
    (tmp_path / "in.txt").write_text('print "hello"\n')
    monkeypatch.setenv("SPREADMAP_MPI_LAUNCHER", "false")  # a launcher that starts nothing
    with pytest.raises(MpiStartError) as err:
        run(tmp_path / "in.txt", tmp_path / "log.txt", ranks=2)
    message = str(err.value)
    assert "\n" not in message
    assert "MPI could not start 2 LIGGGHTS ranks with 'false' (SPREADMAP_MPI_LAUNCHER)" in message
    assert "Fix: set SPREADMAP_MPI_LAUNCHER" in message


def test_mpirun_starts_two_ranks_and_the_run_records_its_launcher(tmp_path, monkeypatch):
    monkeypatch.delenv("SPREADMAP_MPI_LAUNCHER", raising=False)
    monkeypatch.delenv("SLURM_JOB_ID", raising=False)
    check_launcher(["mpirun"], 2)
    (tmp_path / "in.txt").write_text('print "hello"\n')
    result = run(tmp_path / "in.txt", tmp_path / "log.txt", ranks=2)
    assert result["launcher"] == "mpirun" and result["ranks"] == 2


def test_cluster_configuration_is_written_to_its_own_folder(tmp_path):
    cluster = OneNodeCluster(tmp_path / "c", accounting=True, cpus=2, kill_wait_s=10)
    cluster.write_config()
    conf = dict(line.split("=", 1) for line in cluster.conf.read_text().splitlines() if not line.startswith("Node")
                and not line.startswith("Partition"))
    assert conf["AccountingStorageType"] == "accounting_storage/slurmdbd" and conf["KillWait"] == "10"
    for key in ("StateSaveLocation", "SlurmdSpoolDir", "SlurmctldLogFile"):
        assert conf[key].startswith(str(tmp_path)), key
    assert conf["AuthInfo"] == f"socket={tmp_path / 'c' / 'munge' / 'munge.socket'}"
    dbd = tmp_path / "c" / "etc" / "slurmdbd.conf"
    assert stat.S_IMODE(dbd.stat().st_mode) == 0o600 and "StoragePass=" in dbd.read_text()
    assert stat.S_IMODE((tmp_path / "c" / "munge" / "munge.key").stat().st_mode) == 0o400
    bare = OneNodeCluster(tmp_path / "b", accounting=False)
    bare.write_config()
    assert "AccountingStorageType=accounting_storage/none" in bare.conf.read_text()
    assert not (tmp_path / "b" / "etc" / "slurmdbd.conf").exists()


def test_snakemake_log_tells_when_each_job_was_submitted_and_seen_failing():
    log = """Job 5 has been submitted with SLURM jobid 4 (log: x/4.log).
[Wed Dec  2 00:49:50 2026]
Error in rule settle:
    message: SLURM-job '4' failed, SLURM status is: 'FAILED'.
    jobid: 5
    external_jobid: 4
Trying to restart job 5.
"""
    events = snakemake_job_events(log)
    assert list(events.event) == ["submitted", "error"] and list(events.job) == [4, 4]
    error = events[events.event == "error"].iloc[0]
    assert error.rule == "settle" and str(error.seen) == "2026-12-02 00:49:50"


LONG_INPUT = """atom_style granular
atom_modify map array sort 0 0
boundary p p p
newton off
communicate single vel yes
units si
region box block 0 0.001 0 0.001 0 0.001 units box
create_box 1 box
neighbor 0.0001 bin
timestep 1e-6
run 100000000
"""


def test_a_run_stopped_by_sigterm_is_refused(tmp_path):
    """SLURM ends a job at its time limit with SIGTERM; LIGGGHTS then writes its own restart file
    and exits 0 with no ERROR line: the wrapper must not take that for a finished run."""
    (tmp_path / "long.in").write_text(LONG_INPUT)
    proc = subprocess.Popen([sys.executable, "-m", "analysis.dem.liggghts", str(tmp_path / "long.in")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline, ranks = time.time() + 60, []
    while time.time() < deadline and not ranks:
        ranks = [c for c in psutil.Process(proc.pid).children(recursive=True) if c.name() == "liggghts"]
        time.sleep(0.1)
    time.sleep(3)  # into its run (an empty box: set up at once)
    for rank in ranks:
        rank.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 1, out + err
    assert "was stopped by SIGTERM or SIGINT" in err and "exit code 0" in err
    assert list(tmp_path.glob("restart_forced_liggghts_*.data"))      # LIGGGHTS' own handler ran
