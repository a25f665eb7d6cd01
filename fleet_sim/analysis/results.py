"""To go: only fleet_sim.config.experiment.known_kpis (removed on the `config` branch) still
imports `write_run` from here. KPIs are in fleet_sim.analysis.kpis, tables and the run
directory in fleet_sim.analysis.tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fleet_sim.analysis import kpis, tables
from fleet_sim.sim.engine import RunOutput


def write_run(run: RunOutput, out_dir: Path) -> dict[str, Any]:
    """Write the run directory; returns the KPIs."""
    figures = kpis.run_kpis(run)
    tables.write_run(run, out_dir, figures)
    return figures
