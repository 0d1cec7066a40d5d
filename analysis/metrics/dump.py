"""Read and write LIGGGHTS/LAMMPS ``dump custom`` text files.

A dump file is a sequence of frames, each of the form::

    ITEM: TIMESTEP
    1000
    ITEM: NUMBER OF ATOMS
    2
    ITEM: BOX BOUNDS pp pp ff
    -0.01 0.01
    -0.01 0.01
    0.0 0.005
    ITEM: ATOMS id x y z radius
    1 0.001 0.002 0.0001 5e-05
    2 ...

The columns of the atom lines are named by the ``ITEM: ATOMS`` header, in
any order (LIGGGHTS writes the header with a trailing space). Files may be
gzip-compressed (detected from their content, not their name). Values are
read as written: LIGGGHTS runs in SI units, so positions and radii are in
metres.
"""

from __future__ import annotations

import gzip
import io
import mmap
import re
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["DumpError", "Frame", "read_dump", "write_dump"]


#: Columns a dump must have for the spread-layer analysis.
REQUIRED_COLUMNS = ("x", "y", "z", "radius")


_GZIP_MAGIC = b"\x1f\x8b"


# One match per frame: group 1 is the timestep value.
_FRAME_START = re.compile(rb"ITEM: TIMESTEP[ \t]*\r?\n[ \t]*(\S+)")


_HEADER_LINES = 9  # TIMESTEP, value, NUMBER OF ATOMS, N, BOX BOUNDS, 3 bounds, ATOMS


class DumpError(ValueError):
    """A file is not a readable dump, or lacks what was asked of it."""


@dataclass(frozen=True)
class Frame:
    """One frame of a dump file.

    Attributes
    ----------
    timestep : int
        Simulation timestep of the frame.
    box : numpy.ndarray, shape (3, 2)
        Box bounds ``[[xlo, xhi], [ylo, yhi], [zlo, zhi]]`` in the dump's
        length unit (m for LIGGGHTS in SI). For a triclinic box these are
        the bounds of its bounding box.
    atoms : pandas.DataFrame
        One row per atom, one column per name in the ``ITEM: ATOMS`` header,
        in the header's order.
    periodic : tuple of bool
        Whether x, y, z are periodic (``pp`` in the ``BOX BOUNDS`` header).
    """

    timestep: int
    box: np.ndarray
    atoms: pd.DataFrame
    periodic: tuple = (False, False, False)


def read_dump(path, timestep=None, required=REQUIRED_COLUMNS) -> Frame:
    """Read one frame of a LIGGGHTS/LAMMPS ``dump custom`` file.

    Parameters
    ----------
    path : str or os.PathLike
        Dump file, plain text or gzip-compressed.
    timestep : int, optional
        Timestep of the frame to read; default the last frame in the file.
    required : sequence of str, optional
        Column names the frame must have (default ``x y z radius``).

    Returns
    -------
    Frame
        Timestep, box bounds (dump units, m in SI) and atoms table.

    Raises
    ------
    DumpError
        If the file is empty, not a dump, truncated, has a frame whose atom
        lines do not match its announced count, lacks a required column, or
        has no frame with the requested timestep. The message names the file.
    FileNotFoundError
        If ``path`` does not exist.
    """
    path = Path(path)
    data = _load_bytes(path)
    try:
        block = _select_frame(data, path, timestep)
    finally:
        if isinstance(data, mmap.mmap):
            data.close()
    return _parse_frame(block, path, required)


def read_frames(path, required=REQUIRED_COLUMNS):
    """Every frame of a dump file, in order, in one pass (a movie of a run).

    Parameters and errors as :func:`read_dump`; yields :class:`Frame`.
    """
    path = Path(path)
    data = _load_bytes(path)
    try:
        starts = [m.start() for m in _FRAME_START.finditer(data)] + [len(data)]
        if len(starts) == 1:
            raise DumpError(f"{path}: not a LAMMPS/LIGGGHTS dump file (no 'ITEM: TIMESTEP' frame found)")
        for begin, end in zip(starts[:-1], starts[1:]):
            yield _parse_frame(bytes(data[begin:end]), path, required)
    finally:
        if isinstance(data, mmap.mmap):
            data.close()


def write_dump(path, atoms, box, timestep=0, append=False, periodic=(False, True, False)) -> None:
    """Write one frame in LIGGGHTS ``dump custom`` format.

    Parameters
    ----------
    path : str or os.PathLike
        Output file; gzip-compressed if its name ends in ``.gz``.
    atoms : pandas.DataFrame
        One row per atom; every column is written, in order, under the
        ``ITEM: ATOMS`` header (with LIGGGHTS's trailing space). Floats are
        written with round-trip precision.
    box : array_like, shape (3, 2)
        Box bounds ``[[xlo, xhi], [ylo, yhi], [zlo, zhi]]`` in m.
    timestep : int, optional
        Timestep of the frame.
    append : bool, optional
        Append the frame to an existing file instead of replacing it.
    periodic : tuple of bool, optional
        Periodic axes (``pp``; others ``ff``); default that of the spreading
        scene, periodic across the roller's axis y only.
    """
    box = np.asarray(box, dtype=float).reshape(3, 2)
    bounds = "\n".join(f"{lo!r} {hi!r}" for lo, hi in box.tolist())
    header = (
        f"ITEM: TIMESTEP\n{int(timestep)}\nITEM: NUMBER OF ATOMS\n{len(atoms)}\n"
        f"ITEM: BOX BOUNDS {' '.join('pp' if p else 'ff' for p in periodic)}\n{bounds}\n"
        f"ITEM: ATOMS {' '.join(atoms.columns)} \n"
    )
    body = atoms.to_csv(sep=" ", header=False, index=False, lineterminator="\n")
    mode = "at" if append else "wt"
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, mode, newline="\n") as f:
        f.write(header + body)


