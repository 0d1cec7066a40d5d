"""Property-based tests (hypothesis): mutated configs (values, whole-number floats and huge
numbers among them, and the YAML text of a config file or a ``--config`` argument) against the
config check, mutated dumps (plain and gzip) against the dump reader and the ``layer_metrics``
command line. Each input gives a result or a one-line error naming the key or the file: never
a traceback, never a half-written output.

Seeded (``derandomize``) and bounded, so ``make test`` stays fast; the example count
per test is ``FUZZ_EXAMPLES`` (default 150). ``benchmarks/bench_fuzz.py`` runs more and
records how many cases were tried (benchmarks/measured/fuzz.md).
"""
import contextlib
import copy
import gzip
import io
import json
import math
import os

import numpy as np
import pandas as pd
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from analysis.config.errors import ConfigError
from analysis.config.fidelity import scene
from analysis.config.load import load_config
from analysis.config.reading import coerce_cli_values
from analysis.config.sweep import sweep_runs
from analysis.measure import main as layer_metrics_main
from analysis.metrics.dump import DumpError, read_dump, write_dump
from tests.test_config import ROOT

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "150"))
FUZZ = settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

BASE = yaml.safe_load((ROOT / "config.yaml").read_text())


def _leaves(tree, path=()):
    """Every (path, value) in a nested mapping, lists' items included, sections too."""
    out = [(path, tree)] if path else []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out += _leaves(v, (*path, k))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out += _leaves(v, (*path, i))
    return out


PATHS = [p for p, _ in _leaves(BASE)]

BAD_VALUES = st.one_of(
    st.none(), st.booleans(), st.just(float("nan")), st.just(float("inf")), st.just(float("-inf")),
    st.integers(-10**30, 10**30), st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 0.0, -0.5, 1e308, 1e-308, 10**6, "", "x", "nan", "70 mm/s"]),
    st.sampled_from([1.0, 2.0, 3.0, 90.0, 300.0, 1e9, 1e12, 10**9, 100000, 1e-6, 1e-12, "yes", "1e9"]),
    st.lists(st.integers(-5, 5), max_size=3),
    st.dictionaries(st.sampled_from(["a", "U_mm_s"]), st.integers(), max_size=2),
)


def _key_named(message: str, path) -> bool:
    """Does ``message`` name a key on ``path`` (its own name or a section above it)?"""
    names = [str(p) for p in path if not isinstance(p, int)]
    return any(name in message for name in names)


def _set(config, path, value):
    node = config
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def _delete(config, path):
    node = config
    for p in path[:-1]:
        node = node[p]
    del node[path[-1]]


MUTATION = st.one_of(
    st.tuples(st.just("set"), st.sampled_from(PATHS), BAD_VALUES),
    st.tuples(st.just("delete"), st.sampled_from(PATHS), st.none()),
    st.tuples(st.just("unknown"), st.sampled_from([p for p, v in _leaves(BASE) if isinstance(v, dict)] + [()]),
              st.sampled_from(["colour", "U", "speed_mm_s"])),
)


@FUZZ
@given(mutations=st.lists(MUTATION, min_size=1, max_size=3))
def test_mutated_config_is_accepted_or_refused_by_key(mutations):
    config = copy.deepcopy(BASE)
    for kind, path, value in mutations:
        try:
            if kind == "set":
                _set(config, path, value)
            elif kind == "delete":
                _delete(config, path)
            else:
                _set(config, (*path, value), 1)
        except (KeyError, IndexError, TypeError):  # an earlier mutation removed or replaced the parent
            pass
    try:
        checked = load_config(config, base_dir=ROOT)
    except ConfigError as err:
        event("config refused")
        message = str(err)
        assert "\n" not in message, message
        assert any(_key_named(message, path if kind != "unknown" else (*path, value))
                   for kind, path, value in mutations), (mutations, message)
        return
    event("config accepted")
    _accepted_is_sound(checked)


