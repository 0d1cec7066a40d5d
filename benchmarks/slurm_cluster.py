"""A one-node SLURM cluster on this machine, from Debian's packages, for a real-scheduler run.

:class:`OneNodeCluster` writes every configuration file into a folder of its own
(nothing under ``/etc``), starts ``munged``, optionally MariaDB and ``slurmdbd``
(job accounting: what ``sacct`` needs), then ``slurmctld`` and ``slurmd``, each
in the foreground as a child of this process, and stops every one of them by
its process id. The client commands (``sbatch``, ``squeue``, ``sacct``,
``srun``) find the cluster through ``SLURM_CONF``: :meth:`OneNodeCluster.env`.

Debian packages: ``slurm-wlm munge libpmix-dev`` (``libpmix-dev`` lets SLURM's
``pmix`` plugin load the PMIx library), plus ``slurmdbd mariadb-server`` for
accounting. Root only: the daemons run as root (``SlurmUser=root``).

Used by ``benchmarks/bench_slurm.py``.
"""
from __future__ import annotations

import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

#: Debian packages the cluster needs, without and with accounting.
APT_PACKAGES = ("slurm-wlm", "munge", "libpmix-dev")
APT_PACKAGES_ACCOUNTING = ("slurmdbd", "mariadb-server")
#: Where SLURM's commands look for their configuration without ``SLURM_CONF``.
SYSTEM_CONF = Path("/etc/slurm/slurm.conf")


class ClusterError(RuntimeError):
    """A daemon did not start or the cluster did not come up; the message names which and why."""


