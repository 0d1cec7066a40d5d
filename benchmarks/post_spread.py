"""The stage after the spreads, outside Snakemake, on a finished map's dataset.csv.

Runs the scripts of the rules ``model_choice``, ``surrogate``, ``maps`` and ``front_page`` as the
workflow runs them: each in a fresh Python process (as Snakemake's ``script:`` jobs are), with a
stand-in for the ``snakemake`` object (the rule's inputs, outputs, params from config.yaml and its
threads), into a scratch folder; prints each rule's wall time. From the repository root::

    .venv/bin/python benchmarks/post_spread.py results/default/dataset.csv /tmp/post [--threads 2] \\
        [--rules model_choice,surrogate,maps,front_page] [--checkout DIR] [--surrogate cv_loo=false ...]

``--threads`` is what Snakemake gives the rules that ask for 4 (model_choice, surrogate) under
``--cores 2``; maps and front_page run on one. ``--checkout DIR`` runs another checkout's scripts,
config.yaml and ``analysis`` package (e.g. ``git archive <commit> | tar -x -C DIR``): the same
stage before and after a change, side by side. ``--surrogate KEY=VALUE`` (a YAML value, repeatable)
overrides a key of config.yaml's ``surrogate:`` section, as ``--config 'surrogate={...}'`` would.
Used for the post-spread stage's timings in docs/performance.md.
"""

import argparse
import runpy
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[1]
RULES = ("model_choice", "surrogate", "maps", "front_page")


def rule_io(rule, dataset, out, config, threads):
    """(script, inputs, outputs, params, threads) of ``rule`` as rules/surrogate.smk and rules/maps.smk name them."""
    s, m = config["surrogate"], config["maps"]
    surrogate = {"model": out / "model.joblib", "scores": out / "scores.json", "split": out / "split.csv",
                 "grid": out / "grid.csv"}
    choice = {"csv": out / "model_choice.csv", "md": out / "model_choice.md",
              "predictions": out / "cv_predictions.csv"}
    if rule == "model_choice":
        return "model_choice.py", {"dataset": dataset}, choice, {"surrogate": s, "level": "default"}, threads
    if rule == "surrogate":
        return ("fit_surrogate.py", {"dataset": dataset, "choice": choice["csv"], "predictions": choice["predictions"]},
                surrogate, {"surrogate": s, "grid_points": s["grid_points"]}, threads)
    if rule == "maps":
        return ("render_maps.py", {"model": surrogate["model"], "dataset": dataset, "split": surrogate["split"],
                                   "predictions": choice["predictions"]},
                {"maps": out / "maps"}, {"maps": m, "surrogate": s}, 1)
    if rule == "front_page":
        return ("front_page.py", {"model": surrogate["model"], "scores": surrogate["scores"], "choice": choice["csv"]},
                {"rst": out / "front_page.rst"}, {"window": m.get("operating_window")}, 1)
    raise ValueError(f"unknown rule {rule!r}; choose from {', '.join(RULES)}")


def run_one(rule, dataset, out, checkout, threads, overrides=()):
    """Run one rule's script in this process (``checkout``'s scripts and analysis package), with
    ``overrides`` (``KEY=VALUE`` strings) on its config's ``surrogate:`` section."""
    sys.path.insert(0, str(checkout))            # its analysis package, before an installed one
    import yaml

    class Named(list):                            # Snakemake's Namedlist: by position and by name
        def __init__(self, named):
            super().__init__(str(v) for v in named.values())
            self.__dict__.update({k: str(v) for k, v in named.items()})

    config = yaml.safe_load((checkout / "config.yaml").read_text())
    for item in overrides:
        key, value = item.split("=", 1)
        config["surrogate"][key] = yaml.safe_load(value)
    script, inputs, outputs, params, threads = rule_io(rule, Path(dataset), Path(out), config, threads)
    smk = SimpleNamespace(input=Named(inputs), output=Named(outputs), params=SimpleNamespace(**params),
                          log=[str(Path(out) / f"{rule}.log")], rule=rule, threads=threads, config=config,
                          scriptdir=checkout / "scripts")
    runpy.run_path(str(checkout / "scripts" / script), init_globals={"snakemake": smk}, run_name="__main__")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path, help="a finished map's dataset.csv")
    parser.add_argument("out", type=Path, help="scratch folder for the rules' outputs and logs")
    parser.add_argument("--threads", type=int, default=2, help="threads of model_choice and surrogate (min(4, cores))")
    parser.add_argument("--rules", default=",".join(RULES), help="comma-separated, in this order")
    parser.add_argument("--checkout", type=Path, default=ROOT, help="the checkout whose scripts run")
    parser.add_argument("--surrogate", action="append", default=[], metavar="KEY=VALUE",
                        help="override a key of config.yaml's surrogate: section (a YAML value)")
    parser.add_argument("--rule", help=argparse.SUPPRESS)            # one rule, in this process
    args = parser.parse_args(argv)
    checkout = args.checkout.resolve()
    if args.rule:
        run_one(args.rule, args.dataset.resolve(), args.out.resolve(), checkout, args.threads, args.surrogate)
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    total = 0.0
    for rule in args.rules.split(","):
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, __file__, str(args.dataset), str(args.out), "--rule", rule,
                               "--threads", str(args.threads), "--checkout", str(checkout),
                               *(f"--surrogate={item}" for item in args.surrogate)])
        wall = time.perf_counter() - t0
        total += wall
        print(f"{rule}: {wall:.1f} s" + ("" if done.returncode == 0 else f" (failed: {done.returncode}; "
                                          f"log {args.out / (rule + '.log')})"), flush=True)
        if done.returncode:
            return done.returncode
    print(f"total: {total:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
