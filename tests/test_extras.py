"""The heavy parts are extras (pyproject's optional-dependencies): a command that needs one that
is not installed ends in one line naming the extra, exit status 2, before any work.

"Not installed" is made real in a subprocess: the module is set to None in sys.modules before
fleet_sim is imported, so importing or finding it fails exactly as if it were absent (PATH is
emptied too where SUMO's netconvert could be found there).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml

from fleet_sim.errors import EXTRAS, MissingExtra, optional_import, require_extra
from tests.conftest import LAYOUTS, ROOT, write_yaml

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
OPTIONAL_MODULES = ("libsumo", "sumo", "sumolib", "traci", "dask", "distributed", "openpyxl")


def fleet_sim_without(modules: tuple[str, ...], *args: str, cwd: Path = ROOT,
                      empty_path: bool = False, timeout_s: float = 120.0
                      ) -> subprocess.CompletedProcess[str]:
    """`fleet-sim ARGS` in a fresh Python in which `modules` cannot be imported."""
    code = ("import sys\n"
            f"for name in {modules!r}:\n"
            "    sys.modules[name] = None\n"
            "from fleet_sim.cli import main\n"
            f"sys.exit(main({list(args)!r}))\n")
    env = {"PATH": "/nonexistent"} if empty_path else None
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout_s, check=False, env=env)


def one_error_line(result: subprocess.CompletedProcess[str]) -> str:
    assert result.returncode == 2, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]


def sumo_scenario(tmp_path: Path) -> Path:
    data = yaml.safe_load((ROOT / "experiments" / "tiny_loop.yaml").read_text(encoding="utf-8"))
    data |= {"layout": str(LAYOUTS / "tiny_loop.yaml"), "motion": "sumo", "duration_h": 0.1,
             "warmup_h": 0.0}
    return write_yaml(tmp_path / "sumo.yaml", data)


def test_a_sumo_run_without_libsumo_is_one_line(tmp_path: Path) -> None:
    out = tmp_path / "out"
    line = one_error_line(fleet_sim_without(("libsumo",), "run", str(sumo_scenario(tmp_path)),
                                            "--out", str(out)))
    assert line == ("fleet-sim: error: motion: sumo needs the SUMO extra (libsumo is not "
                    "installed): pip install 'fleet-sim[sumo]'")
    assert not (out / "kpis.json").exists()


def test_a_sumo_run_without_netconvert_anywhere_is_one_line(tmp_path: Path) -> None:
    line = one_error_line(fleet_sim_without(("sumo",), "run", str(sumo_scenario(tmp_path)),
                                            "--out", str(tmp_path / "out"), empty_path=True))
    assert line == ("fleet-sim: error: motion: sumo needs the SUMO extra (eclipse-sumo is not "
                    "installed and netconvert is not on PATH): pip install 'fleet-sim[sumo]'")


def test_a_sumo_network_export_without_sumo_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "net"
    line = one_error_line(fleet_sim_without(
        ("sumo",), "layout", str(LAYOUTS / "tiny_loop.yaml"), "--png", str(tmp_path / "t.png"),
        "--sumo", str(out), empty_path=True))
    assert line == ("fleet-sim: error: layout --sumo needs the SUMO extra (eclipse-sumo is not "
                    "installed and netconvert is not on PATH): pip install 'fleet-sim[sumo]'")
    assert not out.exists() or not any(out.iterdir())


def test_a_crosscheck_without_libsumo_runs_nothing(tmp_path: Path) -> None:
    result = fleet_sim_without(("libsumo",), "crosscheck", str(sumo_scenario(tmp_path)))
    line = one_error_line(result)
    assert line == ("fleet-sim: error: crosscheck: motion: sumo needs the SUMO extra (libsumo "
                    "is not installed): pip install 'fleet-sim[sumo]'")
    assert "closed_form" not in result.stdout  # no run was made before the check


def test_a_sweep_of_a_sumo_experiment_without_libsumo_runs_nothing(tmp_path: Path) -> None:
    experiment = write_yaml(tmp_path / "e.yaml", {
        "name": "e", "scenario": str(sumo_scenario(tmp_path)), "factors": {"fleet.size": [1]},
        "replications": 1})
    out = tmp_path / "sweep"
    line = one_error_line(fleet_sim_without(("libsumo",), "sweep", str(experiment),
                                            "--out", str(out), "--quiet"))
    assert line == (f"fleet-sim: error: {experiment}: motion: sumo needs the SUMO extra "
                    "(libsumo is not installed): pip install 'fleet-sim[sumo]'")
    assert not (out / "runs").exists()


@pytest.mark.parametrize("command", ["sweep", "size"])
def test_a_dask_scheduler_without_the_cluster_extra_is_one_line(tmp_path: Path,
                                                                command: str) -> None:
    out = tmp_path / "out"
    line = one_error_line(fleet_sim_without(
        ("dask", "distributed", "dask.distributed"), command,
        str(ROOT / "experiments" / "tiny_loop_sizing.yaml"), "--out", str(out),
        "--scheduler", "local", "--quiet"))
    assert line == ("fleet-sim: error: --scheduler needs the cluster (Dask) extra "
                    "(dask.distributed is not installed): pip install 'fleet-sim[cluster]'")
    assert not (out / "runs").exists()


def test_a_workbook_without_openpyxl_is_one_line_and_csv_still_works(tmp_path: Path) -> None:
    run = tmp_path / "run"
    scenario = write_yaml(tmp_path / "s.yaml", {
        **yaml.safe_load((ROOT / "experiments" / "tiny_loop.yaml").read_text(encoding="utf-8")),
        "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.2, "warmup_h": 0.0})
    assert fleet_sim_without((), "run", str(scenario), "--out", str(run)).returncode == 0
    line = one_error_line(fleet_sim_without(("openpyxl",), "export", str(run), "--xlsx"))
    assert line == ("fleet-sim: error: export --xlsx needs the export extra (openpyxl is not "
                    "installed): pip install 'fleet-sim[export]'")
    assert not (run / "export.xlsx").exists()
    csv = fleet_sim_without(("openpyxl",), "export", str(run), "--csv")
    assert csv.returncode == 0, csv.stderr
    assert (run / "export" / "orders.csv").stat().st_size > 0


def test_emulate_runs_without_pyserial() -> None:
    """pyserial is a dev dependency: the emulator itself only needs a pty."""
    code = ("import sys\n"
            "sys.modules['serial'] = None\n"
            "from fleet_sim.cli import main\n"
            "sys.exit(main(['emulate', 'carriro']))\n")
    with subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            first = process.stdout.readline()
        finally:
            process.terminate()
        _, err = process.communicate(timeout=30)
    assert first.startswith("/dev/pts/"), err
    assert process.returncode == 0, err


def test_the_helper_names_the_extra_and_the_module() -> None:
    with pytest.raises(MissingExtra, match=r"^export --xlsx needs the export extra \(no_such_"
                                           r"module_x is not installed\): pip install "
                                           r"'fleet-sim\[export\]'$"):
        optional_import("no_such_module_x", "export", "export --xlsx")
    with pytest.raises(MissingExtra, match=r"no_such_module_x\.y is not installed"):
        require_extra("no_such_module_x.y", "sumo", "motion: sumo")
    assert optional_import("json", "export", "x").dumps([1]) == "[1]"
    require_extra("json", "export", "x")


def test_every_extra_is_in_pyproject_and_the_core_has_none_of_them() -> None:
    project = PYPROJECT["project"]
    extras = project["optional-dependencies"]
    assert set(EXTRAS) == set(extras) - {"dev"}
    core = " ".join(project["dependencies"]).lower()
    for name in ("eclipse-sumo", "libsumo", "dask", "openpyxl", "pyserial"):
        assert name not in core, name
    assert any(r.startswith("pyserial") for r in extras["dev"])
    assert "fleet-sim[sumo,cluster,export]" in extras["dev"]  # the suite tests every extra


def _imports(path: Path) -> list[str]:
    names: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def test_optional_modules_are_imported_only_through_the_helper() -> None:
    """No `import libsumo` / `import openpyxl` / `import serial` in the packages: an optional
    module goes through fleet_sim.errors.optional_import (or require_extra), and pyserial is
    not used at run time at all."""
    found = [(str(path.relative_to(ROOT)), name)
             for package in ("fleet_sim", "agv_model", "userfiles")
             for path in (ROOT / package).rglob("*.py")
             for name in _imports(path)
             if name.partition(".")[0] in (*OPTIONAL_MODULES, "serial")]
    assert found == []