def free_port() -> int:
    """A TCP port on the loopback address that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def missing_commands(accounting: bool) -> list[str]:
    """The daemons and tools the cluster needs that are not on PATH (or in /usr/sbin)."""
    needed = ["munged", "slurmctld", "slurmd", "sbatch", "squeue", "srun", "scontrol"]
    if accounting:
        needed += ["slurmdbd", "mariadbd", "mariadb-install-db", "mariadb", "sacctmgr", "sacct"]
    path = os.environ.get("PATH", "") + ":/usr/sbin:/sbin"
    return [cmd for cmd in needed if shutil.which(cmd, path=path) is None]


class OneNodeCluster:
    """munge + slurmctld + slurmd (+ MariaDB + slurmdbd) on localhost, configured under ``root``.

    Parameters
    ----------
    root : path
        An empty or new folder for the configuration, state, sockets and logs.
    accounting : bool
        Start MariaDB and ``slurmdbd`` and set ``AccountingStorageType`` so that
        ``sacct`` answers; without it ``sacct`` says accounting is disabled.
    cpus, memory_mb : int
        The node's CPUs and memory as SLURM schedules them.
    kill_wait_s : int
        Seconds between SIGTERM and SIGKILL of a job over its time limit.
    min_job_age_s : int
        How long ``squeue --states=all`` keeps showing a finished job.

    Use as a context manager: every daemon is stopped by its process id on exit.
    """

    def __init__(self, root, accounting=True, cpus=2, memory_mb=8000, kill_wait_s=10, min_job_age_s=300,
                 cluster_name="spreadmap", account="spreadmap"):
        self.root = Path(root).resolve()
        self.accounting = accounting
        self.cpus, self.memory_mb = cpus, memory_mb
        self.kill_wait_s, self.min_job_age_s = kill_wait_s, min_job_age_s
        self.cluster_name, self.account = cluster_name, account
        self.host = socket.gethostname().split(".")[0]
        self.procs: dict[str, subprocess.Popen] = {}
        self.conf = self.root / "etc" / "slurm.conf"
        self._sbin = os.environ.get("PATH", "") + ":/usr/sbin:/sbin"

    # -- configuration ---------------------------------------------------------------------
    def env(self) -> dict:
        """The environment for SLURM's client commands (and Snakemake) to reach this cluster."""
        return {**os.environ, "SLURM_CONF": str(self.conf)}

    def _which(self, cmd: str) -> str:
        path = shutil.which(cmd, path=self._sbin)
        if path is None:
            raise ClusterError(f"'{cmd}' not found: install Debian's "
                               f"{' '.join(APT_PACKAGES + (APT_PACKAGES_ACCOUNTING if self.accounting else ()))}")
        return path

    def write_config(self) -> None:
        """slurm.conf (and slurmdbd.conf), a munge key and the state folders under ``root``."""
        for sub in ("etc", "state", "spool", "log", "run", "munge"):
            (self.root / sub).mkdir(parents=True, exist_ok=True)
        os.chmod(self.root / "munge", 0o700)
        self.munge_socket = self.root / "munge" / "munge.socket"
        key = self.root / "munge" / "munge.key"
        if not key.exists():
            key.write_bytes(secrets.token_bytes(1024))
            os.chmod(key, 0o400)
        self.ports = {name: free_port() for name in ("slurmctld", "slurmd", "slurmdbd", "mariadb")}
        auth = f"AuthType=auth/munge\nAuthInfo=socket={self.munge_socket}\n"
        lines = [
            f"ClusterName={self.cluster_name}",
            f"SlurmctldHost={self.host}(127.0.0.1)",
            f"SlurmctldPort={self.ports['slurmctld']}",
            f"SlurmdPort={self.ports['slurmd']}",
            "SlurmUser=root", "SlurmdUser=root",
            auth.strip(),
            f"StateSaveLocation={self.root / 'state'}",
            f"SlurmdSpoolDir={self.root / 'spool'}",
            f"SlurmctldPidFile={self.root / 'run' / 'slurmctld.pid'}",
            f"SlurmdPidFile={self.root / 'run' / 'slurmd.pid'}",
            f"SlurmctldLogFile={self.root / 'log' / 'slurmctld.log'}",
            f"SlurmdLogFile={self.root / 'log' / 'slurmd.log'}",
            "ProctrackType=proctrack/linuxproc",
            "TaskPlugin=task/affinity",
            "SelectType=select/cons_tres",
            "SelectTypeParameters=CR_Core_Memory",
            "ReturnToService=2",
            "MpiDefault=none",
            f"KillWait={self.kill_wait_s}",
            f"MinJobAge={self.min_job_age_s}",
            "JobCompType=jobcomp/none",
            f"NodeName={self.host} NodeAddr=127.0.0.1 CPUs={self.cpus} RealMemory={self.memory_mb} State=UNKNOWN",
            f"PartitionName=debug Nodes={self.host} Default=YES MaxTime=INFINITE State=UP",
        ]
        if self.accounting:
            lines += ["AccountingStorageType=accounting_storage/slurmdbd",
                      "AccountingStorageHost=127.0.0.1",
                      f"AccountingStoragePort={self.ports['slurmdbd']}",
                      f"AccountingStoragePass={self.munge_socket}",  # slurmdbd: the munge socket
                      "JobAcctGatherType=jobacct_gather/linux"]
            self.db_password = secrets.token_hex(12)
            dbd = self.root / "etc" / "slurmdbd.conf"
            dbd.write_text(
                auth
                + "DbdHost=localhost\nDbdAddr=127.0.0.1\n"
                + f"DbdPort={self.ports['slurmdbd']}\nSlurmUser=root\n"
                + f"PidFile={self.root / 'run' / 'slurmdbd.pid'}\nLogFile={self.root / 'log' / 'slurmdbd.log'}\n"
                + "StorageType=accounting_storage/mysql\nStorageHost=127.0.0.1\n"
                + f"StoragePort={self.ports['mariadb']}\nStorageUser=slurm\nStoragePass={self.db_password}\n"
                + "StorageLoc=slurm_acct_db\n")
            os.chmod(dbd, 0o600)
        else:
            lines.append("AccountingStorageType=accounting_storage/none")
        self.conf.write_text("\n".join(lines) + "\n")

    # -- daemons -----------------------------------------------------------------------------
    def _start(self, name: str, cmd: list[str], env=None) -> subprocess.Popen:
        log = open(self.root / "log" / f"{name}.out", "ab")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env=env or self.env(), start_new_session=True)
        log.close()
        self.procs[name] = proc
        return proc

    def _wait(self, name: str, ready, timeout_s: float = 60) -> None:
        """Wait until ``ready()`` is true; fail naming the daemon and its log's tail if it died or timed out."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            proc = self.procs.get(name)
            if proc is not None and proc.poll() is not None:
                break
            try:
                if ready():
                    return
            except (OSError, subprocess.SubprocessError):
                pass
            time.sleep(0.5)
        tail = []
        for path in sorted((self.root / "log").glob(f"{name}*")):
            tail += path.read_text(errors="replace").strip().splitlines()[-6:]
        state = "exited" if name in self.procs and self.procs[name].poll() is not None else "not ready"
        raise ClusterError(f"{name} {state} after {timeout_s:.0f} s; its log:\n" + "\n".join(tail))

    def _ok(self, *cmd) -> bool:
        return subprocess.run(cmd, env=self.env(), capture_output=True, timeout=30).returncode == 0

    def start(self) -> OneNodeCluster:
        """Write the configuration and start every daemon; returns once the node is idle."""
        self.write_config()
        self._link_system_config()
        self._start("munged", [self._which("munged"), "--foreground", "--force",
                               f"--key-file={self.root / 'munge' / 'munge.key'}",
                               f"--socket={self.munge_socket}",
                               f"--pid-file={self.root / 'munge' / 'munged.pid'}",
                               f"--log-file={self.root / 'log' / 'munged.log'}",
                               f"--seed-file={self.root / 'munge' / 'munged.seed'}"])
        self._wait("munged", lambda: self.munge_socket.exists())
        if self.accounting:
            self._start_database()
            self._start("slurmdbd", [self._which("slurmdbd"), "-D"])
            self._wait("slurmdbd", lambda: _listening(self.ports["slurmdbd"]))
            subprocess.run(["sacctmgr", "-i", "add", "cluster", self.cluster_name], env=self.env(),
                           capture_output=True, timeout=30)
        self._start("slurmctld", [self._which("slurmctld"), "-D", "-i", "-f", str(self.conf)])
        self._wait("slurmctld", lambda: self._ok("scontrol", "ping"))
        self._start("slurmd", [self._which("slurmd"), "-D", "-f", str(self.conf), "-N", self.host])
        self._wait("slurmd", lambda: self.node_state() in ("idle", "mixed", "allocated"))
        if self.accounting:
            for cmd in (["add", "account", self.account, f"cluster={self.cluster_name}"],
                        ["add", "user", "root", f"account={self.account}", f"cluster={self.cluster_name}"]):
                proc = subprocess.run(["sacctmgr", "-i", *cmd], env=self.env(), capture_output=True, text=True,
                                      timeout=30)
                if proc.returncode != 0 and "Nothing new added" not in proc.stdout + proc.stderr:
                    raise ClusterError(f"sacctmgr {' '.join(cmd)} failed: {proc.stdout}{proc.stderr}")
            self._wait("slurmctld", lambda: self._ok("sacct", "-n", "-X"))
        return self

    def _link_system_config(self) -> None:
        """Make ``/etc/slurm/slurm.conf`` a symbolic link to this cluster's ``slurm.conf``.

        The client commands reach the cluster through ``SLURM_CONF``, but
        snakemake-executor-plugin-slurm's job step removes every ``SLURM_*``
        variable but the job's id before it runs a rule, so ``srun`` inside a
        job reads SLURM's default path. A file already there that is not such
        a link is never replaced: the cluster refuses to start instead.
        """
        link = SYSTEM_CONF
        if _dead(link):  # left by a test cluster that crashed: its folder is gone
            link.unlink()
        elif link.exists():
            raise ClusterError(f"{link} exists (-> {link.resolve()}): this machine has a SLURM configuration, "
                               "which the one-node test cluster does not replace; remove it if it is a test's")
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(self.conf)
        self._linked = True

    def _start_database(self) -> None:
        data, sock = self.root / "mariadb", self.root / "run" / "mariadb.sock"
        proc = subprocess.run([self._which("mariadb-install-db"), "--no-defaults", f"--datadir={data}",
                               "--user=root", "--auth-root-authentication-method=socket", "--skip-test-db"],
                              capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            raise ClusterError(f"mariadb-install-db failed: {proc.stdout[-2000:]}{proc.stderr[-2000:]}")
        self._start("mariadb", [self._which("mariadbd"), "--no-defaults", f"--datadir={data}", "--user=root",
                                f"--socket={sock}", f"--port={self.ports['mariadb']}", "--bind-address=127.0.0.1",
                                f"--pid-file={self.root / 'run' / 'mariadb.pid'}",
                                f"--log-error={self.root / 'log' / 'mariadb.log'}"])
        client = [self._which("mariadb"), "--no-defaults", f"--socket={sock}", "-u", "root"]
        self._wait("mariadb", lambda: subprocess.run([*client, "-e", "select 1"], capture_output=True,
                                                      timeout=10).returncode == 0)
        sql = (f"CREATE OR REPLACE USER 'slurm'@'127.0.0.1' IDENTIFIED BY '{self.db_password}';"
               "GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1'; FLUSH PRIVILEGES;")
        proc = subprocess.run([*client, "-e", sql], capture_output=True, text=True, timeout=30)
        if proc.returncode != 0:
            raise ClusterError(f"creating the accounting database's user failed: {proc.stderr}")

    def node_state(self) -> str:
        """The node's state as ``sinfo`` prints it (``idle``, ``mixed``, ``down``, ...)."""
        proc = subprocess.run(["sinfo", "-h", "-N", "-o", "%T"], env=self.env(), capture_output=True, text=True,
                              timeout=30)
        return proc.stdout.strip().rstrip("*~#")

    def stop(self) -> dict:
        """Stop every daemon this object started, by its process id, newest first.

        Jobs still queued or running are cancelled first, and their end awaited, so that
        no job step (``slurmstepd`` and the ranks under it, which outlive ``slurmd``) is left.
        SIGTERM, then SIGKILL after 20 s. Returns ``{daemon: exit code}``.
        """
        if self.procs.get("slurmctld") is not None and self.procs["slurmctld"].poll() is None:
            try:
                self.cancel_jobs()
            except (ClusterError, OSError, subprocess.SubprocessError) as err:
                print(f"warning: {err}", file=sys.stderr)
        codes = {}
        for name, proc in reversed(list(self.procs.items())):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(timeout=20)
            codes[name] = proc.returncode
        self.procs.clear()
        if getattr(self, "_linked", False) and SYSTEM_CONF.is_symlink() and Path(os.readlink(SYSTEM_CONF)) == self.conf:
            SYSTEM_CONF.unlink()
            self._linked = False
        return codes

    def cancel_jobs(self, timeout_s: float = 120) -> None:
        """Cancel every job of the cluster and wait until none is pending, running or completing."""
        squeue = ["squeue", "-h", "-o", "%i", "-t", "PENDING,RUNNING,COMPLETING,CONFIGURING,SUSPENDED"]
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            proc = subprocess.run(squeue, env=self.env(), capture_output=True, text=True, timeout=30)
            jobs = proc.stdout.split()
            if proc.returncode != 0 or not jobs:
                return
            subprocess.run(["scancel", *jobs], env=self.env(), capture_output=True, timeout=30)
            time.sleep(2)
        raise ClusterError(f"jobs {' '.join(jobs)} still there {timeout_s:.0f} s after scancel")

    def versions(self) -> dict:
        """The SLURM, munge, PMIx and Open MPI versions installed (Debian package versions)."""
        out = {}
        for package in ("slurm-wlm", "slurmd", "munge", "libpmix2", "openmpi-bin", "mariadb-server", "liggghts"):
            proc = subprocess.run(["dpkg-query", "-W", "-f", "${Version}", package], capture_output=True, text=True)
            out[package] = proc.stdout.strip() if proc.returncode == 0 else None
        return out

    def __enter__(self) -> OneNodeCluster:
        try:
            return self.start()
        except BaseException:
            self.stop()
            raise

    def __exit__(self, *exc) -> None:
        self.stop()


