"""Bad input, second pass (#35): each probe refused in one line naming the key or the file,
before any engine runs, with nothing half-written."""
import copy
import subprocess
import sys

import numpy as np
import pytest
import yaml

from analysis.config.errors import ConfigError
from analysis.config.load import load_config
from analysis.config.reading import coerce_cli_values
from analysis.config.sweep import sweep_runs
from tests.test_config import ROOT

BASE = yaml.safe_load((ROOT / "config.yaml").read_text())


def with_values(**values):
    """The shipped config with dotted keys (``__`` for ``.``) set."""
    config = copy.deepcopy(BASE)
    for dotted, value in values.items():
        *path, last = dotted.split("__")
        node = config
        for key in path:
            node = node[key]
        node[last] = value
    return config


def refused(config) -> str:
    with pytest.raises(ConfigError) as err:
        load_config(config, base_dir=ROOT)
    message = str(err.value)
    assert "\n" not in message, message
    return message


# ------------------------------------------------------------------ the config


@pytest.mark.parametrize("dotted, value", [
    ("sweep__replicates", 2.0), ("fidelity__smoke__size_classes", 3.0), ("roller__facets_around", 90.0),
    ("random_seed", 1.0), ("fidelity__default__heap_particles", 300.0),
])
def test_whole_number_floats_are_refused_where_integers_are_wanted(dotted, value):
    message = refused(with_values(**{dotted: value}))
    assert dotted.replace("__", ".") in message and f"{value!r} is not of type 'integer'" in message


def test_a_swept_integer_key_stays_an_integer():
    config = load_config(with_values(level="smoke", sweep__U_mm_s=[40, 70], sweep__omega_rad_s=[-5, 0, 5],
                                     surrogate__n_test=2, **{"sweep__fidelity.smoke.heap_particles": [400, 500]}),
                         base_dir=ROOT)
    assert len(sweep_runs(config)) == 12


@pytest.mark.parametrize("dotted, value, words", [
    ("sweep__U_mm_s", [40, 1e12], "maximum of 2000"),
    ("sweep__omega_rad_s", [0, -5000], "minimum of -1000"),
    ("roller__gap_um", 1e9, "maximum of 10000"),
    ("timestep__rayleigh_fraction", 1e-12, "minimum of 0.01"),
    ("fidelity__default__heap_particles", 10**9, "maximum of 10000000"),
    ("fidelity__default__profilometer_lines", 100000, "maximum of 4000"),
    ("substrate__grid_spacing_um", 1e-6, "at most 1e+07 (memory)"),
    ("surrogate__grid_points", 100000, "maximum of 1001"),
    ("sweep__U_mm_s", [1e-9, 40], "at most 2147483647 fit a LIGGGHTS run"),
    ("fidelity__smoke__settle_time_s", 1e6, "at most 2147483647 fit a LIGGGHTS run"),
    ("sweep__omega_rad_s", [-20, -15, -10, -5, 0, 5, 10, 15, 400], "more than 0.1 of the smallest radius"),
    ("surrogate__cv_folds", 50, "exceeds the sweep's 45 points"),
    ("material__youngs_modulus_dem_Pa", 1000, "minimum of 5000000"),             # found by 5000 fuzz cases
    ("fidelity__smoke__youngs_modulus_dem_Pa", 1000, "minimum of 5000000"),
    ("fidelity__default__run_out_max_mm", 299856,
     "fidelity.default.sampling_start_mm + sampling_length_mm + run_out_mm"),
    ("fidelity__default__run_out_mm", 299856, "the latest stop, run_out_max_mm (12 mm)"),
    ("roller__diameter_mm", 2.6815615859885194e+157, "maximum of 1000"),        # found by 5000 fuzz cases at 1c56d9f
    ("roller__diameter_mm", 596477, "maximum of 1000"),                         # (an overflow; a message without it)
])
def test_values_beyond_a_bound_are_refused_by_key_with_the_bound(dotted, value, words):
    message = refused(with_values(**{dotted: value}))
    assert dotted.split("__")[-1] in message and words in message, message


def test_a_boolean_given_as_a_string_is_refused():
    assert "'keep_supply_limited_runs'" in refused(with_values(keep_supply_limited_runs="yes"))
    cli = coerce_cli_values({"keep_supply_limited_runs": "yes"})  # --config keep_supply_limited_runs=yes
    assert cli == {"keep_supply_limited_runs": "yes"}
    assert coerce_cli_values({"a": "true", "b": "1e9", "c": "40"}) == {"a": True, "b": 1e9, "c": 40}


