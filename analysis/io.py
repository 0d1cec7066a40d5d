"""The one way spreadmap writes a file: atomically.

A reader (or a resumed workflow) sees either the old file or the whole new
one, never half of it: the data go to a temporary file in the same folder,
which then replaces the target (``os.replace``); on any error the temporary
file is removed and the target left as it was.
"""
from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path


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
    except OSError as err:  # name the target, not the temporary file (or no file: a failed write())
        if err.errno is None:
            raise
        raise OSError(err.errno, err.strerror, str(path)) from None
    finally:
        tmp.unlink(missing_ok=True)


def error_line(err: BaseException) -> str:
    """One line for a user: the file and the cause of an OS error, else the error's message.

    ``OSError(28, 'No space left on device', 'results/x.json')`` becomes
    ``results/x.json: No space left on device``.
    """
    if isinstance(err, OSError) and err.strerror:
        files = [str(f) for f in (err.filename, err.filename2) if f is not None]
        return ": ".join([*files, err.strerror]) if files else f"{err.strerror} (errno {err.errno})"
    return str(err)


#: The failures a user can cause (a bad value or file, a full disk, a failed engine run):
#: the command-line tools and rules report them in one line, not a traceback.
USER_ERRORS = (ValueError, OSError, RuntimeError)


def write_text(text: str, path) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_bytes(data: bytes, path) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_json(obj, path) -> Path:
    """Write ``obj`` as indented JSON to ``path`` atomically (:func:`atomic_path`)."""
    return write_text(json.dumps(obj, indent=2), path)
