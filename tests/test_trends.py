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


def test_every_statement_against_hand_computed_values():
    """Six points (U 40, 100 mm/s x omega -5, 0, 5 rad/s) whose verdicts and figures are worked
    out by hand; R = 15 mm puts the bottom point of (100, -5) at +25 mm/s, at the edge of "at rest"."""
    import pandas as pd
    data = pd.DataFrame({
        "U_mm_s": [40, 40, 40, 100, 100, 100], "omega_rad_s": [-5, 0, 5, -5, 0, 5],
        "mass_g": [2.0, 1.0, 1.0, 2.2, 1.1, 1.0], "throughput_mm2_s": [10, 8, 6, 20, 12, 11],
        "roughness_um": [90, 80, 85, 95, 82, 90], "porosity_pct": [50, 60, 55, 70, 65, 62]})
    rows = {paper: (measured, agrees) for paper, measured, agrees in trend_table(data, 15.0)}
    # M_s: (2 + 2.2) / 2 over (1 + 1) / 2; Q_s: (10 + 20) / 2 over (6 + 11) / 2
    assert rows["M_s jumps when omega turns negative (multi-layer deposition)"] == \
        ("mean M_s at omega < 0 is 2.10 x that at omega > 0", "yes")
    assert rows["Q_s jumps when omega turns negative (multi-layer deposition)"] == \
        ("mean Q_s at omega < 0 is 1.76 x that at omega > 0", "yes")
    # rising at all 3 omegas; Spearman of ranks [2,2,2,5,5,5] and [3,2,1,6,5,4]: 13.5 / sqrt(13.5 x 17.5)
    assert rows["Q_s grows monotonically with U"] == \
        ("monotonic in U at 100% of the omegas; Spearman rho(U, Q_s) = 0.88", "yes")
    assert rows["R_q is lowest at omega = 0 for every U"] == ("omega of least R_q per U: 40: 0, 100: 0", "yes")
    assert rows["R_q rises more for negative than positive omega"] == \
        ("mean R_q at omega < 0: 92.5 um, at omega > 0: 87.5 um", "yes")
    # peak 70 % at (100, -5): bottom speed 100 - 5 x 15 = +25 mm/s; elsewhere (50+60+55+65+62) / 5
    assert rows["Phi peaks where the roller's bottom point is at rest (U = -omega R)"] == (
        "max Phi 70.0 % at U = 100 mm/s, omega = -5 rad/s (bottom speed +25 mm/s); mean Phi where bottom "
        "speed within 25 mm/s: 70.0 %, elsewhere 58.4 %", "yes")
    assert rows["Phi increases monotonically with U at constant omega"] == ("monotonic at 100% of the omegas", "yes")
    # a 5 % jump is not a jump (threshold 1.1); two of three omegas rising is "partly" (rho > 0.5)
    small = data.assign(mass_g=[1.05, 1, 1, 1.05, 1, 1], throughput_mm2_s=[5, 3, 6, 20, 12, 5.9])  # rho 0.68
    rows = {paper: agrees for paper, _, agrees in trend_table(small, 15.0)}
    assert rows["M_s jumps when omega turns negative (multi-layer deposition)"] == "no"
    assert rows["Q_s grows monotonically with U"] == "partly"
