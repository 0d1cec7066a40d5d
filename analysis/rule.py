"""Glue for the thin Snakemake entry points in ``scripts/``.

``with rule_context(snakemake) as config:`` sends the job's output to its log,
hands over the configuration (checked once, when the workflow started:
``rules/common.smk``), and turns a known failure
(a ValueError such as ConfigError or DumpError, a LiggghtsError, or an OS error
such as a full disk) into a one-line message and a non-zero exit instead of a traceback.
"""
from __future__ import annotations

import contextlib
import sys

from analysis.io import USER_ERRORS, error_line


def by_folder(find, config: dict, table: dict, base_dir):
    """``name -> find(config, name, table, base_dir)`` for the rules' input functions and params
    (:func:`analysis.config.folders.find_run`, :func:`~analysis.config.folders.find_heap`): a ConfigError becomes
    Snakemake's WorkflowError, one line naming the folder."""
    from snakemake.exceptions import WorkflowError

    from analysis.config.errors import ConfigError

    def of(name):
        try:
            return find(config, name, table, base_dir)
        except ConfigError as err:
            raise WorkflowError(str(err)) from None
    return of


@contextlib.contextmanager
def rule_context(smk):
    log = open(smk.log[0], "w") if smk.log else sys.stderr
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            yield smk.config
        except USER_ERRORS as err:  # ConfigError, DumpError, UnsoundRunError, LiggghtsError, a full disk
            print(f"error: {error_line(err)}", file=log, flush=True)
            print(f"error in rule {smk.rule}: {error_line(err)}", file=sys.__stderr__, flush=True)
            sys.exit(1)
