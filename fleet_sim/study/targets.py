"""Checks of an experiment's targets that need no simulation, made before any run starts.

A target names a KPI; the names come from the static catalogue of fleet_sim.analysis.kpis (the
per-code counts flattened as in the sweep summary, `errors_by_code.E_101`), so a misspelt KPI
is an input error before hours of simulation, without running anything to learn the names.
"""

from __future__ import annotations

import difflib

from fleet_sim.analysis.kpis import is_kpi_name, kpi_names
from fleet_sim.config.experiment import Experiment
from fleet_sim.errors import InputError


def check_targets_known(experiment: Experiment) -> None:
    """Raise InputError naming the first target whose KPI no run reports."""
    known = sorted(kpi_names())
    for i, target in enumerate(experiment.spec.targets):
        if target.kpi in known or is_kpi_name(target.kpi):  # per-type: by_type.<type>.<kpi>
            continue
        closest = difflib.get_close_matches(target.kpi, known, n=1)
        hint = f" (closest: {closest[0]})" if closest else ""
        raise InputError(str(experiment.file), f"targets[{i}].kpi", target.kpi,
                         f"one of the KPIs{hint}: " + ", ".join(known))