def test_a_key_that_is_not_a_name_is_refused_by_its_place():
    """--config 'sweep={..., null: 1}' (found by 5000 fuzz cases: jsonschema's key patterns crashed on it)."""
    config = coerce_cli_values({"sweep": '{"U_mm_s": [40, 70], null: 1}'})
    with pytest.raises(ConfigError, match=r"config key 'sweep.None': a key must be a name"):
        load_config(with_values(**config), base_dir=ROOT)


def test_a_yaml_error_in_a_config_argument_names_it_with_line_and_column():
    with pytest.raises(ConfigError) as err:
        coerce_cli_values({"sweep": '{"U_mm_s": [40, 70}'})
    assert str(err.value) == ("--config sweep={\"U_mm_s\": [40, 70}: YAML syntax error at line 1, column 19: "
                              "expected ',' or ']', but got '}'")


@pytest.mark.parametrize("text, words", [
    ("level: smoke\nsweep:\n  U_mm_s: [40, 70\n  replicates: 1\n", "YAML syntax error at line 4, column 13"),
    ("", "empty: no config keys"),
    ("- 1\n- 2\n", "holds a list, not a mapping"),
    ("\xff\xfe", "not a YAML text file"),
])
def test_a_broken_config_file_is_one_line_naming_the_file(tmp_path, text, words):
    path = tmp_path / "bad.yaml"
    path.write_bytes(text.encode("latin-1"))
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert str(err.value).startswith(f"{path}: ") and words in str(err.value) and "\n" not in str(err.value)


def test_simulate_cli_with_a_broken_config_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("level: smoke\nsweep: {U_mm_s: [40, 70}\n")
    res = subprocess.run([sys.executable, "-m", "analysis.dem.simulate", "geometry", "--config", str(bad),
                          "--out", str(tmp_path / "m")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr == f"spreadmap-simulate: error: {bad}: YAML syntax error at line 2, column 24: " \
                         "expected ',' or ']', but got '}'\n"
    assert not (tmp_path / "m").exists()


def test_snakemake_names_a_broken_config_argument_and_the_config_file(tmp_path):
    """The README's --config form with one typo, and a config.yaml with a syntax error: one line each."""
    def dry_run(*extra, workdir):
        proc = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--cores", "1", "-d", str(workdir),
                               "-s", str(ROOT / "Snakefile"), *extra], capture_output=True, text=True, cwd=ROOT)
        assert proc.returncode != 0
        return proc.stdout + proc.stderr

    out = dry_run("--configfile", str(ROOT / "config.yaml"), "--config", 'sweep={"U_mm_s": [40, 70}',
                  workdir=tmp_path / "a")
    assert "--config sweep={\"U_mm_s\": [40, 70}: YAML syntax error at line 1, column 19" in out
    assert "Traceback" not in out and not (tmp_path / "a" / "results").exists()
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "config.yaml").write_text("level: smoke\nsweep:\n  U_mm_s: [40, 70\n  replicates: 1\n")
    out = dry_run(workdir=tmp_path / "b")
    assert "config.yaml: YAML syntax error at line 4, column 13" in out and "Traceback" not in out


# ------------------------------------------------------------------ a user's substrate mesh


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """The smoke level's generated substrate (it covers the bed exactly) and the config that made it."""
    from analysis.dem.simulate import make_geometry
    folder = tmp_path_factory.mktemp("generated")
    config = load_config(with_values(level="smoke"), base_dir=ROOT)
    make_geometry(config, "smoke", folder)
    return folder / "substrate.stl"


def geometry_with(mesh, out):
    from analysis.dem.simulate import make_geometry
    config = with_values(level="smoke", substrate__mesh=str(mesh))
    return make_geometry(load_config(config, base_dir=ROOT), "smoke", out)


@pytest.mark.parametrize("fmt", ["binary.stl", "ply", "obj"])
def test_a_mesh_that_exactly_covers_the_bed_passes_float32_rounding(generated, tmp_path, fmt):
    import trimesh
    mesh = trimesh.load_mesh(str(generated), process=False)
    path = tmp_path / f"mine.{fmt}"
    path.write_bytes(trimesh.exchange.export.export_mesh(mesh, None, file_type=fmt.split(".")[-1]) if fmt != "obj"
                     else trimesh.exchange.obj.export_obj(mesh).encode())
    summary = geometry_with(path, tmp_path / "out")
    assert summary["substrate_triangles"] == len(mesh.faces)