def _dead(link: Path) -> bool:
    """A symbolic link whose target is gone (a test cluster's, left by a crash)."""
    return link.is_symlink() and not link.exists()


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(1)
        return s.connect_ex(("127.0.0.1", port)) == 0


def job_table(env: dict, accounting: bool) -> pd.DataFrame:
    """Every job the cluster knows: id, name, state, submit, start and end times.

    With accounting from ``sacct``; without it from ``squeue --states=all``, which keeps
    a finished job for ``MinJobAge`` seconds only.
    """
    if accounting:
        cmd = ["sacct", "-X", "-P", "-n", "-o", "JobIDRaw,JobName%100,State,Submit,Start,End"]
    else:
        cmd = ["squeue", "--states=all", "-h", "-o", "%i|%j|%T|%V|%S|%e"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=60)
    if proc.returncode != 0:
        raise ClusterError(f"{' '.join(cmd)} failed: {proc.stderr.strip()}")
    rows = [line.split("|") for line in proc.stdout.splitlines() if line.count("|") == 5]
    table = pd.DataFrame(rows, columns=["job", "name", "state", "submit", "start", "end"])
    table["state"] = table["state"].str.split().str[0]   # "CANCELLED by 0" -> "CANCELLED"
    for col in ("submit", "start", "end"):
        table[col] = pd.to_datetime(table[col], errors="coerce", format="%Y-%m-%dT%H:%M:%S")
    return table.astype({"job": int}).sort_values("job", ignore_index=True)


