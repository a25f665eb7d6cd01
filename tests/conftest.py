"""Shared fixtures: paths to bundled files and small scenario builders."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from fleet_sim.confparse import build
from fleet_sim.layout import Layout, load_layout
from fleet_sim.scenario import Scenario

ROOT = Path(__file__).resolve().parent.parent
LAYOUTS = ROOT / "layouts"
DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def tiny_layout() -> Layout:
    return load_layout(LAYOUTS / "tiny_loop.yaml")


@pytest.fixture(scope="session")
def warehouse_layout() -> Layout:
    return load_layout(LAYOUTS / "warehouse.yaml")


def make_scenario(layout_file: str = "tiny_loop.yaml", base_dir: Path = LAYOUTS,
                  **fields: Any) -> Scenario:
    """A scenario from keyword fields, as if read from a file in `base_dir`."""
    data: dict[str, Any] = {"layout": layout_file, **fields, "_base_dir": str(base_dir)}
    return build(Scenario, data, "<test scenario>")


def write_yaml(path: Path, data: Any) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path
