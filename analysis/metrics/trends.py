"""The paper's section-3 statements, checked against a dataset.

``python -m analysis.metrics.trends results/default/dataset.csv`` prints a Markdown
table: the paper's statement beside what this dataset shows.
"""
from __future__ import annotations

import numpy as np
import pandas as pd


def _share_verdict(share: float) -> str:
    """"yes" where a per-U statement holds at 80 % of the speeds or more, "partly" at half."""
    return "yes" if share >= 0.8 else "partly" if share >= 0.5 else "no"


def trend_table(data: pd.DataFrame, roller_radius_mm: float,
                mean_diameter_um: float = 175.0) -> list[tuple[str, str, str]]:
    """(paper's statement, measured here, agrees?) rows, from replicate means.

    ``roller_radius_mm`` (mm) places the roller's bottom point at rest, U = -omega R;
    ``mean_diameter_um`` (um) counts the layers a deposit's ``thickness_um`` makes (a row
    the dataset has no column for is left out).
    """
    mean = data.groupby(["U_mm_s", "omega_rad_s"], as_index=False).mean(numeric_only=True)
    rows = []
    neg, pos = mean[mean.omega_rad_s < 0], mean[mean.omega_rad_s > 0]
    for col, name in (("mass_g", "M_s"), ("throughput_mm2_s", "Q_s")):
        ratio = neg[col].mean() / pos[col].mean()
        rows.append((f"{name} jumps when omega turns negative (multi-layer deposition)",
                     f"mean {name} at omega < 0 is {ratio:.2f} x that at omega > 0", "yes" if ratio > 1.1 else "no"))
    for col, name in (("mass_g", "M_s"), ("throughput_mm2_s", "Q_s")):
        table = mean.pivot(index="U_mm_s", columns="omega_rad_s", values=col)
        falling = table[[w for w in table.columns if w >= 0]]      # omega = 0, 5, 10, ...
        share = np.mean(np.all(np.diff(falling.to_numpy(), axis=1) < 0, axis=1)) if falling.shape[1] > 1 else 0.0
        rows.append((f"{name} rises as omega falls from positive to zero",
                     f"falling in omega over omega >= 0 at {share:.0%} of the U", _share_verdict(share)))
        back = table[sorted((w for w in table.columns if w <= 0), reverse=True)]   # 0, -5, -10, ...
        peak = back.to_numpy().argmax(axis=1)
        interior = np.mean((peak > 0) & (peak < back.shape[1] - 1)) if back.shape[1] > 2 else 0.0
        rows.append((f"{name} first rises then falls as negative omega grows in magnitude",
                     f"largest between omega = 0 and {back.columns[-1]:g} rad/s at omega = "
                     + ", ".join(f"{w:g}" for w in back.columns[peak]) + " (U = "
                     + ", ".join(f"{u:g}" for u in back.index) + f"): inside the range at {interior:.0%} of the U",
                     _share_verdict(interior)))
    if "thickness_um" in mean:
        layers = mean.thickness_um / mean_diameter_um
        still, forward, counter = (layers[mean.omega_rad_s == 0].mean(), layers[mean.omega_rad_s < 0].mean(),
                                   layers[mean.omega_rad_s > 0].mean())
        rows.append(("omega = 0 and omega < 0 lay 2-3 layers, omega > 0 a single one",
                     f"deposit thickness over the mean diameter: {still:.2f} at omega = 0, {forward:.2f} at "
                     f"omega < 0, {counter:.2f} at omega > 0",
                     "yes" if min(still, forward) >= 1.8 and counter <= 1.5 else
                     "partly" if max(still, forward) >= 1.8 and counter <= 1.5 else "no"))
    jump = neg.porosity_pct.mean() - pos.porosity_pct.mean()
    rows.append(("Phi jumps up when omega turns negative",
                 f"mean Phi at omega < 0: {neg.porosity_pct.mean():.1f} %, at omega > 0: "
                 f"{pos.porosity_pct.mean():.1f} %", "yes" if jump > 2 else "no"))
    by_omega = mean.pivot(index="U_mm_s", columns="omega_rad_s", values="throughput_mm2_s")
    rising = np.mean([np.all(np.diff(by_omega[w].to_numpy()) > 0) for w in by_omega.columns])
    corr = mean[["U_mm_s", "throughput_mm2_s"]].corr(method="spearman").iloc[0, 1]
    rows.append(("Q_s grows monotonically with U", f"monotonic in U at {rising:.0%} of the omegas; "
                 f"Spearman rho(U, Q_s) = {corr:.2f}", "yes" if rising >= 0.8 else "partly" if corr > 0.5 else "no"))
    rough = mean.pivot(index="U_mm_s", columns="omega_rad_s", values="roughness_um")
    argmin = rough.idxmin(axis=1)
    near_zero = np.mean(np.abs(argmin.to_numpy()) <= 5)
    rows.append(("R_q is lowest at omega = 0 for every U",
                 "omega of least R_q per U: " + ", ".join(f"{u:g}: {w:g}" for u, w in argmin.items()),
                 "yes" if near_zero == 1 else "partly" if near_zero >= 0.5 else "no"))
    rows.append(("R_q rises more for negative than positive omega",
                 f"mean R_q at omega < 0: {neg.roughness_um.mean():.1f} um, "
                 f"at omega > 0: {pos.roughness_um.mean():.1f} um",
                 "yes" if neg.roughness_um.mean() > pos.roughness_um.mean() else "no"))
    por = mean.pivot(index="U_mm_s", columns="omega_rad_s", values="porosity_pct")
    bottom = mean.U_mm_s + mean.omega_rad_s * roller_radius_mm
    at_rest, moving = mean.loc[bottom.abs() <= 25], mean.loc[bottom.abs() > 25]
    peak = mean.loc[mean.porosity_pct.idxmax()]
    rows.append(("Phi peaks where the roller's bottom point is at rest (U = -omega R)",
                 f"max Phi {peak.porosity_pct:.1f} % at U = {peak.U_mm_s:g} mm/s, omega = {peak.omega_rad_s:g} rad/s "
                 f"(bottom speed {peak.U_mm_s + peak.omega_rad_s * roller_radius_mm:+.0f} mm/s); mean Phi where "
                 f"bottom speed within 25 mm/s: {at_rest.porosity_pct.mean():.1f} %, "
                 f"elsewhere {moving.porosity_pct.mean():.1f} %",
                 "yes" if abs(peak.U_mm_s + peak.omega_rad_s * roller_radius_mm) <= 25 else "no"))
    rising_phi = np.mean([np.all(np.diff(por[w].to_numpy()) > 0) for w in por.columns])
    rows.append(("Phi increases monotonically with U at constant omega",
                 f"monotonic at {rising_phi:.0%} of the omegas", "yes" if rising_phi >= 0.8 else "no"))
    return rows


def markdown(rows) -> str:
    """The rows of :func:`trend_table` as a Markdown table."""
    return pd.DataFrame(rows, columns=["paper (section 3)", "this dataset", "agrees"]).to_markdown(index=False)