def _accepted_is_sound(checked):
    """An accepted config: the scene of every level is finite, its counts are integers, its runs listable."""
    for level in checked["fidelity"]:
        s = scene(checked, level)
        assert all(math.isfinite(v) for v in (*s.box, s.timestep, s.strip_width, *s.sampling_region)), level
        assert s.timestep > 0 and s.heap_particles > 0
        assert isinstance(s.heap_particles, int) and isinstance(s.roller_facets, int)
    assert isinstance(checked["sweep"]["replicates"], int) and isinstance(checked["random_seed"], int)
    assert sweep_runs(checked)


TEXT = (ROOT / "config.yaml").read_text()
YAML_CHARS = st.sampled_from(list("[]{}:,\"'\t-#&*!|>%@? \n") + ["1e9", "2.0", "yes", "- x", ": y", "\\"])
TEXT_MUTATION = st.tuples(st.sampled_from(["insert", "delete", "replace", "truncate", "indent", "duplicate_line"]),
                          st.integers(0, len(TEXT)), YAML_CHARS)


def _mutate_text(text: str, kind: str, k: int, chars: str) -> str:
    k %= len(text) + 1
    if kind == "insert":
        return text[:k] + chars + text[k:]
    if kind == "delete":
        return text[:k] + text[k + len(chars):]
    if kind == "replace":
        return text[:k] + chars + text[k + len(chars):]
    if kind == "truncate":
        return text[:k]
    lines = text.split("\n")
    i = k % len(lines)
    if kind == "indent":
        lines[i] = chars[:1].replace("\n", " ") + lines[i]
    else:
        lines.insert(i, lines[i])
    return "\n".join(lines)


@FUZZ
@given(mutations=st.lists(TEXT_MUTATION, min_size=1, max_size=3))
def test_mutated_config_file_is_accepted_or_refused_by_file_or_key(tmp_path_factory, mutations):
    text = TEXT
    for mutation in mutations:
        text = _mutate_text(text, *mutation)
    path = tmp_path_factory.mktemp("yaml") / "config.yaml"
    path.write_text(text)
    try:
        checked = load_config(path)
    except ConfigError as err:
        message = str(err)
        event("YAML error, named by file" if message.startswith(str(path)) else "config refused by key")
        assert "\n" not in message, message
        assert message.startswith(str(path)) or message.startswith("config key"), message
        return
    event("config accepted")
    _accepted_is_sound(checked)


@FUZZ
@given(section=st.sampled_from(["sweep", "surrogate", "roller", "fidelity"]), mutation=TEXT_MUTATION)
def test_mutated_config_argument_is_accepted_or_refused_by_argument_or_key(section, mutation):
    argument = _mutate_text(json.dumps(BASE[section]), *mutation)   # --config <section>='<flow YAML>'
    config = copy.deepcopy(BASE)
    try:
        config[section] = coerce_cli_values({section: argument})[section]
        checked = load_config(config, base_dir=ROOT)
    except ConfigError as err:
        message = str(err)
        event("YAML error, named by argument" if message.startswith("--config") else "config refused by key")
        assert "\n" not in message, message
        assert message.startswith((f"--config {section}=", "config key")), message
        return
    event("config accepted")
    _accepted_is_sound(checked)


# ------------------------------------------------------------------ dumps


def _lattice_dump_text(tmp_dir) -> bytes:
    """A valid dump: 3 x 3 spheres (r = 100 um) on a 1 x 1 mm box, with ids and velocities."""
    a, r = 300e-6, 100e-6
    xs, ys = np.meshgrid(np.arange(3) * a + 2 * r, np.arange(3) * a + 2 * r)
    atoms = pd.DataFrame({"id": np.arange(1, 10), "type": 1, "x": xs.ravel(), "y": ys.ravel(), "z": r,
                          "radius": r, "vx": 0.0, "vy": 0.0, "vz": 0.0})
    path = tmp_dir / "valid.dump"
    write_dump(path, atoms, [[0, 1e-3], [0, 1e-3], [-1e-4, 1e-3]], timestep=1000)
    return path.read_bytes()


@pytest.fixture(scope="module")
def valid_dump(tmp_path_factory):
    return _lattice_dump_text(tmp_path_factory.mktemp("fuzz"))


