"""What shapes a layer along the travel: its powder (heap and feed) or its substrate?

Usage::

    .venv/bin/python benchmarks/profile_swap.py VARIANT=CSV [VARIANT=CSV ...]
        [--name profile_swap] [--out benchmarks/measured]

Each CSV is a ``bench_region.py --variant VARIANT`` table of kept layers measured
over 1 mm bins (``--regions 0-1,1-2,...``): the default's own layers (replicate r:
powder r on substrate r) and the swapped ones of ``bench_fidelity.py``'s
``substrate+1`` and ``substrate-1`` variants (powder r on substrate r +- 1). Every
layer's substrate realisation is read from its variant's config. For each layer whose
powder and substrate differ, the table gives the root-mean-square difference of
its deposit profile (M_s per bin, mg per the level's area) from the layer that
shares its substrate and from the one that shares its powder, over the flat bed
(bins starting at 0 to 4 mm) and over the rough patch (5 to 9 mm): the
realisation the profile follows is the one it is nearer to.

Writes ``<name>.md``; no DEM.
"""
from __future__ import annotations

import argparse
import platform
import sys
from datetime import date
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from analysis.config.load import load_config  # noqa: E402
from analysis.dem.simulate import substrate_seed  # noqa: E402
from benchmarks.bench_fidelity import VARIANTS, variant_config  # noqa: E402

#: The bins' starts [mm]: the flat bed ahead of the rough patch, and the patch (the default's region 6-9 mm).
STRETCHES = {"flat bed 0-5 mm": range(0, 5), "rough patch 5-10 mm": range(5, 10)}


def deposit_profiles(tables: list[pd.DataFrame], variants: list[str], config: dict) -> pd.DataFrame:
    """One row per layer: its powder and substrate replicates, then M_s [mg per the level's area] per 1 mm bin
    (columns: the bins' starts [mm])."""
    rows = []
    for table, variant in zip(tables, variants):
        vconfig = variant_config(config, "default", VARIANTS.get(variant, {}))
        bins = table[table["length_mm"].round(6) == 1.0]
        for seed, layer in bins.groupby("seed"):
            row = {"variant": variant, "powder": int(seed),
                   "substrate": substrate_seed(vconfig, int(seed)) - substrate_seed(config, 0)}
            row.update({int(round(x)): m * 1e3 for x, m in zip(layer["start_mm"], layer["mass_g"])})
            rows.append(row)
    return pd.DataFrame(rows).set_index(["variant", "powder", "substrate"]).sort_index(axis=1)


def swap_distances(profiles: pd.DataFrame) -> pd.DataFrame:
    """For each layer whose powder and substrate replicates differ: the RMS difference [mg] of its profile from the
    layer with its substrate and from the layer with its powder (both unswapped), per stretch of STRETCHES."""
    own = {(p, s): row for (_, p, s), row in profiles.iterrows() if p == s}
    rows = []
    for (variant, powder, substrate), row in profiles.iterrows():
        if powder == substrate or (substrate, substrate) not in own or (powder, powder) not in own:
            continue
        for stretch, starts in STRETCHES.items():
            cols = [c for c in starts if c in row.index]
            rms = {k: float(np.sqrt(np.mean((row[cols] - own[(r, r)][cols]) ** 2)))
                   for k, r in (("same substrate", substrate), ("same powder", powder))}
            rows.append({"layer": f"powder {powder} on substrate {substrate} ({variant})", "stretch": stretch,
                         "rms_mg_vs_same_substrate": rms["same substrate"],
                         "rms_mg_vs_same_powder": rms["same powder"],
                         "follows": min(rms, key=rms.get)})
    return pd.DataFrame(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tables", nargs="+", metavar="VARIANT=CSV",
                        help="a bench_region.py table of kept layers and the variant they were run at")
    parser.add_argument("--name", default="profile_swap")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "measured")
    args = parser.parse_args(argv)
    config = load_config(ROOT / "config.yaml")
    tables, variants = [], []
    for arg in args.tables:
        variant, _, path = arg.partition("=")
        if variant not in VARIANTS and variant != "default":
            parser.error(f"{arg!r}: no variant {variant!r} in bench_fidelity (VARIANT=CSV)")
        if not Path(path).is_file():
            parser.error(f"{arg!r}: no such bench_region table {path!r}")
        tables.append(pd.read_csv(path))
        variants.append(variant)
    profiles = deposit_profiles(tables, variants, config)
    distances = swap_distances(profiles)
    if distances.empty:
        parser.error("no swapped layer with both its unswapped layers among the tables")
    args.out.mkdir(parents=True, exist_ok=True)
    command = " ".join(["benchmarks/profile_swap.py", *args.tables, "--name", args.name])
    text = [f"# A layer's profile along the travel: its powder or its substrate? ({date.today()})", "",
            f"Measured on {platform.machine()}, by `.venv/bin/python {command}` (no DEM).", "",
            "Deposit profiles (M_s per 1 mm bin, mg per the default's 3.6 mm^2; bins by their start, mm):", "",
            profiles.round(2).to_markdown(), "",
            "RMS difference of each swapped layer's profile from the unswapped layer with its substrate and from "
            "the one with its powder:", "",
            distances.round(2).to_markdown(index=False), ""]
    (args.out / f"{args.name}.md").write_text("\n".join(text))
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
