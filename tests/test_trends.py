"""The paper's trend statements are detected on a dataset that has them, and
refuted on one that has the opposite."""
from conftest import ROLLER_RADIUS_MM

from analysis.metrics.trends import markdown, trend_table


def test_paper_like_dataset_agrees_everywhere(dataset):
    rows = trend_table(dataset, ROLLER_RADIUS_MM)
    assert [agrees for *_, agrees in rows] == ["yes"] * len(rows)
    assert markdown(rows).count("\n") == len(rows) + 1


def test_reversed_dataset_disagrees(dataset):
    flipped = dataset.assign(omega_rad_s=-dataset.omega_rad_s, U_mm_s=140 - dataset.U_mm_s)
    verdicts = dict((paper, agrees) for paper, _, agrees in trend_table(flipped, ROLLER_RADIUS_MM))
    assert verdicts["M_s jumps when omega turns negative (multi-layer deposition)"] == "no"
    assert verdicts["Q_s grows monotonically with U"] == "no"
    assert verdicts["Phi increases monotonically with U at constant omega"] == "no"
