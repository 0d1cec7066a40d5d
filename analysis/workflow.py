"""Glue for the thin Snakemake entry points in ``scripts/``.

``with rule_context(snakemake) as config:`` sends the job's output to its log,
hands over the checked configuration, and turns a known failure
(a ValueError such as ConfigError or DumpError, or a LiggghtsError) into a
one-line message and a non-zero exit instead of a traceback.
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path

from analysis.config import load_config
from analysis.run_liggghts import LiggghtsError


@contextlib.contextmanager
def rule_context(smk):
    log = open(smk.log[0], "w") if smk.log else sys.stderr
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            yield load_config(smk.config, base_dir=Path(smk.scriptdir).parent)
        except (ValueError, LiggghtsError) as err:  # ConfigError, DumpError, UnsoundRunError are ValueErrors
            print(f"error: {err}", file=log, flush=True)
            print(f"error in rule {smk.rule}: {err}", file=sys.__stderr__, flush=True)
            sys.exit(1)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; move it onto ``path`` on success.

    The temporary name keeps the suffix (writers that pick a format from the
    extension still work) and is removed if the block raises.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(obj, path) -> None:
    """Write JSON atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2))
