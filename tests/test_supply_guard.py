"""The supply guard through the real workflow: a smoke heap too small for forward rolling runs dry,
and the dataset rule refuses it naming the key to raise unless the user keeps supply-limited runs.
(Its own module, so that `make test`'s module-per-worker scheduling runs it beside the smoke
workflow's module, the suite's long pole.)"""
import subprocess
import sys

import pandas as pd

from tests.test_config import ROOT


def test_a_heap_that_runs_dry_is_refused_by_name_unless_kept(tmp_path):
    """A smoke scene with a 60-particle heap and no feed runs dry at omega = -10 rad/s: the dataset rule
    refuses it naming the key to raise; keep_supply_limited_runs keeps and marks it."""
    base = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "-d", str(tmp_path),
            "--configfile", str(ROOT / "config.yaml"), "--cores", "2", "results/smoke/dataset.csv", "--config",
            "level=smoke", 'sweep={"U_mm_s": [100], "omega_rad_s": [-10, 0, 5, 10], "replicates": 1}',
            'surrogate={"n_test": 1, "cv_folds": 4}',
            'fidelity={"smoke": {"heap_particles": 60, "feed_pile_mg_per_mm": null}}']
    proc = subprocess.run([*base, "keep_supply_limited_runs=false"], capture_output=True, text=True)
    assert proc.returncode != 0
    assert "raise fidelity.smoke.heap_particles" in proc.stderr
    assert not (tmp_path / "results/smoke/dataset.csv").exists()
    proc = subprocess.run([*base, "keep_supply_limited_runs=true"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = pd.read_csv(tmp_path / "results/smoke/dataset.csv")
    dry = data[data.omega_rad_s == -10].iloc[0]
    assert dry.heap_exhausted and dry.supply_margin == 0.0
