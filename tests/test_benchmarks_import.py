"""Every benchmark script still imports against today's code and parses its own command line
(``--help``): the cheap guard against a benchmark rotting outside CI. The benchmarks' own smoke runs
are in test_bench_fidelity.py, test_bench_region.py, test_workflow.py (map_record), test_slurm.py
and test_bad_input.py (bench_slurm), test_fuzz.py."""
import importlib
import inspect
from pathlib import Path

import pytest

BENCHMARKS = sorted(p.stem for p in (Path(__file__).resolve().parents[1] / "benchmarks").glob("*.py")
                    if p.stem != "__init__")


@pytest.mark.parametrize("name", BENCHMARKS)
def test_a_benchmark_imports_and_parses_its_command_line(name, capsys):
    module = importlib.import_module(f"benchmarks.{name}")
    main = getattr(module, "main", None)
    if main is None or "argv" not in inspect.signature(main).parameters:
        return  # a library of the others (machine, faults, ...) or a main without a command line
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_the_calibration_size_benchmark_overrides_a_key_and_refuses_an_unknown_one():
    """``bench_calibration_size.py --set``: a dotted key's value is read as YAML; a key the config
    does not have is refused with its name, before any LIGGGHTS starts."""
    from benchmarks.bench_calibration_size import override

    config = {"material": {"rolling_friction": 0.1, "sliding_friction_particle": 0.5}}
    assert override(config, ["material.rolling_friction=0.556"])["material"] == {
        "rolling_friction": 0.556, "sliding_friction_particle": 0.5}
    with pytest.raises(SystemExit, match="material.rolling'"):
        override(config, ["material.rolling=0.3"])
    with pytest.raises(SystemExit, match="dotted.key=value"):
        override(config, ["material.rolling_friction"])
