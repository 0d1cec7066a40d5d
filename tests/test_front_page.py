"""The report's front page: the finished map's facts, and report/workflow.rst rendered as Snakemake does."""

from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
import yaml

from analysis.columns import METRICS
from analysis.viz.front_page import front_page_rst

ROOT = Path(__file__).resolve().parents[1]


def _choice():
    r2 = {"mlp": 0.9197, "gp": 0.907, "trees": 0.9201}
    return pd.DataFrame([{"model": m, "scheme": "kfold", "metric": x, "R2": v, "mean_R2_se": 0.01}
                         for m, v in r2.items() for x in METRICS])


def _scores():
    spread = {m: {"R_mean": 0.95, "R_sd": 0.02, "R_min": 0.90, "R_max": 0.98} for m in METRICS}
    return {"n_runs": 45, "model": {"name": "mlp"}, "test": {m: {"R": 0.961} for m in METRICS},
            "test_spread": {"n_splits": 20, **spread}}


FOUND = {"inputs": ["U_mm_s", "omega_rad_s"], "U_mm_s": 85.0, "omega_rad_s": -5.0, "throughput_mm2_s": 30.1,
         "mass_g": 0.012, "roughness_um": 70.2, "porosity_pct": 55.0, "n_feasible": 812, "n_grid": 40401,
         "meets_confidence": True}
WINDOW = {"max_porosity_pct": 60, "max_roughness_um": 90}


def test_front_page_states_the_window_the_choice_and_the_spread():
    text = front_page_rst(_scores(), _choice(), WINDOW, FOUND, "the upper end of the 90 % single-run interval")
    assert "porosity <= 60 % and roughness R_q <= 90 um" in text
    assert "**U = 85 mm/s, omega = -5 rad/s**" in text and "812 of 40401" in text
    assert "**mlp**" in text and "+- 0.0100" in text and "tied with it: mlp 0.9197" in text
    assert "over 20 seeded splits" in text and "M_s 0.950 +- 0.020 (0.900 to 0.980)" in text
    none = front_page_rst(_scores(), _choice(), WINDOW, None, "the predicted mean")
    assert "No setting in the swept range meets them" in none
    assert "Layer structure" not in text                      # scores.json without 'structure': not stated


def test_front_page_states_the_structure_limits_and_scores():
    structure = {"model": "mlp", "test": {"void_fraction_pct": {"R": 0.9412}, "coverage_pct": {"R": 0.987}},
                 "cv": {"kfold": {"void_fraction_pct": {"R2": 0.8512}, "coverage_pct": {"R2": 0.9}}}}
    window = {**WINDOW, "max_void_fraction_pct": 35, "min_coverage_pct": 95.0}
    found = {**FOUND, "void_fraction_pct": 34.23, "coverage_pct": 98.76}
    text = front_page_rst({**_scores(), "structure": structure}, _choice(), window, found, "the upper end")
    assert "porosity <= 60 % and roughness R_q <= 90 um and void fraction <= 35 % and coverage >= 95 %" in text
    assert "Phi 55 %, void fraction 34.2 %, coverage 98.8 %;" in text
    assert ("void fraction eps = 100 (1 - packing fraction): test R 0.941, k-fold R^2 0.851; coverage C: "
            "test R 0.987, k-fold R^2 0.900") in text
    skipped = front_page_rst({**_scores(), "structure": {"skipped": "the dataset lacks coverage"}}, _choice())
    assert "not fitted, the dataset lacks coverage" in skipped


@pytest.mark.parametrize("level", ["smoke", "default"])
def test_workflow_rst_renders_without_a_docutils_problem(level, tmp_path, monkeypatch):
    """Jinja over the config, the front page included from results/<level>/, the results' link
    targets appended (as Snakemake's report does); any docutils warning fails."""
    from docutils.core import publish_parts
    from jinja2 import Environment

    config = yaml.safe_load((ROOT / "config.yaml").read_text()) | {"level": level}
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results" / level).mkdir(parents=True)
    (tmp_path / "results" / level / "front_page.rst").write_text(
        front_page_rst(_scores(), _choice(), WINDOW, FOUND, "the upper end of the 90 % single-run interval"))
    links = "".join(f"\n.. _{name}: javascript:void(0)\n" for name in ("operating_window.png", "process_map.png"))
    source = (ROOT / "report" / "workflow.rst").read_text() + links
    rendered = Environment(trim_blocks=True, lstrip_blocks=True).from_string(source).render(
        snakemake=SimpleNamespace(config=config))
    html = publish_parts(rendered, writer="html", settings_overrides={"halt_level": 2, "report_level": 5})
    body = html["html_body"]
    assert f"Spreading process maps ({level} level)" in body
    assert body.index("operating_window.png") < body.index("What this map says") < body.index("812 of 40401")
    assert "Where each output lives" in body and f"results/{level}/" in body
