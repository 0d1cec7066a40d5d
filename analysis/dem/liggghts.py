"""Render a LIGGGHTS input from ``templates/``, run the real ``liggghts`` binary,
and read its log: fail loudly, with the error line and the input line it died at.

Traps of the Debian LIGGGHTS 3.8 build that this module guards against:

* it can die through ``MPI_Abort`` without printing its ERROR line (seen with a
  seed used twice), so seeds are checked here, before the run;
* ``-screen none`` crashes ``fix insert/pack``: the screen goes to a file;
* parallel runs in one folder would all write ``log.liggghts``: every run
  gets its own ``-log``.

Command line: ``python -m analysis.dem.liggghts INPUT [--np N] [--log FILE]``
runs an input file and prints its health as JSON.
"""
from __future__ import annotations

import argparse
import errno
import functools
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jinja2
import numpy as np
import pandas as pd

from analysis.config.reading import PROJECT_DIR
from analysis.physics import is_prime

TEMPLATES = PROJECT_DIR / "templates"


LIGGGHTS = os.environ.get("SPREADMAP_LIGGGHTS", "liggghts")


_SEED_PATTERNS = [r"particletemplate/sphere\s+(\S+)", r"particledistribution/discrete\S*\s+(\S+)",
                  r"\bseed\s+(\S+)"]


class LiggghtsError(RuntimeError):
    """LIGGGHTS failed, or its run is not physically sound; the message says why."""


class UnstableRunError(LiggghtsError):
    """The integration broke down: a kinetic-energy blow-up, or particles through the roller.
    A smaller time step is the cure (``timestep.unstable_retry_fraction``)."""