def _load_bytes(path: Path):
    """Return the file's (decompressed) content as a bytes-like object."""
    with open(path, "rb") as f:
        if f.read(2) == _GZIP_MAGIC:
            try:
                with gzip.open(path, "rb") as g:
                    return g.read()
            except (OSError, EOFError, zlib.error) as err:  # truncated or corrupt stream
                raise DumpError(f"{path}: broken gzip stream ({err})") from None
        f.seek(0)
        try:
            return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError as err:  # empty file
            raise DumpError(f"{path}: empty file, not a dump") from err


def _select_frame(data, path: Path, timestep) -> bytes:
    """Return the text of the frame with ``timestep`` (None: the last frame)."""
    starts = list(_FRAME_START.finditer(data))
    if not starts:
        raise DumpError(f"{path}: not a LAMMPS/LIGGGHTS dump file (no 'ITEM: TIMESTEP' frame found)")
    steps = [_parse_int(m.group(1), path, "timestep") for m in starts]
    if timestep is None:
        i = len(starts) - 1
    elif timestep in steps:
        i = steps.index(timestep)
    else:
        raise DumpError(
            f"{path}: no frame with timestep {timestep} "
            f"({len(steps)} frames, timesteps {steps[0]}..{steps[-1]})"
        )
    end = starts[i + 1].start() if i + 1 < len(starts) else len(data)
    return bytes(data[starts[i].start() : end])


def _parse_frame(block: bytes, path: Path, required) -> Frame:
    """Parse one frame's text (header plus atom lines)."""
    lines = block.split(b"\n", _HEADER_LINES)
    if len(lines) < _HEADER_LINES:
        raise DumpError(f"{path}: truncated frame header ({len(lines)} of {_HEADER_LINES} header lines)")
    head = [ln.decode("ascii", "replace").strip() for ln in lines[:_HEADER_LINES]]
    timestep = _parse_int(head[1], path, "timestep")
    expect = [(2, "ITEM: NUMBER OF ATOMS"), (4, "ITEM: BOX BOUNDS"), (8, "ITEM: ATOMS")]
    for k, item in expect:
        if not head[k].startswith(item):
            raise DumpError(f"{path}: timestep {timestep}: expected '{item}' in header line {k + 1}, "
                            f"got {head[k]!r}")
    n_atoms = _parse_int(head[3], path, "number of atoms")
    try:
        box = np.array([ln.split()[:2] for ln in head[5:8]], dtype=float)
    except ValueError as err:
        raise DumpError(f"{path}: timestep {timestep}: unreadable box bounds {head[5:8]}") from err
    if box.shape != (3, 2):
        raise DumpError(f"{path}: timestep {timestep}: unreadable box bounds {head[5:8]}")
    flags = [f for f in head[4].split()[3:] if len(f) == 2 and set(f) <= set("pfsm")]
    periodic = tuple(f == "pp" for f in flags[:3]) if len(flags) >= 3 else (False, False, False)
    names = head[8].split()[2:]
    missing = [c for c in required if c not in names]
    if missing:
        raise DumpError(f"{path}: timestep {timestep}: missing column(s) {missing} (columns: {names})")
    body = lines[_HEADER_LINES] if len(lines) > _HEADER_LINES else b""
    atoms = _parse_atoms(body, names, n_atoms, path, timestep)
    return Frame(timestep=timestep, box=box, atoms=atoms, periodic=periodic)


def _parse_atoms(body: bytes, names, n_atoms: int, path: Path, timestep: int) -> pd.DataFrame:
    """Parse the atom lines of one frame into a DataFrame, checking their count."""
    where = f"{path}: timestep {timestep}"
    body = body.rstrip()
    n_lines = body.count(b"\n") + 1 if body else 0
    if n_lines != n_atoms:
        raise DumpError(f"{where}: announces {n_atoms} atoms but has {n_lines} atom lines (truncated file?)")
    if n_atoms == 0:
        return pd.DataFrame({c: np.empty(0) for c in names})
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)  # more fields than names
            atoms = pd.read_csv(io.BytesIO(body), sep=r"\s+", header=None, names=names, index_col=False)
    except (pd.errors.ParserError, pd.errors.ParserWarning, ValueError) as err:
        cause = " ".join(str(err).split())  # pandas' messages span lines
        raise DumpError(f"{where}: atom lines do not match the columns {names} ({cause})") from err
    bad = [c for c in names if not pd.api.types.is_numeric_dtype(atoms[c]) or atoms[c].isna().any()]
    if len(atoms) != n_atoms or bad:
        raise DumpError(f"{where}: missing or non-numeric values in column(s) {bad} (truncated line?)")
    infinite = [c for c in names if not np.isfinite(atoms[c].to_numpy(dtype=float)).all()]
    if infinite:
        raise DumpError(f"{where}: infinite values in column(s) {infinite}")
    return atoms


def _parse_int(text, path: Path, what: str) -> int:
    """Parse an integer header value, raising DumpError naming the file."""
    try:
        return int(text)
    except ValueError as err:
        raise DumpError(f"{path}: bad {what} {text!r}") from err
