"""The calibration's report page: response surfaces with the measured bands, the chosen
coefficients with their uncertainty, the tests' images and the check with new seeds."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.calibration.calibrate import PROPERTIES, Response, grid


def plot_responses(responses: dict[str, Response], results: pd.DataFrame, bounds: dict, solution: dict,
                   path: Path, grid_points: int = 61) -> None:
    """One panel per measured property: its surrogate over the first one or two coefficients
    (the others at their chosen values), the measured value and band, the design's runs and
    the chosen point with its range."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names, chosen = list(bounds), solution["chosen"]
    props = list(solution["measured"])
    fig, axes = plt.subplots(1, len(props), figsize=(5.2 * len(props), 4.2), dpi=110, squeeze=False)
    shown = names[:2]
    box = {n: (bounds[n] if n in shown else (chosen[n], chosen[n])) for n in names}
    X = grid(box, grid_points) if len(shown) == 2 else grid(box, 201)
    X = np.unique(X, axis=0)
    for ax, prop in zip(axes[0], props):
        unit = PROPERTIES[prop][2]
        value, sd = solution["measured"][prop]["value"], solution["measured"][prop]["sd"]
        band = solution["z"] * sd
        mean, std = responses[prop].predict(X)
        if len(shown) == 1:
            x = X[:, 0]
            ax.plot(x, mean, "C0-", label="surrogate (mean)")
            ax.fill_between(x, mean - solution["z"] * std, mean + solution["z"] * std, color="C0", alpha=0.25,
                            label=f"model {100 * solution['confidence']:g} % band")
            ax.axhspan(value - band, value + band, color="C3", alpha=0.2, label="measured band")
            ax.axhline(value, color="C3")
            ax.plot(results[shown[0]], results[prop], "ko", ms=4, label="test runs")
            lo, hi = solution["range"][shown[0]]
            ax.axvspan(lo, hi, color="C2", alpha=0.2, label="calibrated range")
            ax.axvline(chosen[shown[0]], color="C2", lw=2, label="chosen")
            ax.set(xlabel=shown[0], ylabel=f"{prop} ({unit})")
            ax.legend(fontsize=7)
        else:
            i, j = names.index(shown[0]), names.index(shown[1])
            n0, n1 = len(np.unique(X[:, i])), len(np.unique(X[:, j]))
            order = np.lexsort((X[:, j], X[:, i]))
            xs, ys, zs = (a[order].reshape(n0, n1) for a in (X[:, i], X[:, j], mean))
            cs = ax.contourf(xs, ys, zs, levels=14, cmap="viridis")
            fig.colorbar(cs, ax=ax, label=f"{prop} ({unit})")
            ax.contour(xs, ys, zs, levels=[value - band, value + band], colors="w", linestyles="--")
            ax.contour(xs, ys, zs, levels=[value], colors="w")
            ax.plot(results[shown[0]], results[shown[1]], "k.", ms=5)
            (lo0, hi0), (lo1, hi1) = solution["range"][shown[0]], solution["range"][shown[1]]
            ax.errorbar([chosen[shown[0]]], [chosen[shown[1]]],
                        xerr=[[chosen[shown[0]] - lo0], [hi0 - chosen[shown[0]]]],
                        yerr=[[chosen[shown[1]] - lo1], [hi1 - chosen[shown[1]]]], fmt="r*", ms=12, capsize=3)
            ax.set(xlabel=shown[0], ylabel=shown[1],
                   title=f"measured {value:.4g} +- {sd:.3g} {unit} (white; dashed: band)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def nearest_run(results: pd.DataFrame, names: list[str], chosen: dict, bounds: dict) -> str:
    """The design point (``point`` column) nearest the chosen coefficients, in box-scaled distance."""
    scale = np.array([max(hi - lo, 1e-12) for lo, hi in bounds.values()])
    d = np.linalg.norm((results[names].to_numpy(float) - np.array([chosen[n] for n in names])) / scale, axis=1)
    return str(results["point"].iloc[int(np.argmin(d))])


def check_table(checks: pd.DataFrame, solution: dict) -> tuple[list[str], bool]:
    """Markdown rows of the re-simulation with new seeds at the chosen coefficients, and whether
    every measured property's mean over them lies within the measurement's band
    (z sqrt(sd^2 + seed sd^2 / n))."""
    rows, passed = [], True
    for prop, m in solution["measured"].items():
        values = checks[prop].dropna().to_numpy(float) if prop in checks else np.array([])
        if not len(values):
            continue
        sd_seed = float(np.std(values, ddof=1)) if len(values) > 1 else float("nan")
        band = solution["z"] * np.hypot(m["sd"], (sd_seed if np.isfinite(sd_seed) else 0.0) / np.sqrt(len(values)))
        ok = abs(values.mean() - m["value"]) <= band
        passed &= bool(ok)
        unit = PROPERTIES[prop][2]
        rows.append(f"| {prop} | {m['value']:.4g} +- {m['sd']:.3g} {unit} | {values.mean():.4g} | "
                    f"{sd_seed:.3g} | {len(values)} | {'yes' if ok else '**no**'} |")
    return rows, passed


def _heap_note(results: pd.DataFrame) -> str:
    """What the angle of repose is when it comes from heaps on several bases (``angle_d<D>_deg`` columns)."""
    bases = [c[len("angle_d"):-len("_deg")] for c in results.columns if c.startswith("angle_d")]
    if not bases:
        return ""
    return (f" The angle of repose is the large-heap limit a of angle = a + b / D fitted to each run's heaps "
            f"on bases of {', '.join(bases)} mm (their own angles in the table's `angle_d<D>_deg`).")


def report_markdown(solution: dict, results: pd.DataFrame, responses: dict, checks: pd.DataFrame | None,
                    images: dict, level: str) -> str:
    """The report page (Markdown) of one calibration."""
    names = list(solution["chosen"])
    lines = ["# Calibration of the virtual powder", "",
             f"Characterisation tests at the `{level}` level's PSD and time step; "
             f"{results['point'].nunique()} design points x {results['replicate'].nunique()} replicate(s) "
             f"(docs/calibration.md).{_heap_note(results)}", "", "## Measured and calibrated", "",
             "| property | measured | calibrated powder (model) | reachable over the box |", "|---|---|---|---|"]
    for prop, m in solution["measured"].items():
        unit = PROPERTIES[prop][2]
        p, (lo, hi) = solution["predicted"][prop], solution["reachable"][prop]
        lines.append(f"| {prop} | {m['value']:.4g} +- {m['sd']:.3g} {unit} | {p['mean']:.4g} +- "
                     f"{p['sd_model']:.3g} | {lo:.4g} .. {hi:.4g} |")
    lines += ["", f"| coefficient | chosen | consistent range ({100 * solution['confidence']:g} % bands) |",
              "|---|---|---|"]
    for n in names:
        lo, hi = solution["range"][n]
        lines.append(f"| {n} | {solution['chosen'][n]:.4g} | {lo:.4g} .. {hi:.4g} |")
    if solution["at_box_edge"]:
        lines += ["", f"**At the edge of the box:** {', '.join(solution['at_box_edge'])}: widen its range."]
    if len(names) > len(solution["measured"]):
        lines += ["", f"{len(names)} coefficients from {len(solution['measured'])} measurement(s): the "
                  "consistent set is a band, not a point; the chosen point is the best fit inside it."]
    lines += ["", "## Response surfaces", "", f"![response surfaces]({images['surfaces']})", "",
              "| property | surrogate LOO RMSE | seed sd (GP noise) | std inflation c | conformal q |",
              "|---|---|---|---|---|"]
    for prop, r in responses.items():
        lines.append(f"| {prop} | {r['loo_rmse']:.3g} | {r['noise_sd']:.3g} | {r['scale']:.3g} | {r['quantile']:.3g} |")
    if checks is not None and len(checks):
        rows, passed = check_table(checks, solution)
        lines += ["", "## Check: the chosen coefficients re-simulated with new seeds", "",
                  "| property | measured | new seeds' mean | seed sd | runs | within the band |",
                  "|---|---|---|---|---|---|", *rows, "",
                  "Reproduces every measurement." if passed else "**Does not reproduce every measurement.**"]
    lines += ["", "## The tests at the design point nearest the chosen coefficients", ""]
    lines += [f"![{name}]({img})" for name, img in images.items() if name != "surfaces"]
    lines += ["", "## Design and results", "", results.to_markdown(index=False, floatfmt=".4g")]
    return "\n".join(lines) + "\n"


def copy_images(run_dir: Path, out: Path, tests: list[str]) -> dict:
    """Copy the tests' side views of one run folder next to the report; ``{test: file name}``."""
    images = {}
    for test in tests:
        src = run_dir / test / f"{test}.png"
        if src.is_file():
            shutil.copyfile(src, out / f"{test}.png")
            images[test] = f"{test}.png"
    return images