def render(template: str, **context) -> str:
    """Render ``templates/<template>`` with ``context``; unknown names are errors."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(TEMPLATES), undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    return env.get_template(template).render(**context)


def input_path(path: str | Path, run_dir: str | Path) -> str:
    """``path`` as an input in ``run_dir`` (LIGGGHTS' working directory) names it: relative.

    LIGGGHTS splits an input line at whitespace, so an absolute path under a
    project folder such as ``~/My Projects`` would break; the path from the
    run folder to a file of the same workflow holds only its own folder names.
    """
    rel = os.path.relpath(Path(path).resolve(), Path(run_dir).resolve())
    if any(c.isspace() for c in rel):
        raise LiggghtsError(f"LIGGGHTS cannot read {rel!r} from {str(run_dir)!r}: the path holds whitespace")
    return rel


def check_seeds(text: str) -> list[int]:
    """Every random seed in an input must be a distinct prime > 10000.

    LIGGGHTS aborts, sometimes silently, otherwise; checked here instead.
    """
    commands = [line.split("#")[0] for line in text.splitlines()]
    seeds = [tok for line in commands for pat in _SEED_PATTERNS for tok in re.findall(pat, line)]
    values = []
    for tok in seeds:
        if not tok.isdigit() or int(tok) <= 10000 or not is_prime(int(tok)):
            raise LiggghtsError(f"seed {tok!r} is not a prime > 10000 (LIGGGHTS aborts on it)")
        values.append(int(tok))
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise LiggghtsError(f"seed(s) {repeated} used twice (LIGGGHTS aborts without an ERROR line)")
    return values


class MpiStartError(LiggghtsError):
    """MPI could not start LIGGGHTS' ranks with the chosen launcher; the message names it and the fix."""


MPI_FIX = ("set SPREADMAP_MPI_LAUNCHER to a launcher that starts MPI ranks at your site, e.g. "
           "'srun --mpi=pmix' where `srun --mpi=list` shows pmix, or 'mpirun' "
           "(on a cluster: in profiles/slurm's precommand, after any `module load`)")


def launcher(ranks: int) -> tuple[list[str], str]:
    """The MPI launcher for ``ranks`` ranks and where it came from, checked once per process.

    1. ``SPREADMAP_MPI_LAUNCHER`` (read at each call; options split on whitespace,
       e.g. ``"srun --mpi=pmix"``) when it is set;
    2. inside a SLURM job (``SLURM_JOB_ID`` set): ``srun --mpi=pmix`` when SLURM offers
       the pmix plugin (``srun --mpi=list``), else ``mpirun`` within the allocation,
       whichever starts ``ranks`` ranks of LIGGGHTS first (:func:`check_launcher`);
       plain ``srun`` is never chosen: Debian's Open MPI has no SLURM PMI support;
    3. ``mpirun`` otherwise.

    Returns ``(launcher and its options, source)``. Raises :class:`MpiStartError`
    when, inside a SLURM job, no candidate starts.
    """
    override = os.environ.get("SPREADMAP_MPI_LAUNCHER", "").split()
    if override:
        return override, "SPREADMAP_MPI_LAUNCHER"
    job = os.environ.get("SLURM_JOB_ID")
    if not job:
        return ["mpirun"], "default"
    return list(_slurm_launcher(job, ranks)), f"chosen in SLURM job {job}"


@functools.cache
def _slurm_launcher(job: str, ranks: int) -> tuple[str, ...]:
    candidates = [("srun", "--mpi=pmix")] if "pmix" in _srun_mpi_plugins() else []
    candidates.append(("mpirun",))
    failures = []
    for candidate in candidates:
        try:
            check_launcher(list(candidate), ranks)
            return candidate
        except MpiStartError as err:
            failures.append(f"'{' '.join(candidate)}': {err.reason}")
    raise MpiStartError(f"MPI could not start {ranks} LIGGGHTS ranks in SLURM job {job}: tried "
                        + "; ".join(failures) + f". Fix: {MPI_FIX}")


def _srun_mpi_plugins() -> str:
    """``srun --mpi=list``'s answer (the MPI plugins this SLURM offers), '' without srun."""
    if shutil.which("srun") is None:
        return ""
    proc = subprocess.run(["srun", "--mpi=list"], capture_output=True, text=True, timeout=60)
    return proc.stdout + proc.stderr


def mpi_command(ranks: int, prefix: list[str] | None = None) -> list[str]:
    """The launcher prefix for ``ranks`` MPI ranks (none for one rank).

    ``prefix`` is the launcher and its options (default: :func:`launcher`'s
    choice). Open MPI's ``mpirun`` or ``mpiexec`` gets ``-np N``, plus
    ``--allow-run-as-root`` as root and ``--oversubscribe`` for more ranks than
    cores. Any other launcher gets ``-n N``: ``srun`` inside a SLURM job starts
    the ranks on the job's nodes itself.
    """
    if ranks <= 1:
        return []
    prefix = list(prefix) if prefix else launcher(ranks)[0]
    if Path(prefix[0]).name not in ("mpirun", "mpiexec"):
        return prefix + ["-n", str(ranks)]
    cmd = prefix + ["-np", str(ranks)]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    if ranks > (os.cpu_count() or 1) and "SLURM_JOB_ID" not in os.environ:
        cmd.append("--oversubscribe")
    return cmd


def launcher_env() -> dict:
    """The environment for the launcher: inside a SLURM job, the allocation's node list
    and tasks per node put back when they are missing.

    snakemake-executor-plugin-slurm's job step removes every ``SLURM_*`` variable but
    the job's id before it runs a rule, and Open MPI's ``mpirun`` then fails in its
    SLURM allocation module; ``scontrol show job -d`` still knows the allocation.
    """
    env = dict(os.environ)
    job = env.get("SLURM_JOB_ID")
    if job and not env.get("SLURM_TASKS_PER_NODE") and shutil.which("scontrol"):
        env.update(_allocation(job))
    return env


@functools.cache
def _allocation(job: str) -> dict:
    """``SLURM_NODELIST`` and ``SLURM_TASKS_PER_NODE`` (one task per allocated CPU) of ``job``."""
    proc = subprocess.run(["scontrol", "show", "job", "-d", job], capture_output=True, text=True, timeout=60)
    nodelist = re.search(r"^\s*NodeList=(\S+)", proc.stdout, re.MULTILINE)
    per_node = []
    for hosts, cpu_ids in re.findall(r"^\s*Nodes=(\S+) CPU_IDs=(\S+)", proc.stdout, re.MULTILINE):
        cpus = sum(int(b) - int(a) + 1 if b else 1
                   for a, b in re.findall(r"(\d+)(?:-(\d+))?", cpu_ids))
        names = subprocess.run(["scontrol", "show", "hostnames", hosts], capture_output=True, text=True,
                               timeout=60).stdout.split()
        per_node.append(f"{cpus}(x{len(names)})" if len(names) > 1 else str(cpus))
    if proc.returncode != 0 or not nodelist or not per_node:
        return {}
    return {"SLURM_NODELIST": nodelist.group(1), "SLURM_JOB_NODELIST": nodelist.group(1),
            "SLURM_TASKS_PER_NODE": ",".join(per_node)}


def check_launcher(prefix: list[str], ranks: int, timeout_s: float = 120) -> None:
    """Start ``ranks`` ranks of LIGGGHTS with ``prefix`` on a one-line input; raise
    :class:`MpiStartError` (its ``reason``: the telling line of the output) if they do not all run."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="spreadmap-mpi-check-") as tmp:
        probe = Path(tmp) / "check.in"
        probe.write_text('print "spreadmap-mpi-ok"\n')
        cmd = mpi_command(ranks, prefix) + [LIGGGHTS, "-in", str(probe), "-log", "none"]
        try:
            proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=timeout_s,
                                  stdin=subprocess.DEVNULL, env=launcher_env())
            out, code = proc.stdout + proc.stderr, proc.returncode
        except FileNotFoundError:
            out, code = f"{prefix[0]}: command not found", 127
        except subprocess.TimeoutExpired:
            out, code = f"no answer within {timeout_s:.0f} s", None
    if code != 0 or out.count("spreadmap-mpi-ok") < 1:
        err = MpiStartError(f"MPI could not start {ranks} LIGGGHTS ranks with '{' '.join(prefix)}': "
                            f"{_mpi_reason(out)}. Fix: {MPI_FIX}")
        err.reason = _mpi_reason(out)
        raise err


def _mpi_reason(output: str) -> str:
    """The line of a failed MPI start that says why (SLURM's or Open MPI's own words)."""
    known = {r"not built with SLURM's PMI":
             "Open MPI was not built with SLURM's PMI support (plain srun cannot start it)",
             r"not enough slots": "more ranks than the allocation's slots",
             r"can not load PMIx library": "SLURM's pmix plugin cannot load the PMIx library (Debian: libpmix-dev)"}
    for pattern, reason in known.items():
        if re.search(pattern, output):
            return reason
    lines = [ln.strip(" *-") for ln in output.splitlines() if ln.strip(" *-")]
    for pattern in (r"srun: error", r"lacks support",
                    r"error", r"MPI_Init", r"not found"):
        hit = next((ln for ln in lines if re.search(pattern, ln, re.IGNORECASE)), None)
        if hit:
            return hit
    return lines[-1] if lines else "no output"


#: Seconds between two looks at a running log for a blow-up (:func:`run`'s ``abort_speed``).
WATCH_EVERY_S = 2.0


class BlowupWatch:
    """Reads a growing LIGGGHTS log's new complete lines; ``scan`` returns the first thermo row
    (step, fastest particle [m/s]) whose ``vmax`` column is past ``limit`` [m/s] or not finite."""

    def __init__(self, log_file: Path, limit: float):
        self.log_file, self.limit, self.offset, self.column, self.width = log_file, limit, 0, None, 0

    def scan(self) -> tuple[int, float] | None:
        try:
            with open(self.log_file, "rb") as f:
                f.seek(self.offset)
                chunk = f.read()
        except FileNotFoundError:
            return None
        end = chunk.rfind(b"\n") + 1  # complete lines only: the rest is read next time
        self.offset += end
        for line in chunk[:end].decode(errors="replace").splitlines():
            parts = line.split()
            if parts[:2] == ["Step", "Atoms"]:
                self.column, self.width = (parts.index("vmax") if "vmax" in parts else None), len(parts)
            elif self.column is not None and len(parts) == self.width and parts[0].isdigit():
                try:
                    speed = float(parts[self.column])
                except ValueError:
                    speed = float("nan")
                if not np.isfinite(speed) or speed > self.limit:
                    return int(parts[0]), speed
        return None


def _stop(proc: subprocess.Popen, ranks: int) -> None:
    """End a running LIGGGHTS: kill a single process; ask an MPI launcher to end its ranks
    (SIGTERM, which it forwards), killing it if it has not within 30 s."""
    if ranks == 1:
        proc.kill()
    else:
        proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def run(input_file: str | Path, log_file: str | Path, ranks: int = 1, cwd: str | Path | None = None,
        abort_speed: float | None = None) -> dict:
    """Run LIGGGHTS on ``input_file``; return the parsed log (see :func:`read_log`).

    The screen output goes to ``<log_file>.screen``. Raises
    :class:`LiggghtsError` naming the ERROR line and the input command it died
    at, or the tail of the screen when LIGGGHTS died without one. With ``abort_speed``
    [m/s], the log is watched while LIGGGHTS runs (every :data:`WATCH_EVERY_S` s) and the
    run is stopped at the first thermo line whose fastest particle (``vmax``) is past it,
    raising :class:`UnstableRunError`: a blown-up run costs no more CPU than it took to blow up.
    """
    input_file, log_file = Path(input_file).resolve(), Path(log_file).resolve()
    if shutil.which(LIGGGHTS) is None:
        raise LiggghtsError(f"'{LIGGGHTS}' not found on PATH: install it with `apt-get install liggghts` "
                            "(or run the README's set-up command)")
    check_seeds(input_file.read_text())
    screen = log_file.with_name(log_file.name + ".screen")
    prefix, source = launcher(ranks) if ranks > 1 else ([], "")
    if prefix:
        _checked(tuple(prefix), ranks, source)
    cmd = mpi_command(ranks, prefix) + [LIGGGHTS, "-in", str(input_file), "-log", str(log_file)]
    start, cpu_start = time.perf_counter(), children_cpu()
    blown, watch = None, BlowupWatch(log_file, abort_speed) if abort_speed else None
    if watch:
        log_file.unlink(missing_ok=True)  # a previous attempt's log is not this run's
    with open(screen, "w") as out:
        proc = subprocess.Popen(cmd, cwd=cwd or input_file.parent, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=launcher_env() if prefix else None)
        try:
            while blown is None:
                try:
                    proc.wait(timeout=WATCH_EVERY_S if watch else None)
                    break
                except subprocess.TimeoutExpired:
                    blown = watch.scan()
            if blown:
                _stop(proc, ranks)
        except BaseException:  # interrupted (Ctrl-C, a job's SIGTERM): take LIGGGHTS down too
            _stop(proc, ranks)
            raise
    wall, cpu = time.perf_counter() - start, children_cpu() - cpu_start
    if blown:
        raise UnstableRunError(f"unsound run: kinetic-energy blow-up, a particle at {blown[1]:.3g} m/s at step "
                               f"{blown[0]} (limit {abort_speed:.3g} m/s), stopped there after {wall:.0f} s: lower "
                               f"the time step; full log: {log_file}")
    log_text = log_file.read_text(errors="replace") if log_file.exists() else ""
    screen_text = screen.read_text(errors="replace")
    error = _error_message(log_text + "\n" + screen_text)
    if prefix and proc.returncode != 0 and "LIGGGHTS (Version" not in log_text:  # died before its first line
        raise MpiStartError(f"MPI could not start {ranks} LIGGGHTS ranks with '{' '.join(prefix)}' ({source}): "
                            f"{_mpi_reason(screen_text)}. Fix: {MPI_FIX}")
    check_disk(input_file.parent, log_text + screen_text)
    killed = _signal_of(proc.returncode, error)
    if killed:
        raise LiggghtsError(f"LIGGGHTS on {input_file.name} was killed by {killed}; run folder: {input_file.parent}")
    if "SIGINT/SIGTERM caught" in screen_text + log_text:  # LIGGGHTS' own handler: restart file, then exit 0
        raise LiggghtsError(f"LIGGGHTS on {input_file.name} was stopped by SIGTERM or SIGINT (a time limit, "
                            f"scancel or a kill) and quit before its end (exit code {proc.returncode}); "
                            f"full log: {log_file}")
    if proc.returncode != 0 or error:
        where = _failing_command(log_text)
        known = next((why for pattern, why in KNOWN_ERRORS.items() if error and re.search(pattern, error)), None)
        if known:
            raise LiggghtsError(f"LIGGGHTS failed on {input_file.name}: {known.format(**_error_fields(error))} "
                                f"({error}); run folder: {input_file.parent}")
        tail = "\n".join(screen_text.strip().splitlines()[-8:])
        raise LiggghtsError(
            f"LIGGGHTS failed on {input_file.name} (exit code {proc.returncode})\n"
            f"  error: {error or 'no ERROR line printed (e.g. an MPI_Abort)'}\n"
            f"  at input line: {where or 'unknown'}\n  last screen lines:\n{tail}\n"
            f"  full log: {log_file}")
    parsed = read_log(log_text)
    parsed["wall_s"] = wall
    parsed["cpu_s"] = cpu
    parsed["ranks"] = ranks
    parsed["launcher"] = " ".join(prefix)
    return parsed


#: LIGGGHTS' ERROR lines the wrapper can foresee, and what to change (config keys or files).
KNOWN_ERRORS = {
    r"Mesh \(id roller\S*\).*lost / left the domain":
        "the roller mesh left the simulation box (its facets outside were deleted): check roller.diameter_mm, "
        "roller.gap_um and the speeds (sweep.U_mm_s, sweep.omega_rad_s)",
    r"Mesh \(id substrate\).*lost / left the domain":
        "the substrate mesh lies outside the simulation box (its facets outside were deleted): check "
        "substrate.mesh (metres, mean plane near z = 0), substrate.sq_um and roller.gap_um",
    r"Invalid run command":
        "a run command out of range (its number of time steps): check timestep.rayleigh_fraction, the speeds "
        "(sweep.U_mm_s) and the level's settle_time_s and rest_time_s",
    r"Cannot open (?:mesh |restart )?file (?P<file>\S+?)\.?(?:\s|$)":
        "LIGGGHTS cannot open {file}: run the step that makes it (geometry before settle, settle before spread)",
}

#: Free bytes below which a failed or truncated run is put down to a full disk.
FULL_DISK_BYTES = 1 << 20


def check_disk(folder: str | Path, output: str = "") -> None:
    """Raise ``OSError(ENOSPC)`` naming ``folder`` if its disk is full (under :data:`FULL_DISK_BYTES`
    free) or LIGGGHTS' ``output`` says so: LIGGGHTS writes on a full disk without a word, leaving
    truncated dumps and restarts."""
    free = shutil.disk_usage(folder).free
    if free < FULL_DISK_BYTES or "No space left on device" in output:
        raise OSError(errno.ENOSPC, f"No space left on device ({free} bytes free; LIGGGHTS' output there is "
                                    "incomplete: free space and run again)", str(folder))


def _signal_of(returncode: int, error: str | None) -> str | None:
    """'SIGKILL (signal 9, e.g. ...)' for a return code that says a signal stopped the process
    (negative: Python's; 128 + n: a launcher's), else None."""
    number = -returncode if returncode < 0 else returncode - 128 if returncode > 128 and not error else 0
    try:
        name = signal.Signals(number).name
    except ValueError:
        return None
    why = {"SIGKILL": "the out-of-memory killer, a time limit or kill -9", "SIGXFSZ": "a file-size limit",
           "SIGSEGV": "a crash of the engine", "SIGBUS": "a crash of the engine"}.get(name, "a kill")
    return f"{name} (signal {number}, e.g. {why})"


def _error_fields(error: str) -> dict:
    match = re.search(r"Cannot open (?:mesh |restart )?file (\S+?)\.?(?:\s|$)", error)
    return {"file": match.group(1) if match else "a file"}


@functools.cache
def _checked(prefix: tuple[str, ...], ranks: int, source: str) -> None:
    """:func:`check_launcher` once per process for each launcher and rank count; the error names the source."""
    try:
        check_launcher(list(prefix), ranks)
    except MpiStartError as err:
        raise MpiStartError(str(err).replace(f"with '{' '.join(prefix)}'", f"with '{' '.join(prefix)}' ({source})",
                                             1)) from None


def children_cpu() -> float:
    """User + system CPU seconds of this process's finished children (LIGGGHTS, or the
    MPI launcher and every rank it waited for): the run's true cost, which Snakemake's
    ``benchmark:`` sampling misses part of."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _error_message(text: str) -> str | None:
    match = re.search(r"^ERROR[^:]*:.*$", text, re.MULTILINE)
    return match.group(0).strip() if match else None


