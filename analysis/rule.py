"""Glue for the thin Snakemake entry points in ``scripts/``.

``with rule_context(snakemake) as config:`` sends the job's output to its log,
hands over the configuration (checked once, when the workflow started:
``rules/common.smk``), and turns a known failure
(a ValueError such as ConfigError or DumpError, or a LiggghtsError) into a
one-line message and a non-zero exit instead of a traceback.
"""
from __future__ import annotations

import contextlib
import sys

from analysis.dem.liggghts import LiggghtsError


@contextlib.contextmanager
def rule_context(smk):
    log = open(smk.log[0], "w") if smk.log else sys.stderr
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            yield smk.config
        except (ValueError, LiggghtsError) as err:  # ConfigError, DumpError, UnsoundRunError are ValueErrors
            print(f"error: {err}", file=log, flush=True)
            print(f"error in rule {smk.rule}: {err}", file=sys.__stderr__, flush=True)
            sys.exit(1)