def _shuffle_columns(text: bytes, order) -> bytes:
    lines = text.decode().splitlines()
    names = lines[8].split()[2:]
    perm = [names[i] for i in order]
    out = lines[:8] + ["ITEM: ATOMS " + " ".join(perm) + " "]
    for line in lines[9:]:
        fields = dict(zip(names, line.split()))
        out.append(" ".join(fields[n] for n in perm))
    return ("\n".join(out) + "\n").encode()


def _mutate(text: bytes, kind: str, k: int, value: str) -> bytes:
    lines = text.decode().split("\n")
    atom_lines = range(9, len(lines) - 1)
    if kind == "truncate":
        return text[: k % (len(text) + 1)]
    if kind == "duplicate_id":
        i = atom_lines[k % len(atom_lines)]
        return "\n".join(lines[: i + 1] + [lines[i]] + lines[i + 1:]).replace(
            "NUMBER OF ATOMS\n9", "NUMBER OF ATOMS\n10").encode()
    if kind == "value":  # one field of one atom line replaced
        i = atom_lines[k % len(atom_lines)]
        fields = lines[i].split()
        fields[k % len(fields)] = value
        lines[i] = " ".join(fields)
        return "\n".join(lines).encode()
    if kind == "count":
        lines[3] = value
        return "\n".join(lines).encode()
    if kind == "header_line":
        lines[k % 9] = value
        return "\n".join(lines).encode()
    packed = gzip.compress(text, mtime=0)
    if kind == "gzip_flip":  # one byte of the compressed file flipped
        i = k % len(packed)
        return packed[:i] + bytes([packed[i] ^ (1 + k % 255)]) + packed[i + 1:]
    if kind == "gzip_truncate":
        return packed[: k % len(packed)]
    raise AssertionError(kind)


DUMP_MUTATION = st.tuples(
    st.sampled_from(["truncate", "duplicate_id", "value", "count", "header_line", "gzip_flip", "gzip_truncate"]),
    st.integers(0, 10**6),
    st.sampled_from(["nan", "inf", "-inf", "1e308", "-1", "0", "x", "", "1e999", "99999999999999999999",
                     "1000000000000", "-5", "ITEM: ATOMS x y", "4.2e-4"]),
)

REGION_MM = ["0", "1", "0", "1"]


def _layer_metrics(dump_path, json_path):
    """``layer_metrics`` in-process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = layer_metrics_main([str(dump_path), "--region", *REGION_MM, "--speed", "50", "--density", "4430",
                                     "--lines", "40", "--json", str(json_path)])
    return status, out.getvalue(), err.getvalue()


@FUZZ
@given(mutation=DUMP_MUTATION)
def test_mutated_dump_gives_metrics_or_one_line_naming_the_file(valid_dump, tmp_path_factory, mutation):
    folder = tmp_path_factory.mktemp("dump")
    path, report = folder / "mutated.dump", folder / "metrics.json"
    path.write_bytes(_mutate(valid_dump, *mutation))
    try:
        frame = read_dump(path)
    except DumpError as err:
        event("dump refused by read_dump")
        assert str(path) in str(err)
    else:
        assert len(frame.atoms) >= 0
    status, out, err = _layer_metrics(path, report)
    event(f"layer_metrics exit {status}")
    if status == 0:
        metrics = json.loads(out)
        assert json.loads(report.read_text()) == metrics
        assert all(v is None or math.isfinite(v) for v in metrics.values() if not isinstance(v, (list, str))), metrics
    else:
        assert status == 2 and out == ""
        assert err.count("\n") == 1 and err.startswith("layer_metrics: error:"), err
        assert "mutated.dump" in err or "region" in err or "dump" in err, err
        assert sorted(p.name for p in folder.iterdir()) == ["mutated.dump"]  # nothing half-written


@FUZZ
@given(order=st.permutations(range(9)))
def test_shuffled_columns_give_the_same_metrics(valid_dump, tmp_path_factory, order):
    folder = tmp_path_factory.mktemp("shuffled")
    (folder / "a.dump").write_bytes(valid_dump)
    (folder / "b.dump").write_bytes(_shuffle_columns(valid_dump, order))
    first, second = (_layer_metrics(folder / name, folder / f"{name}.json") for name in ("a.dump", "b.dump"))
    assert first[0] == second[0] == 0
    assert json.loads(first[1]) == json.loads(second[1])