_LOG_TIME = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")


def snakemake_job_events(log_text: str) -> pd.DataFrame:
    """When Snakemake reported each SLURM job finished or failed, from its log.

    Returns one row per event: ``job`` (SLURM id), ``event`` (``error`` from an
    ``Error in rule`` block naming the ``external_jobid``; ``submitted``), ``rule``
    and ``seen`` (the log's time stamp before it, 1 s resolution, or the time of the
    line itself for submissions, which have none: the last stamp before them).
    """
    rows, stamp, rule = [], None, None
    lines = log_text.splitlines()
    for i, line in enumerate(lines):
        m = _LOG_TIME.match(line.strip())
        if m:
            stamp = pd.to_datetime(m.group(1), format="%a %b %d %H:%M:%S %Y")
            continue
        m = re.match(r"^Error in rule (\w+):", line)
        if m:
            rule = m.group(1)
            for follow in lines[i + 1:i + 15]:
                jid = re.match(r"^\s+external_jobid: (\d+)", follow)
                if jid:
                    rows.append({"job": int(jid.group(1)), "event": "error", "rule": rule, "seen": stamp})
                    break
            continue
        m = re.search(r"submitted with SLURM jobid (\d+)", line)
        if m:
            rows.append({"job": int(m.group(1)), "event": "submitted", "rule": None, "seen": stamp})
    return pd.DataFrame(rows, columns=["job", "event", "rule", "seen"])
