"""The layer's mass against the substrate's height under it: is a change along the travel the substrate's?

Usage::

    .venv/bin/python benchmarks/substrate_height.py NAME=CSV [NAME=CSV ...] --near 6-9 --far 9-12
        [--omegas 0,10] [--bin-mm 1] [--name substrate_height] [--out benchmarks/measured]

Each CSV is ``bench_region.py``'s: kept layers (or a map's) re-measured over short regions, each row with
the substrate's mean height under it above the gap's datum (``substrate_above_datum_um``); the bins are
its regions ``--bin-mm`` long. The roller's bottom is level, so a bin whose substrate stands higher has
less room under the roller. Per scene (NAME) and omega, the bins inside ``--near`` and ``--far`` (their
labels ``a-b`` [mm]) are fitted by least squares as

    M_s(bin) = a_layer + b * height(bin) + c * [bin in far]

(``a_layer``: one level per layer, so that a packing's overall mass does not count). ``b`` is the mass a
micrometre of substrate height takes (% of the mean M_s), ``c`` the change from the near bins to the far
ones with the height removed; beside it the change as measured (the far bins' mean against the near
ones', % of the near ones'), and the mean height of the far bins above the near ones'. With ``--far none``
only the height is fitted (e.g. a map's runs, all on one substrate, over their own region's bins).

Writes ``<name>.csv`` (one row per scene and omega) and ``<name>.md``.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent


def span(label: str) -> tuple[float, float]:
    """``"a-b"`` [mm] as (a, b)."""
    a, b = (float(v) for v in label.split("-"))
    return a, b


def fit_height(bins: pd.DataFrame, near: tuple[float, float], far: tuple[float, float]) -> dict:
    """Least squares of a bin's M_s on its substrate height and on being far, one level per layer
    (without far bins, on the height alone).

    ``bins``: rows of one scene and omega with ``U_mm_s``, ``seed`` (a layer is one of each), ``start_mm``,
    ``end_mm``, ``mass_g`` and ``substrate_above_datum_um``; a bin counts when it lies inside ``near`` or ``far`` [mm].
    Returns the slope ``mass_pct_per_um`` (% of the mean M_s per um of height) with its standard error,
    ``far_pct`` (the far bins' change with the height removed, % of the near bins' mean M_s) with its
    standard error, ``far_raw_pct`` (as measured), ``far_height_um`` (the far bins' mean height above the
    near ones'), the correlation of M_s with height within the layers, and the counts.
    """
    is_near = (bins["start_mm"] >= near[0] - 1e-9) & (bins["end_mm"] <= near[1] + 1e-9)
    is_far = (bins["start_mm"] >= far[0] - 1e-9) & (bins["end_mm"] <= far[1] + 1e-9)
    used = bins[is_near | is_far]
    is_far = is_far[is_near | is_far].to_numpy(float)
    mass = 1e3 * used["mass_g"].to_numpy()  # mg
    height = used["substrate_above_datum_um"].to_numpy()
    layer = used[["U_mm_s", "seed"]].astype(str).agg("_".join, axis=1).to_numpy()  # a map's runs share a seed
    levels = pd.get_dummies(layer).to_numpy(float)
    k = levels.shape[1]  # the height's column
    design = np.column_stack([levels, height] + ([is_far] if is_far.any() else []))
    coef, *_ = np.linalg.lstsq(design, mass, rcond=None)
    dof = len(mass) - design.shape[1]
    sigma2 = float(np.sum((mass - design @ coef) ** 2) / dof) if dof > 0 else np.nan
    se = np.sqrt(np.diag(sigma2 * np.linalg.pinv(design.T @ design)))
    near_mean, mean = mass[is_far == 0].mean(), mass.mean()

    def centred(v):  # each layer's mean removed
        return v - pd.Series(v).groupby(layer).transform("mean").to_numpy()

    fit = {"layers": k, "bins": len(mass),
           "mass_pct_per_um": 100 * coef[k] / mean, "mass_pct_per_um_se": 100 * se[k] / mean,
           "corr_within_layers": float(np.corrcoef(centred(height), centred(mass))[0, 1]),
           "far_height_um": np.nan, "far_raw_pct": np.nan, "far_pct": np.nan, "far_pct_se": np.nan}
    if is_far.any():
        fit.update({"far_height_um": height[is_far == 1].mean() - height[is_far == 0].mean(),
                    "far_raw_pct": 100 * (mass[is_far == 1].mean() / near_mean - 1),
                    "far_pct": 100 * coef[-1] / near_mean, "far_pct_se": 100 * se[-1] / near_mean})
    return fit


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tables", nargs="+", help="NAME=CSV: a scene's bench_region.py CSV of short bins")
    parser.add_argument("--near", default="6-9", help="the near bins' span, start-end [mm]")
    parser.add_argument("--far", default="9-12", help="the far bins' span, start-end [mm], or none (height only)")
    parser.add_argument("--omegas", default="", help="omegas [rad/s] to fit, comma-separated (default: all)")
    parser.add_argument("--bin-mm", type=float, default=1.0, help="the bins' length [mm]: the CSV's regions this long")
    parser.add_argument("--name", default="substrate_height")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    try:
        near, far = span(args.near), ((np.inf, np.inf) if args.far == "none" else span(args.far))
    except ValueError:
        parser.error(f"--near {args.near!r} / --far {args.far!r}: want start-end in mm (e.g. 9-12), or --far none")
    rows = []
    for item in args.tables:
        name, sep, path = item.partition("=")
        if not sep or not Path(path).is_file():
            parser.error(f"{item!r}: want NAME=CSV, a bench_region.py CSV that exists")
        runs = pd.read_csv(path)
        if "substrate_above_datum_um" not in runs:
            parser.error(f"{path}: no substrate_above_datum_um column (re-measure it with bench_region.py)")
        runs = runs[(runs["length_mm"] - args.bin_mm).abs() < 1e-9]
        for omega, one in runs.groupby("omega_rad_s"):
            if args.omegas and omega not in [float(w) for w in args.omegas.split(",")]:
                continue
            rows.append({"scene": name, "U_mm_s": ",".join(f"{u:g}" for u in sorted(one["U_mm_s"].unique())),
                         "omega_rad_s": omega,
                         **fit_height(one, near, far)})
    if not rows:
        parser.error(f"no {args.bin_mm:g} mm bins of the omegas asked for in the tables given")
    table = pd.DataFrame(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / f"{args.name}.csv", index=False)
    command = " ".join(argv if argv is not None else sys.argv[1:])
    text = (f"# The layer's mass against the substrate's height under it\n\n"
            f"Fitted {time.strftime('%Y-%m-%d')} on {platform.machine()}, {platform.node()} (no DEM), by\n"
            f"`.venv/bin/python benchmarks/substrate_height.py {command}`.\n\n"
            f"Per scene and omega, the {args.bin_mm:g} mm bins inside {args.near} mm (near) and "
            + ("no far bins" if args.far == "none" else f"{args.far} mm (far)")
            + " of every layer: M_s(bin) = a_layer + b height(bin) + c [far].\n\n"
            "- `mass_pct_per_um`: b, % of the mean M_s per um of the substrate's mean height above the gap's "
            "datum (with its standard error);\n"
            "- `corr_within_layers`: the correlation of a bin's M_s with its height, each layer's means removed;\n"
            "- `far_height_um`: the far bins' mean height above the near ones';\n"
            "- `far_raw_pct`: the far bins' mean M_s against the near ones', as measured (%);\n"
            "- `far_pct`: c, the same change with the height removed (% of the near bins' mean, with its "
            "standard error).\n\n" + table.to_markdown(index=False, floatfmt=".2f") + "\n")
    (args.out / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
