"""Tests of analysis.metrics.dump: reading and writing LIGGGHTS dump custom files."""

import gzip

import numpy as np
import pandas as pd
import pytest

from analysis.metrics.dump import DumpError, Frame, read_dump, read_frames, write_dump

BOX = np.array([[-1e-3, 2e-3], [0.0, 3e-3], [0.0, 1e-3]])

# A frame as LIGGGHTS writes it: columns in its own order, trailing space in
# the ATOMS header, an extra column, integer ids.
LIGGGHTS_TEXT = """ITEM: TIMESTEP
2500
ITEM: NUMBER OF ATOMS
3
ITEM: BOX BOUNDS pp pp ff
-1.0000000000000000e-03 2.0000000000000000e-03
0.0000000000000000e+00 3.0000000000000000e-03
0.0000000000000000e+00 1.0000000000000000e-03
ITEM: ATOMS id type radius z x y vx 
1 1 5.0e-05 5.0e-05 1.0e-04 2.0e-04 0
2 1 6.0e-05 1.2e-04 -3.0e-04 4.0e-04 0.5
3 2 7.5e-05 2.5e-04 1.5e-03 2.5e-03 -1
"""


def atoms_table(n=50, seed=3):
    """A random atoms table [m] with the usual LIGGGHTS columns."""
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "id": np.arange(1, n + 1),
            "type": rng.integers(1, 3, n),
            "x": rng.uniform(*BOX[0], n),
            "y": rng.uniform(*BOX[1], n),
            "z": rng.uniform(*BOX[2], n),
            "radius": rng.uniform(50e-6, 125e-6, n),
        }
    )


def test_reads_liggghts_frame_by_header_names(tmp_path):
    path = tmp_path / "a.dump"
    path.write_text(LIGGGHTS_TEXT)
    frame = read_dump(path)
    assert isinstance(frame, Frame)
    assert frame.timestep == 2500
    np.testing.assert_array_equal(frame.box, BOX)
    assert list(frame.atoms.columns) == ["id", "type", "radius", "z", "x", "y", "vx"]
    np.testing.assert_array_equal(frame.atoms["x"], [1.0e-4, -3.0e-4, 1.5e-3])
    np.testing.assert_array_equal(frame.atoms["radius"], [5.0e-5, 6.0e-5, 7.5e-5])
    np.testing.assert_array_equal(frame.atoms["id"], [1, 2, 3])


@pytest.mark.parametrize("name", ["b.dump", "b.dump.gz"])
def test_write_read_round_trip_is_exact(tmp_path, name):
    atoms = atoms_table()
    write_dump(tmp_path / name, atoms, BOX, timestep=7)
    frame = read_dump(tmp_path / name)
    assert frame.timestep == 7
    np.testing.assert_array_equal(frame.box, BOX)
    pd.testing.assert_frame_equal(frame.atoms, atoms)
    if name.endswith(".gz"):
        with gzip.open(tmp_path / name, "rt") as f:
            assert "ITEM: ATOMS id type x y z radius \n" in f.read()


def test_gzip_detected_by_content_not_name(tmp_path):
    path = tmp_path / "c.dump"  # gzipped but without .gz
    path.write_bytes(gzip.compress(LIGGGHTS_TEXT.encode()))
    assert read_dump(path).timestep == 2500


