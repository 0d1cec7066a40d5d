"""Command line: the spread-layer metrics (paper eqs. 1-7, :mod:`analysis.metrics.spread_layer`) of
one LIGGGHTS dump frame, measured by the virtual profilometer, printed as JSON in the report's
units (mm, um, g, mm/s).  It checks a substrate STL against the dump's box (in metres?), so it
stands above :mod:`analysis.dem`.  Run ``python -m analysis.measure -h`` (``spreadmap-layer-metrics``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from analysis.dem.geometry import units_slip
from analysis.io import USER_ERRORS, error_line, write_text
from analysis.metrics.dump import read_dump
from analysis.metrics.profilometer import load_mesh
from analysis.metrics.spread_layer import check_inputs, spread_layer_metrics, to_report_units


def main(argv=None):
    """Command line: print (and optionally save) the metrics of a dump frame.

    Returns
    -------
    int
        Exit status: 0 on success, 2 on a bad argument or input file.
    """
    args = _parser().parse_args(argv)
    args.region_text = [f"{v:g}" for v in args.region]
    try:
        for path in (args.dump, args.substrate):
            if path is not None and not Path(path).is_file():
                raise ValueError(f"file not found: {path}")
        if args.json and not Path(args.json).resolve().parent.is_dir():
            raise ValueError(f"--json {args.json}: folder does not exist")
        frame = read_dump(args.dump, timestep=args.timestep)
        # check in the units given, so that messages quote the user's numbers
        check_inputs(args.region, args.speed, args.density, args.lines, frame.box * 1e3, unit="mm")
        region = tuple(v * 1e-3 for v in args.region)
        _check_units(frame, region, args)
        substrate = args.substrate if args.substrate is not None else args.substrate_height * 1e-3
        try:
            if args.substrate is not None:
                substrate = load_mesh(substrate)
                slip = units_slip(substrate, np.ptp(frame.box[:2], axis=1), float(np.ptp(frame.box[2])))
                if slip:
                    raise ValueError(f"substrate {args.substrate} {slip} (the dump's box): in millimetres? "
                                     "--substrate is in metres")
            metrics = spread_layer_metrics(frame, region, args.speed * 1e-3, args.density, substrate=substrate,
                                           n_lines=args.lines, seed=args.seed)
        except ValueError as err:
            raise ValueError(f"{args.dump}: {err}") from None
        if metrics["n_particles"] == 0:
            raise ValueError(f"{args.dump}: no particle is centred in the region {' '.join(args.region_text)} mm "
                             f"(of {len(frame.atoms)} in the dump): no layer to measure")
        text = json.dumps(to_report_units(metrics), indent=2)
        if args.json:
            write_text(text + "\n", args.json)
    except USER_ERRORS as err:
        print(f"layer_metrics: error: {error_line(err)}", file=sys.stderr)
        return 2
    print(text)
    return 0


def _check_units(frame, region, args):
    """A ValueError if ``--region`` [mm] looks like metres: narrower than the dump's median particle."""
    if "radius" not in frame.atoms or frame.atoms.empty:
        return
    typical = 2 * float(frame.atoms["radius"].median())
    width = min(region[1] - region[0], region[3] - region[2])
    if width < typical:
        raise ValueError(f"region {' '.join(args.region_text)} mm is {width * 1e3:.3g} mm across, less than the "
                         f"dump's median particle diameter ({typical * 1e3:.3g} mm): in metres? --region takes mm")


def _parser():
    p = argparse.ArgumentParser(
        prog="python -m analysis.measure",
        description="Spread-layer metrics (mass, throughput, roughness, porosity) of a LIGGGHTS dump frame.",
    )
    p.add_argument("dump", help="LIGGGHTS dump custom file (SI, m), optionally gzipped")
    p.add_argument("--region", nargs=4, type=float, required=True, metavar=("XMIN", "XMAX", "YMIN", "YMAX"),
                   help="sampling region [mm]")
    p.add_argument("--speed", type=float, required=True, metavar="U", help="spreader translation speed [mm/s]")
    p.add_argument("--density", type=float, required=True, metavar="RHO", help="particle density [kg/m3]")
    sub = p.add_mutually_exclusive_group()
    sub.add_argument("--substrate", metavar="STL", help="substrate surface, STL in m (default: flat plane)")
    sub.add_argument("--substrate-height", type=float, default=0.0, metavar="Z",
                     help="height of a flat substrate plane [mm] (default 0)")
    p.add_argument("--lines", type=int, default=1000, help="profilometer lines per direction (default 1000)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random line positions (default 0)")
    p.add_argument("--timestep", type=int, help="timestep of the frame (default: the last)")
    p.add_argument("--json", metavar="OUT", help="also write the JSON object to this file (atomically)")
    return p


if __name__ == "__main__":
    sys.exit(main())
