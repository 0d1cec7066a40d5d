"""Fuzzing at scale: the property-based tests of tests/test_fuzz.py with many more cases.

Run from the repository root::

    .venv/bin/python benchmarks/bench_fuzz.py [--examples 5000]

Runs ``pytest tests/test_fuzz.py`` with ``FUZZ_EXAMPLES`` cases per test (the test suite
uses 150) and Hypothesis' statistics, and writes how many cases each test tried, how
they ended (refused with a one-line error, or accepted) and any failure to
``benchmarks/measured/fuzz.md``, with the commit measured. Exits with pytest's status.
"""
import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from benchmarks.machine import commit, machine  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=5000, help="cases per test (default 5000)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_fuzz.py",
                           "--hypothesis-show-statistics"], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "FUZZ_EXAMPLES": str(args.examples)})
    elapsed = time.perf_counter() - start
    stats = proc.stdout.split("Hypothesis Statistics", 1)[-1]
    rows = []
    for block in re.split(r"\n(?=tests/test_fuzz\.py::)", stats):
        name = re.match(r"tests/test_fuzz\.py::(\w+)", block.strip())
        if not name:
            continue
        counts = re.search(r"(\d+) passing, (\d+) failing, and (\d+) invalid", block)
        events = "; ".join(f"{pct} {what}" for pct, what in re.findall(r"\* ([\d.]+%), (.+)", block))
        rows.append(f"| `{name.group(1)}` | {counts.group(1)} | {counts.group(2)} | {counts.group(3)} | {events} |")
    summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else proc.stderr[-500:]
    text = "\n".join([
        "# Fuzzing the config check (values, YAML text), the dump reader (plain, gzip) and layer_metrics",
        "",
        f"Measured at commit {commit()}, {machine()}, in {elapsed:.0f} s, by `.venv/bin/python "
        f"benchmarks/bench_fuzz.py --examples {args.examples}` (tests/test_fuzz.py, seeded: the same cases "
        "every run).",
        "",
        "Each case must end in a result or a one-line error naming the key or the file, with nothing "
        "half-written; a failing case is one that did not.",
        "",
        "| test | cases passed | failing | invalid (discarded) | how the cases ended |",
        "|---|---|---|---|---|",
        *rows,
        "",
        f"pytest: `{summary}`",
        "",
    ])
    out = ROOT / "benchmarks/measured/fuzz.md"
    out.write_text(text)
    print(text)
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
