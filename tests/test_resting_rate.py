"""benchmarks/resting_rate.py: the engine's resting rate with the spread's contact model, its summary on
hand-made runs and a smoke run through real LIGGGHTS (the study: benchmarks/measured/resting_rate.md)."""
import pandas as pd
import pytest

from analysis.config.fidelity import scene
from analysis.config.load import load_config
from benchmarks import resting_rate


def test_the_summary_takes_each_variants_median_rate_against_the_spreads_model():
    runs = pd.DataFrame({"variant": ["as_spread", "flat_wall"] * 3, "particles": [100] * 6,
                         "cpu_s": [1.0] * 6, "max_speed_m_s": [0.01, 0.02, 0.03, 0.01, 0.01, 0.01],
                         "particle_steps_per_cpu_s": [2e6, 3e6, 4e6, 5e6, 1e6, 9e6]})
    table = resting_rate.summarise(runs).set_index("variant")
    assert table.loc["as_spread", "rate_M_per_cpu_s"] == pytest.approx(2.0)
    assert table.loc["flat_wall", "rate_M_per_cpu_s"] == pytest.approx(5.0)
    assert table.loc["flat_wall", "vs_as_spread"] == pytest.approx(2.5)
    assert table.loc["as_spread", "max_speed_m_s"] == pytest.approx(0.03)


def test_the_benchmark_leaves_the_smoke_heap_at_rest_in_both_variants_then_spreads_it(tmp_path):
    """One repeat of 1,000 steps: both variants integrate the same particles, every one of the settled heap's
    over the flat bed, at a positive rate, and the heap stays at rest (the flat wall launches nothing: a
    blow-up reaches metres per second); then the same heap is spread at one point."""
    assert resting_rate.main(["--level", "smoke", "--steps", "1000", "--repeats", "1", "--spread-points", "100:10",
                              "--name", "r", "--out", str(tmp_path)]) == 0
    runs = pd.read_csv(tmp_path / "r.csv").set_index("variant")
    s = scene(load_config(resting_rate.ROOT / "config.yaml"), "smoke")
    assert set(runs.index) == {"as_spread", "flat_wall", "spread 100:10"}
    spread, rest = runs.loc["spread 100:10"], runs.drop(index="spread 100:10")
    assert rest["particles"].nunique() == 1 and 0.9 * s.heap_particles <= rest["particles"].iloc[0] <= s.heap_particles
    assert (rest["particle_steps_per_cpu_s"] > 1e5).all() and (rest["steps"] == 1000).all()
    assert (rest["max_speed_m_s"] < 0.2).all()  # the settled heap's stragglers, not a launched particle (m/s)
    assert spread["steps"] > 1000 and spread["particle_steps_per_cpu_s"] > 1e5 and spread["particles"] > 100
    assert "| `flat_wall` | 1 |" in (tmp_path / "r.md").read_text()


def test_the_benchmark_refuses_no_steps(capsys):
    with pytest.raises(SystemExit):
        resting_rate.main(["--steps", "0"])
    assert "--steps 0" in capsys.readouterr().err


def test_the_benchmark_refuses_a_point_that_is_not_a_pair(capsys):
    with pytest.raises(SystemExit):
        resting_rate.main(["--spread-points", "70"])
    assert "--spread-points '70'" in capsys.readouterr().err
