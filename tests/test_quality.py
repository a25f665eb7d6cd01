"""ruff, mypy and the import contract (import-linter) run as part of the tests; and no module or
function is too long to hold in mind."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from .conftest import ROOT


def test_ruff() -> None:
    result = subprocess.run([sys.executable, "-m", "ruff", "check", "."], cwd=ROOT,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_mypy() -> None:
    result = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True,
                            text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_import_contract() -> None:
    """The direction of imports in pyproject.toml's [tool.importlinter] holds."""
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


MODULE_LINES = 800
FUNCTION_LINES = 80
"""Rooms a newcomer can hold in mind: no module, and no function, longer than this."""


def test_no_module_or_function_is_too_long_to_hold_in_mind() -> None:
    too_long = []
    for package in ("fleet_sim", "agv_model", "userfiles"):
        for path in sorted((ROOT / package).rglob("*.py")):
            text = path.read_text("utf-8")
            name = str(path.relative_to(ROOT))
            if text.count("\n") > MODULE_LINES:
                too_long.append(f"{name}: {text.count(chr(10))} lines")
            for node in ast.walk(ast.parse(text)):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    lines = (node.end_lineno or node.lineno) - node.lineno + 1
                    if lines > FUNCTION_LINES:
                        too_long.append(f"{name}: {node.name} is {lines} lines")
    assert too_long == []