def three_frames(path):
    """A dump of three frames (timesteps 0, 100, 200) of different atoms; their tables by timestep."""
    tables = {step: atoms_table(n=10 + step // 100, seed=step) for step in (0, 100, 200)}
    for step, atoms in tables.items():
        write_dump(path, atoms, BOX, timestep=step, append=step > 0)
    return tables


@pytest.mark.parametrize("name", ["m.dump", "m.dump.gz"])
def test_last_frame_by_default_or_chosen_timestep(tmp_path, name):
    path = tmp_path / name
    tables = three_frames(path)
    assert read_dump(path).timestep == 200
    pd.testing.assert_frame_equal(read_dump(path).atoms, tables[200])
    pd.testing.assert_frame_equal(read_dump(path, timestep=100).atoms, tables[100])
    with pytest.raises(DumpError, match=r"no frame with timestep 150.*3 frames"):
        read_dump(path, timestep=150)


@pytest.mark.parametrize("name", ["m.dump", "m.dump.gz"])
def test_every_frame_in_order_in_one_pass(tmp_path, name):
    path = tmp_path / name
    tables = three_frames(path)
    frames = list(read_frames(path))
    assert [f.timestep for f in frames] == [0, 100, 200]
    for frame in frames:
        pd.testing.assert_frame_equal(frame.atoms, tables[frame.timestep])
    (tmp_path / "text").write_text("no frames here")
    with pytest.raises(DumpError, match="no 'ITEM: TIMESTEP' frame"):
        list(read_frames(tmp_path / "text"))


def test_empty_frame(tmp_path):
    path = tmp_path / "e.dump"
    write_dump(path, atoms_table(n=0), BOX, timestep=1)
    frame = read_dump(path)
    assert len(frame.atoms) == 0
    assert {"x", "y", "z", "radius"} <= set(frame.atoms.columns)


def test_triclinic_box_reads_bounds(tmp_path):
    text = LIGGGHTS_TEXT.replace("BOX BOUNDS pp pp ff", "BOX BOUNDS xy xz yz pp pp ff")
    lines = text.split("\n")
    lines[5:8] = [ln + " 0.0" for ln in lines[5:8]]
    path = tmp_path / "t.dump"
    path.write_text("\n".join(lines))
    np.testing.assert_array_equal(read_dump(path).box, BOX)


def test_dump_error_is_value_error():
    assert issubclass(DumpError, ValueError)


def test_truncated_file(tmp_path):
    path = tmp_path / "trunc.dump"
    write_dump(path, atoms_table(n=200), BOX)
    data = path.read_bytes()
    for cut in (len(data) // 2, len(data) - 30):  # mid-file, and mid-line in the last line
        path.write_bytes(data[:cut])
        with pytest.raises(DumpError, match="trunc.dump"):
            read_dump(path)


def test_truncated_gzip(tmp_path):
    path = tmp_path / "trunc.dump.gz"
    write_dump(path, atoms_table(n=500), BOX)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DumpError, match="trunc.dump.gz"):
        read_dump(path)


def test_frame_with_fewer_atom_lines_than_announced(tmp_path):
    path = tmp_path / "short.dump"
    write_dump(path, atoms_table(n=5), BOX, timestep=0)
    write_dump(path, atoms_table(n=5), BOX, timestep=10, append=True)
    lines = path.read_text().splitlines(keepends=True)
    del lines[12]  # an atom line of the first frame
    path.write_text("".join(lines))
    with pytest.raises(DumpError, match=r"short.dump: timestep 0: announces 5 atoms but has 4"):
        read_dump(path, timestep=0)
    assert len(read_dump(path).atoms) == 5  # the intact frame still reads


def test_frame_with_more_fields_than_columns(tmp_path):
    path = tmp_path / "wide.dump"
    path.write_text(LIGGGHTS_TEXT.replace("ITEM: ATOMS id type", "ITEM: ATOMS id"))
    with pytest.raises(DumpError, match="wide.dump"):
        read_dump(path)


@pytest.mark.parametrize("column", ["x", "y", "z", "radius"])
def test_missing_required_column(tmp_path, column):
    path = tmp_path / "nocol.dump"
    write_dump(path, atoms_table().drop(columns=column), BOX)
    with pytest.raises(DumpError, match=rf"nocol.dump.*missing column.*'{column}'"):
        read_dump(path)


def test_non_numeric_value(tmp_path):
    path = tmp_path / "nan.dump"
    path.write_text(LIGGGHTS_TEXT.replace("1.5e-03", "abc"))
    with pytest.raises(DumpError, match=r"nan.dump.*'x'"):
        read_dump(path)


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "empty file"),
        (b"x y z radius\n1 2 3 4\n", "not a LAMMPS/LIGGGHTS dump"),
        (b"ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n", "truncated frame header"),
        (b"ITEM: TIMESTEP\nfive\n", "bad timestep"),
    ],
)
def test_not_a_dump(tmp_path, content, message):
    path = tmp_path / "junk.txt"
    path.write_bytes(content)
    with pytest.raises(DumpError, match=rf"junk.txt.*{message}"):
        read_dump(path)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_dump(tmp_path / "nope.dump")