@pytest.mark.parametrize("case, words", [
    ("empty", "holds no triangles"), ("random", "holds no triangles"), ("truncated", "holds no triangles"),
    ("nan_vertex", "1 vertices that are not finite numbers"), ("millimetres", "in millimetres or micrometres?"),
    ("heights_in_mm", "box is high"),
])
def test_a_bad_mesh_is_refused_in_one_line_naming_the_file(generated, tmp_path, case, words):
    import os

    import trimesh
    mesh = trimesh.load_mesh(str(generated), process=False)
    path = tmp_path / "mine.stl"
    text = generated.read_bytes()
    if case == "empty":
        path.write_bytes(b"")
    elif case == "random":
        path.write_bytes(os.urandom(4000))
    elif case == "truncated":
        path.write_bytes(text[: len(text) // 2])
    else:
        if case == "nan_vertex":
            mesh.vertices[mesh.faces[7, 1], 2] = np.nan
        elif case == "millimetres":
            mesh.vertices *= 1e3
        else:
            mesh.vertices[:, 2] *= 1e3
        path.write_text(trimesh.exchange.stl.export_stl_ascii(mesh))
    with pytest.raises(ConfigError) as err:
        geometry_with(path, tmp_path / "out")
    message = str(err.value)
    assert "substrate.mesh" in message and str(path) in message and words in message, message
    assert "\n" not in message and not (tmp_path / "out").exists()


def test_a_meshs_content_is_in_the_fingerprint(generated, tmp_path):
    from analysis.config.sweep import simulation_fingerprint
    mesh = tmp_path / "mine.stl"
    mesh.write_bytes(generated.read_bytes())
    config = load_config(with_values(level="smoke", substrate__mesh="mine.stl"), base_dir=tmp_path)
    before = simulation_fingerprint(config, "smoke", base_dir=tmp_path)
    mesh.write_bytes(generated.read_bytes().replace(b"solid", b"solid edited", 1))
    assert simulation_fingerprint(config, "smoke", base_dir=tmp_path) != before
    assert simulation_fingerprint(config, "smoke", sections=("roller",), base_dir=tmp_path) == \
        simulation_fingerprint(config, "smoke", sections=("roller",))


def test_simulate_settle_with_missing_meshes_is_refused_by_name(tmp_path, capsys):
    from analysis.dem.simulate import main
    assert main(["settle", "--config", str(ROOT / "config.yaml"), "--level", "smoke",
                 "--meshes", str(tmp_path / "nonexistent"), "--out", str(tmp_path / "s")]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err == f"spreadmap-simulate: error: {tmp_path / 'nonexistent' / 'substrate.stl'}: No such " \
                                "file or directory (the geometry step's substrate: --meshes)\n"
    assert not (tmp_path / "s").exists()


def test_simulate_spread_with_a_nan_speed_is_refused(tmp_path, capsys):
    from analysis.dem.simulate import main
    assert main(["spread", "--config", str(ROOT / "config.yaml"), "--level", "smoke", "--meshes", "m",
                 "--settled", "s", "--U", "nan", "--omega", "0", "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "U = nan mm/s" in err and not (tmp_path / "never").exists()


# ------------------------------------------------------------------ the workflow


def snakemake(workdir, *args):
    proc = subprocess.run([sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "-d", str(workdir),
                           "--configfile", str(ROOT / "config.yaml"), str(ROOT / ".test/config.yaml"), *args],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    return proc.returncode, proc.stdout + proc.stderr


def test_a_run_outside_the_sweep_asked_for_by_its_path_is_checked_as_a_swept_point(tmp_path):
    """(One that passes the checks runs: test_the_slurm_benchmarks_commands_resolve_without_a_cluster.)"""
    code, out = snakemake(tmp_path, "-n", "--cores", "1", "results/smoke/runs/U1e+12_w-7_r0/metrics.json")
    assert code != 0 and "KeyError" not in out
    assert "run folder 'U1e+12_w-7_r0': config key 'sweep.U_mm_s.0': 1000000000000.0 is greater than the maximum " \
           "of 2000" in out, out
    assert not (tmp_path / "results").exists()


def test_editing_a_user_mesh_reruns_its_geometry(generated, tmp_path):
    mesh = tmp_path / "scan.stl"
    mesh.write_bytes(generated.read_bytes())
    target = "results/smoke/meshes/r0/geometry.json"
    mine = ["--config", f"substrate={{mesh: {mesh}}}"]
    code, out = snakemake(tmp_path / "w", "--cores", "1", *mine, "--", target)
    assert code == 0, out
    code, out = snakemake(tmp_path / "w", "-n", "--cores", "1", *mine, "--", target)
    assert code == 0 and "Nothing to be done" in out, out
    text = mesh.read_text()
    mesh.write_text(text.replace("vertex ", "vertex  ", 1))   # the same shape: the content changed, not the physics
    code, out = snakemake(tmp_path / "w", "-n", "--cores", "1", *mine, "--", target)
    assert code == 0 and "geometry" in out and "Nothing to be done" not in out, out


# ------------------------------------------------------------------ LIGGGHTS' failures


def fake_liggghts(tmp_path, monkeypatch, body: str):
    """A stand-in ``liggghts`` (a shell script) for the run wrapper, and a one-line input for it."""
    import analysis.dem.liggghts as lg
    exe = tmp_path / "liggghts"
    exe.write_text(f"#!/bin/sh\n{body}\n")
    exe.chmod(0o755)
    monkeypatch.setattr(lg, "LIGGGHTS", str(exe))
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "in.txt").write_text('print "hello"\n')
    return tmp_path / "run" / "in.txt"


@pytest.mark.parametrize("body, words", [
    ("kill -9 $$", "was killed by SIGKILL (signal 9, e.g. the out-of-memory killer, a time limit or kill -9)"),
    ("echo 'ERROR: Mesh (id roller): 12 mesh elements have been lost / left the domain. (fix_mesh.cpp:91)'; exit 1",
     "the roller mesh left the simulation box (its facets outside were deleted): check roller.diameter_mm"),
    ("echo 'ERROR: Invalid run command N value (run.cpp:69)'; exit 1", "a run command out of range"),
    ("echo 'ERROR: Cannot open restart file ../settle/r0/settled.restart (read_restart.cpp:98)'; exit 1",
     "LIGGGHTS cannot open ../settle/r0/settled.restart"),
])
def test_a_foreseen_liggghts_failure_is_one_line_naming_what_to_change(tmp_path, monkeypatch, body, words):
    from analysis.dem.liggghts import LiggghtsError, run
    script = fake_liggghts(tmp_path, monkeypatch, body)
    with pytest.raises(LiggghtsError) as err:
        run(script, script.with_name("log.txt"))
    message = str(err.value)
    assert words in message and message.endswith(f"run folder: {script.parent}") and "\n" not in message, message


def test_a_full_disk_is_reported_as_a_full_disk(tmp_path, monkeypatch):
    import errno
    import shutil as sh

    import analysis.dem.liggghts as lg
    script = fake_liggghts(tmp_path, monkeypatch, "exit 0")
    monkeypatch.setattr(lg.shutil, "disk_usage", lambda path: sh._ntuple_diskusage(10**9, 10**9 - 4096, 4096))
    with pytest.raises(OSError) as err:
        lg.run(script, script.with_name("log.txt"))
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(script.parent)


def test_a_liggghts_that_exits_0_without_running_is_refused(generated, tmp_path, monkeypatch):
    from analysis.dem.liggghts import LiggghtsError
    from analysis.dem.simulate import settle
    fake_liggghts(tmp_path, monkeypatch, "exit 0")
    with pytest.raises(LiggghtsError, match="exited 0 without running a time step"):
        settle(load_config(with_values(level="smoke"), base_dir=ROOT), "smoke", generated.parent, tmp_path / "s")
    assert not (tmp_path / "s" / "health.json").exists()


# ------------------------------------------------------------------ layer metrics, dumps, recommend


def layer_metrics(*argv):
    import contextlib
    import io

    from analysis.measure import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([str(a) for a in argv])
    return status, out.getvalue(), err.getvalue()


@pytest.fixture
def lattice(tmp_path):
    """3 x 3 spheres (r = 100 um) in the corner of a 2 x 2 mm box."""
    import pandas as pd

    from analysis.metrics.dump import write_dump
    xs, ys = np.meshgrid(np.arange(3) * 3e-4 + 2e-4, np.arange(3) * 3e-4 + 2e-4)
    atoms = pd.DataFrame({"id": np.arange(1, 10), "x": xs.ravel(), "y": ys.ravel(), "z": 1e-4, "radius": 1e-4})
    write_dump(tmp_path / "frame.dump", atoms, [[0, 2e-3], [0, 2e-3], [-1e-4, 1e-3]], timestep=10)
    return tmp_path / "frame.dump"


@pytest.mark.parametrize("region, substrate, words", [
    (["0.0001", "0.0009", "0.0001", "0.0009"], None, "in metres? --region takes mm"),
    (["1.2", "1.8", "1.2", "1.8"], None, "no particle is centred in the region 1.2 1.8 1.2 1.8 mm (of 9"),
    (["0", "1", "0", "1"], "mm", "in millimetres? --substrate is in metres"),
])
def test_layer_metrics_refuses_an_empty_region_and_unit_slips(lattice, tmp_path, region, substrate, words):
    from analysis.dem.geometry import height_field_mesh, write_stl
    extra = []
    if substrate:
        plane = height_field_mesh(np.array([-1.0, 3.0]), np.array([-1.0, 3.0]), np.zeros((2, 2)))  # mm as m
        extra = ["--substrate", write_stl(plane, tmp_path / "plane.stl")]
    status, out, err = layer_metrics(lattice, "--region", *region, "--speed", "50", "--density", "4430",
                                     "--lines", "40", "--json", tmp_path / "m.json", *extra)
    assert status == 2 and out == "" and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "m.json").exists()


def test_a_corrupt_gzip_dump_is_one_line_naming_the_file(lattice, tmp_path):
    import gzip

    from analysis.metrics.dump import DumpError, read_dump
    packed = gzip.compress(lattice.read_bytes())
    for i in range(12, len(packed) - 8, max(1, (len(packed) - 20) // 60)):   # 60 one-byte flips in the stream
        path = tmp_path / "flipped.dump.gz"
        path.write_bytes(packed[:i] + bytes([packed[i] ^ 0xFF]) + packed[i + 1:])
        try:
            read_dump(path)
        except DumpError as err:
            assert str(path) in str(err) and "\n" not in str(err)


@pytest.mark.parametrize("argv, words", [
    (["--fix", "U_mm_s=90", "--fix", "U_mm_s=95"], "U_mm_s is fixed twice (at 90 too)"),
    (["--grid-points", "100000"], "--grid-points must be 2 to 1001"),
    (["--axis-points", "100000"], "--axis-points must be 2 to 101"),
])
def test_recommend_refuses_a_repeated_fix_and_a_grid_past_memory(tmp_path, capsys, argv, words):
    from analysis.surrogate.recommend import main
    with pytest.raises(SystemExit) as exit_:
        main(["--max-porosity", "30", "--model", str(tmp_path / "model.joblib"), *argv])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and words in err, err


# ------------------------------------------------------------------ what the workflow writes


def test_dataset_records_which_runs_were_resumed(tmp_path):
    import json

    import pandas as pd

    from analysis.metrics.dataset import build_dataset
    from tests.test_sweep import _synthetic_runs
    files = _synthetic_runs(tmp_path, with_gap=False)
    for i, path in enumerate(files["health"]):
        health = json.loads(path.read_text())
        path.write_text(json.dumps({**health, "resumed_from_step": 4000 if i == 2 else 0}))
    build_dataset(files["metrics"], files["health"], files["bench"], tmp_path / "dataset.csv")
    df = pd.read_csv(tmp_path / "dataset.csv")
    assert sorted(df["resumed_from_step"]) == [0] * 8 + [4000]


def test_a_grid_with_unbounded_intervals_comes_with_a_warning():
    import pandas as pd

    from analysis.surrogate.intervals import unbounded_warning
    grid = pd.DataFrame({"U_mm_s": [40.0, 70.0], "mass_g": [1.0, 2.0], "mass_g_lo": [-np.inf, -np.inf],
                         "mass_g_hi": [np.inf, np.inf]})
    assert unbounded_warning(grid, 6, 0.9) == (
        "warning: 2 interval columns of the grid are infinite (mass_g_lo, mass_g_hi): 90 % intervals need at least "
        "9 calibration runs, the model has 6; add sweep points or replicates, or lower surrogate.confidence")
    assert unbounded_warning(grid.drop(columns=["mass_g_lo", "mass_g_hi"]), 6, 0.9) is None


def test_the_slurm_benchmarks_commands_resolve_without_a_cluster(capsys):
    """benchmarks/bench_slurm.py --dry-run: its phases' Snakemake commands, the time-limited spread
    outside the sweep among them, resolve (the full run on a cluster: make bench-slurm)."""
    from benchmarks import bench_slurm
    with pytest.raises(SystemExit) as exit_:
        bench_slurm.main(["--limit-point", "fast"])
    assert exit_.value.code == 2 and "--limit-point 'fast': give U:omega" in capsys.readouterr().err
    assert bench_slurm.main(["--dry-run"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        "2. workflow through profiles/slurm: resolves", "3. time-limited spread: resolves",
        "5. local reference: resolves"]
