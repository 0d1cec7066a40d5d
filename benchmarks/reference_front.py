"""The default scene against the converged reference, knob by knob: the front of cost against error.

Run from the repository root (no simulation; it reads the fidelity benchmark's runs)::

    .venv/bin/python benchmarks/reference_front.py [--runs stiffness.csv,...,combined.csv]
        [--default E2e7] [--name reference_front]

Each CSV is a ``bench_fidelity.py`` run table under ``benchmarks/measured/``. Runs repeated in
several of them (same variant, seed, U and omega) are counted once; a variant called ``default``
is renamed by ``--renamed`` (the level as configured when the CSV was measured). Every step
``a -> b`` of :data:`STEPS` whose two variants both ran is judged as ``bench_fidelity --ladder``
judges it (:func:`benchmarks.bench_fidelity.convergence`: the largest shift over the shared
points, in the pooled seed sd of the finer scene ``b``) and costed: the mean LIGGGHTS CPU seconds
per run of ``b`` over ``a`` on the same points. Writes ``benchmarks/measured/<name>.csv``, ``.md``
and ``.png`` (largest shift against CPU relative to ``--default``).
"""
from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script: `benchmarks` (and this checkout's `analysis`) importable

from benchmarks.bench_fidelity import METRICS, convergence  # noqa: E402
from benchmarks.machine import commit  # noqa: E402

#: The knob each step turns, coarser (cheaper) -> finer (bigger, stiffer, better supplied).
STEPS = {
    ("E5e6", "E2e7"): "stiffness 5 -> 20 MPa",
    ("E2e7", "E5e7"): "stiffness 20 -> 50 MPa",
    ("E5e7", "E1e8"): "stiffness 50 -> 100 MPa",
    ("E2e7", "E1e8"): "stiffness 20 -> 100 MPa",
    ("E1e8", "E2e8"): "stiffness 100 -> 200 MPa",
    ("E2e8", "E4e8"): "stiffness 200 -> 400 MPa",
    ("E2e7+strip2.5+pile40", "E5e7+strip2.5+pile40"): "stiffness 20 -> 50 MPa (2.5 mm, 40 mg/mm)",
    ("E5e7+strip2.5+pile40", "E1e8+strip2.5+pile40"): "stiffness 50 -> 100 MPa (2.5 mm, 40 mg/mm)",
    ("E1e8", "E1e8+strip2.5+pile40"): "strip 1.2 -> 2.5 mm and pile 20 -> 40 mg/mm (100 MPa)",
    ("E2e7", "E1e8+strip2.5+pile40"): "20 MPa, 1.2 mm, 20 mg/mm, top-ups every 0.5 mm -> 100 MPa, 2.5 mm, 40 mg/mm",
    ("feed0.25", "E1e8+strip2.5+pile40"): "the same, top-ups every 0.25 mm -> 100 MPa, 2.5 mm, 40 mg/mm",
    ("facets180", "E1e8+strip2.5+pile40"): "the same, 180 roller facets -> 100 MPa, 2.5 mm, 40 mg/mm",
    ("E2e7", "E2e7+strip2.5"): "strip 1.2 -> 2.5 mm (20 MPa)",
    ("E2e7", "E2e7+pile40"): "pile 20 -> 40 mg/mm (20 MPa)",
    ("E2e7", "feed0.25"): "top-up every 0.5 -> 0.25 mm (20 MPa)",
    ("E2e7", "unfed40"): "fed 20 mg/mm pile -> unfed 40 mg/mm heap (20 MPa)",
    ("dt0.5", "E2e7"): "time step 0.5 -> 0.35 T_R (20 MPa)",
    ("E2e7", "E2e7+strip2.5+pile40"): "strip 1.2 -> 2.5 mm and pile 20 -> 40 mg/mm (20 MPa)",
    ("E2e7+strip2.5", "E2e7+strip5"): "strip 2.5 -> 5 mm (20 MPa)",
    ("E2e7", "E2e7+strip5"): "strip 1.2 -> 5 mm (20 MPa)",
    ("E2e7", "facets180"): "roller facets 90 -> 180: the gap as built (20 MPa)",
}


def load_runs(paths: list[Path], renamed: str) -> pd.DataFrame:
    """The runs of ``paths`` (bench_fidelity CSVs), ``default`` renamed ``renamed``, each run once."""
    runs = pd.concat([pd.read_csv(p) for p in paths], ignore_index=True)
    runs["variant"] = runs["variant"].replace({"default": renamed})
    return runs.drop_duplicates(["variant", "seed", "U_mm_s", "omega_rad_s"]).reset_index(drop=True)


def front(runs: pd.DataFrame, steps: dict = STEPS, default: str = "E2e7") -> pd.DataFrame:
    """One row per step of ``steps`` whose variants both ran: its convergence row (shifts in the
    finer scene's pooled sds, changes in %), its points, the largest shift over the metrics, and
    the CPU per run of each side relative to ``default`` on the same points (``cpu_coarser_rel``,
    ``cpu_finer_rel``; NaN where ``default`` did not run there)."""
    ok = runs[runs["error"].isna()] if "error" in runs else runs
    rows = []
    for (a, b), knob in steps.items():
        pa = set(map(tuple, ok.loc[ok["variant"] == a, ["U_mm_s", "omega_rad_s"]].values))
        pb = set(map(tuple, ok.loc[ok["variant"] == b, ["U_mm_s", "omega_rad_s"]].values))
        points = sorted(pa & pb)
        if not points:
            continue
        here = ok[[p in points for p in map(tuple, ok[["U_mm_s", "omega_rad_s"]].values)]]
        step = convergence(here, [a, b]).iloc[0].to_dict()
        cpu = here.groupby("variant")["cpu_s"].mean()
        base = cpu.get(default, float("nan"))
        shifts = [step[f"{m} shift (finer sds)"] for m in METRICS.values()]
        rows.append({"knob": knob, **step, "omega_rad_s": ", ".join(f"{o:g}" for _, o in points),
                     "largest shift (finer sds)": max(shifts),
                     "cpu_coarser_rel": cpu[a] / base, "cpu_finer_rel": cpu[b] / base})
    return pd.DataFrame(rows)


def plot(table: pd.DataFrame, path: Path, default: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for _, r in table.iterrows():
        colour = "tab:blue" if r["converged"] else "tab:red"
        x0, x1, y = r["cpu_coarser_rel"], r["cpu_finer_rel"], r["largest shift (finer sds)"]
        ax.plot([x0, x1], [y, 0.0], color=colour, lw=0.8, ls=":")
        ax.scatter([x0], [y], color=colour)
        ax.scatter([x1], [0.0], color=colour, marker="x")
        ax.annotate(r["knob"], (x0, y), fontsize=8, xytext=(4, 4), textcoords="offset points")
    ax.axhline(1.0, color="grey", ls="--", lw=0.8)
    ax.set_xlabel(f"CPU per run relative to {default}")
    ax.set_ylabel("largest shift from the finer scene (its pooled seed sds)")
    ax.set_ylim(bottom=-0.2)
    ax.set_title("each knob: the coarser scene (dot) against the finer one (x, at 0);\nred: not converged")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs",
                        default="stiffness.csv,stiffness_omega.csv,scene20.csv,feed_interval.csv,unfed_dt.csv,combined.csv,"
                                "strip5.csv,facets180.csv,pile40_w10.csv",
                        help="bench_fidelity run tables under --measured, comma-separated")
    parser.add_argument("--measured", type=Path, default=ROOT / "benchmarks" / "measured")
    parser.add_argument("--renamed", default="E5e6", help="what a variant called `default` in them was")
    parser.add_argument("--default", default="E2e7", help="the variant that is the default scene")
    parser.add_argument("--name", default="reference_front")
    parser.add_argument("--powder", default="",
                        help="what the runs' config was (a sentence for the table's page), e.g. the calibrated powder")
    args = parser.parse_args(argv)
    paths = [args.measured / name for name in args.runs.split(",")]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        parser.error(f"no such run table: {', '.join(missing)}")
    table = front(load_runs(paths, args.renamed), default=args.default)
    if table.empty:
        parser.error(f"none of the steps {list(STEPS)} has both its variants in {args.runs}")
    table.to_csv(args.measured / f"{args.name}.csv", index=False)
    plot(table, args.measured / f"{args.name}.png", args.default)
    cols = ["knob", "omega_rad_s", "finer seeds", *[f"{m} shift (finer sds)" for m in METRICS.values()],
            *[f"{m} change (%)" for m in METRICS.values()], "converged", "cpu_coarser_rel", "cpu_finer_rel"]
    text = (f"# The default scene against bigger, stiffer, better-supplied ones\n\n"
            f"Summarised {time.strftime('%Y-%m-%d')} at commit {commit()} from the fidelity benchmark's runs "
            f"({args.runs}, U = 70 mm/s, 3 seeds each), by\n`.venv/bin/python benchmarks/reference_front.py "
            f"--runs {args.runs} --renamed {args.renamed} --name {args.name}"
            + (f" --powder {shlex.quote(args.powder)}" if args.powder else "") + "`.\n\n"
            + (f"{args.powder}\n\n" if args.powder else "")
            + "Each knob turned one step from the coarser scene to the finer one; a shift "
            "is the largest over the points of |coarser - finer| in the finer scene's pooled seed sd (converged: "
            "every metric within 1), a change the mean of 100 (coarser - finer) / finer. CPU: LIGGGHTS' own per "
            f"run, relative to `{args.default}` (the default scene) on the same points; the CSVs were measured "
            "in different invocations on shared cores, so a ratio across them is rougher than one within.\n\n"
            + table[cols].to_markdown(index=False, floatfmt=".2f") + "\n")
    (args.measured / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
