"""The workflow's last line (Snakefile onsuccess): what the spreads cost, from a hand-made dataset.csv;
a missing or broken dataset gives a short line, never an exception."""
import os

import pandas as pd
import pytest

from analysis.metrics.dataset import workflow_summary, workflow_summary_line

STARTED = 1_700_000_000.0          # epoch seconds


@pytest.fixture
def dataset(tmp_path):
    """Three runs: 100 + 300 + 200 CPU s, 2e8 + 4e8 + 3e8 particle-steps, written after the start."""
    path = tmp_path / "dataset.csv"
    pd.DataFrame({"U_mm_s": [40.0, 70.0, 100.0], "cpu_s": [100.0, 300.0, 200.0],
                  "particle_steps": [2e8, 4e8, 3e8]}).to_csv(path, index=False)
    os.utime(path, (STARTED + 60, STARTED + 60))
    return path


def test_the_line_gives_runs_cpu_rate_and_wall_time(dataset):
    line = workflow_summary_line(dataset, STARTED, now=STARTED + 5400)
    assert line == ("spreadmap: 3 runs, LIGGGHTS CPU 10.0 min (200 s a run), 1.50 M particle-steps per CPU second, "
                    "workflow wall time 90.0 min")


def test_a_dataset_this_invocation_did_not_write_is_said_to_be_older(dataset):
    line = workflow_summary_line(dataset, STARTED + 120, now=STARTED + 180)
    assert line.startswith("spreadmap: 3 runs, LIGGGHTS CPU 10.0 min") and "wall time 1.0 min" in line
    assert line.endswith("(dataset.csv not remade by this invocation)")


def test_no_dataset_gives_a_short_line(tmp_path):
    line = workflow_summary_line(tmp_path / "results/smoke/dataset.csv", STARTED, now=STARTED + 30)
    assert line.startswith("spreadmap: workflow wall time 0.5 min (no ") and "runs" not in line


def test_a_broken_dataset_gives_a_short_line_not_an_exception(tmp_path):
    path = tmp_path / "dataset.csv"
    pd.DataFrame({"U_mm_s": [40.0], "particle_steps": [1e8]}).to_csv(path, index=False)   # no cpu_s
    os.utime(path, (STARTED + 1, STARTED + 1))
    line = workflow_summary_line(path, STARTED, now=STARTED + 60)
    assert line.startswith("spreadmap: workflow wall time 1.0 min (") and "KeyError" in line and "cpu_s" in line
    path.write_bytes(b"\x00\xff not a table")
    assert workflow_summary_line(path, STARTED, now=STARTED + 60).startswith("spreadmap: workflow wall time 1.0 min")


def test_the_rate_counts_only_runs_with_both_numbers():
    """A run without particle_steps (an older health.json) adds its CPU to the total, not to the rate."""
    table = pd.DataFrame({"cpu_s": [100.0, 300.0, 50.0], "particle_steps": [2e8, 4e8, None]})
    line = workflow_summary(table, wall_s=60.0)
    assert "LIGGGHTS CPU 7.5 min (150 s a run), 1.50 M particle-steps" in line
    assert "n/a particle-steps per CPU second" in workflow_summary(table.drop(columns="particle_steps"), 60.0)