def _failing_command(log_text: str) -> str | None:
    """The last input command LIGGGHTS echoed to its log before the ERROR."""
    head = log_text.split("ERROR")[0]
    lines = [ln for ln in head.splitlines() if ln.strip() and not ln.startswith(("  ", "INFO", "WARNING"))]
    commands = [ln for ln in lines if re.match(r"^[a-z_]+(\s|$)", ln)]
    return commands[-1].strip() if commands else None


#: LIGGGHTS' own timing breakdown after each ``run``: its name in the log -> ours.
TIMING = {"Pair": "pair", "Neigh": "neigh", "Comm": "comm", "Outpt": "output", "Other": "other"}


def timing_breakdown(text: str) -> dict:
    """Seconds [s] LIGGGHTS spent in each part of its loop, summed over every ``run`` of a log:
    ``pair`` (particle-particle contacts), ``neigh`` (neighbour lists), ``comm`` (MPI),
    ``output`` and ``other`` (the fixes: mesh walls and their motion, insertion, integration),
    and ``loop`` (their total)."""
    found = re.findall(r"^(Pair|Neigh|Comm|Outpt|Other)\s+time \(%\) = (\S+)", text, re.MULTILINE)
    parts = {name: 0.0 for name in TIMING.values()}
    for name, seconds in found:
        parts[TIMING[name]] += float(seconds)
    return {**parts, "loop": float(sum(float(s) for s in re.findall(r"^Loop time of (\S+)", text, re.MULTILINE)))}


