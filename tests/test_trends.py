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
    assert verdicts["Phi jumps up when omega turns negative"] == "no"
    assert verdicts["M_s rises as omega falls from positive to zero"] == "no"


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


def test_the_rest_of_section_3_against_hand_computed_values():
    """Two speeds x omega -10..10: M_s falls with omega over omega >= 0 at U 40 only (50 %: partly),
    peaks inside the negative range at both U (at -5), Q_s peaks at the range's end at U 100; layers
    from thickness / 175 um; Phi 10 points higher at omega < 0."""
    import pandas as pd
    omega = [-10, -5, 0, 5, 10]
    data = pd.DataFrame({
        "U_mm_s": [40] * 5 + [100] * 5, "omega_rad_s": omega * 2,
        "mass_g": [3, 4, 2, 1.5, 1] + [3, 4, 2, 1, 1.5],
        "throughput_mm2_s": [30, 40, 20, 15, 10] + [50, 40, 20, 15, 10],
        "roughness_um": [90] * 10,
        "thickness_um": [350, 525, 350, 175, 175] * 2,       # 2, 3, 2, 1, 1 layers
        "porosity_pct": [60, 60, 55, 50, 50] * 2})
    rows = {paper: (measured, agrees) for paper, measured, agrees in trend_table(data, 15.0, 175.0)}
    assert rows["M_s rises as omega falls from positive to zero"] == (
        "falling in omega over omega >= 0 at 50% of the U", "partly")
    assert rows["Q_s rises as omega falls from positive to zero"] == (
        "falling in omega over omega >= 0 at 100% of the U", "yes")
    assert rows["M_s first rises then falls as negative omega grows in magnitude"] == (
        "largest between omega = 0 and -10 rad/s at omega = -5, -5 (U = 40, 100): inside the range at 100% of the U",
        "yes")
    assert rows["Q_s first rises then falls as negative omega grows in magnitude"][1] == "partly"
    # layers: omega = 0: 2.00; omega < 0: (2 + 3) / 2 = 2.50; omega > 0: 1.00
    assert rows["omega = 0 and omega < 0 lay 2-3 layers, omega > 0 a single one"] == (
        "deposit thickness over the mean diameter: 2.00 at omega = 0, 2.50 at omega < 0, 1.00 at omega > 0", "yes")
    assert rows["Phi jumps up when omega turns negative"] == (
        "mean Phi at omega < 0: 60.0 %, at omega > 0: 50.0 %", "yes")
    thin = data.assign(thickness_um=[175.0] * 10, porosity_pct=[50, 50, 55, 60, 60] * 2)
    rows = {paper: agrees for paper, _, agrees in trend_table(thin, 15.0, 175.0)}
    assert rows["omega = 0 and omega < 0 lay 2-3 layers, omega > 0 a single one"] == "no"
    assert rows["Phi jumps up when omega turns negative"] == "no"
