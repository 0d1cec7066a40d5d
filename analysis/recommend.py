"""The operator's question: which spreader speeds give the most throughput within limits?

Usage::

    python -m analysis.recommend --max-porosity 45 [--max-roughness 60] \\
        [--model results/default/surrogate/model.joblib] [--grid-points 201]

Prints the (U, omega) inside the swept range (stored with the model) whose
predicted spread throughput Q_s is highest among the speeds whose predicted
porosity (%) and, if given, roughness (um) are within the limits, with the
four predicted metrics.  Exit status: 0 found, 1 no speeds meet the limits,
2 bad input (the message names it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from analysis.surrogate import METRICS, load_surrogate, predict_grid

DEFAULT_MODEL = "results/default/surrogate/model.joblib"


def _check_limit(name, value):
    if value is not None and not value >= 0:    # also rejects NaN
        raise ValueError(f"{name} must be a non-negative number, got {value}")


def recommend(model, meta, max_porosity_pct, max_roughness_um=None, n=201):
    """Speeds of highest predicted throughput that meet porosity and roughness limits.

    Parameters
    ----------
    model : estimator
        Fitted surrogate.
    meta : dict
        Its metadata; ``meta["input_range"]`` gives the swept range
        ``{"U_mm_s": [min, max], "omega_rad_s": [min, max]}``.
    max_porosity_pct : float
        Highest acceptable predicted porosity Phi, %.
    max_roughness_um : float, optional
        Highest acceptable predicted roughness R_q, um.
    n : int
        Grid points per axis over the swept range (resolution
        (max - min)/(n - 1) per speed).

    Returns
    -------
    dict or None
        None if no grid point meets the limits.  Otherwise ``U_mm_s``,
        ``omega_rad_s``, the four predicted metrics (``mass_g``,
        ``throughput_mm2_s``, ``roughness_um``, ``porosity_pct``),
        ``n_feasible`` (grid points meeting the limits) and ``n_grid``.

    Raises
    ------
    ValueError
        A negative or NaN limit, n < 2, or metadata without the swept range.
    """
    _check_limit("max porosity (%)", max_porosity_pct)
    _check_limit("max roughness (um)", max_roughness_um)
    if "input_range" not in meta:
        raise ValueError("the model's metadata has no swept range (input_range); refit it")
    grid = predict_grid(model, meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"], n)
    feasible = grid["porosity_pct"] <= max_porosity_pct
    if max_roughness_um is not None:
        feasible &= grid["roughness_um"] <= max_roughness_um
    if not feasible.any():
        return None
    best = grid.loc[grid.loc[feasible, "throughput_mm2_s"].idxmax()]
    return {**{c: float(best[c]) for c in ("U_mm_s", "omega_rad_s", *METRICS)},
            "n_feasible": int(feasible.sum()), "n_grid": len(grid)}


def _range_text(meta):
    (u0, u1), (w0, w1) = meta["input_range"]["U_mm_s"], meta["input_range"]["omega_rad_s"]
    return f"U {u0:g}..{u1:g} mm/s, omega {w0:g}..{w1:g} rad/s"


def _report(found, meta, limits):
    return "\n".join([
        f"Highest predicted throughput with {limits}",
        f"(surrogate grid of {found['n_grid']} points over {_range_text(meta)}; "
        f"{found['n_feasible']} meet the limits):",
        f"  U     = {found['U_mm_s']:.1f} mm/s",
        f"  omega = {found['omega_rad_s']:.2f} rad/s",
        f"  predicted: Q_s = {found['throughput_mm2_s']:.4g} mm^2/s, "
        f"M_s = {found['mass_g']:.4g} g, R_q = {found['roughness_um']:.4g} um, "
        f"Phi = {found['porosity_pct']:.4g} %",
    ])


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        """Bad arguments: one line on stderr, exit 2."""
        self.exit(2, f"{self.prog}: error: {message}\n")


def main(argv=None):
    """Command-line entry; returns the exit status."""
    parser = _Parser(prog="python -m analysis.recommend", description=__doc__.split("\n\n")[0])
    parser.add_argument("--max-porosity", type=float, required=True, metavar="PCT",
                        help="highest acceptable spread-layer porosity, %%")
    parser.add_argument("--max-roughness", type=float, metavar="UM",
                        help="highest acceptable spread-layer roughness R_q, um")
    parser.add_argument("--model", default=DEFAULT_MODEL, type=Path,
                        help=f"surrogate saved by the workflow (default {DEFAULT_MODEL})")
    parser.add_argument("--grid-points", type=int, default=201, metavar="N",
                        help="grid points per speed axis (default 201)")
    args = parser.parse_args(argv)
    try:
        _check_limit("--max-porosity", args.max_porosity)
        _check_limit("--max-roughness", args.max_roughness)
        if args.grid_points < 2:
            raise ValueError(f"--grid-points must be at least 2, got {args.grid_points}")
        if not args.model.is_file():
            raise ValueError(f"model file not found: {args.model} (run the workflow's surrogate rule first)")
        try:
            model, meta = load_surrogate(args.model)
        except Exception as err:  # a corrupt or foreign file fails in many ways
            raise ValueError(f"cannot load model {args.model}: {err}") from err
        found = recommend(model, meta, args.max_porosity, args.max_roughness, args.grid_points)
    except ValueError as err:
        parser.error(str(err))
    limits = f"porosity <= {args.max_porosity:g} %" + (
        "" if args.max_roughness is None else f" and roughness <= {args.max_roughness:g} um")
    if found is None:
        grid = predict_grid(model, meta["input_range"]["U_mm_s"],
                            meta["input_range"]["omega_rad_s"], args.grid_points)
        print(f"No speeds in {_range_text(meta)} are predicted to meet {limits}; the lowest "
              f"predicted porosity there is {grid['porosity_pct'].min():.4g} % and the lowest "
              f"roughness {grid['roughness_um'].min():.4g} um.")
        return 1
    print(_report(found, meta, limits))
    return 0


if __name__ == "__main__":
    sys.exit(main())