def read_log(text: str) -> dict:
    """Health figures from a LIGGGHTS log.

    Returns a dict: ``thermo`` (DataFrame of every thermo block, columns as in
    ``thermo_style``), ``inserted`` (particles inserted), ``atoms_final``,
    ``measured_max_rayleigh_fraction``/``measured_max_hertz_fraction`` (the largest time step
    over the Rayleigh and Hertz times, measured by ``check/timestep/gran``), ``warnings``,
    ``printed`` (the values of the input's ``print "spreadmap <key> <value>"`` lines),
    ``timing_s`` (:func:`timing_breakdown`).
    """
    blocks, lines = [], text.splitlines()
    for i, line in enumerate(lines):
        names = line.split()
        if names[:2] != ["Step", "Atoms"]:
            continue
        rows = []
        for row in lines[i + 1:]:
            if row.startswith("Loop time"):
                break
            parts = row.split()
            if len(parts) == len(names) and re.fullmatch(r"-?\d+", parts[0]):
                rows.append(parts)
        if rows:
            blocks.append(pd.DataFrame(np.array(rows, dtype=float), columns=names))
    thermo = pd.concat(blocks, ignore_index=True) if blocks else pd.DataFrame()
    inserted = sum(int(n) for n in re.findall(r"inserted\s+(\d+)\s+particle templates", text))
    fractions = {key: float(thermo[col].max()) if col in thermo else float("nan")
                 for key, col in (("measured_max_rayleigh_fraction", "ts[1]"),
                                 ("measured_max_hertz_fraction", "ts[2]"))}
    printed = {key: float(value) for key, value in re.findall(r"^spreadmap (\w+) (\S+)$", text, re.MULTILINE)}
    return {"thermo": thermo, "inserted": inserted, "printed": printed, "timing_s": timing_breakdown(text),
            "atoms_final": int(thermo["Atoms"].iloc[-1]) if len(thermo) else 0,
            "warnings": sorted(set(re.findall(r"^WARNING:.*$", text, re.MULTILINE))), **fractions}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("input", type=Path)
    parser.add_argument("--np", type=int, default=1, help="MPI ranks")
    parser.add_argument("--log", type=Path, help="log file (default: INPUT.log)")
    args = parser.parse_args(argv)
    if not args.input.is_file():
        print(f"error: input file {str(args.input)!r} not found", file=sys.stderr)
        return 2
    try:
        result = run(args.input, args.log or args.input.with_suffix(".log"), ranks=args.np)
    except LiggghtsError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    thermo = result.pop("thermo")
    result["steps"] = int(thermo["Step"].iloc[-1]) if len(thermo) else 0
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
