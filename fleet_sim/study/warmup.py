"""The warm-up of an experiment's runs, estimated from the data (experiment `warmup.method:
mser5`) rather than fixed.

Before any run of the design starts, pilot runs of the base scenario are made without warm-up
(`warmup.pilot_replications` of them, with the design's replication seeds, for each combination
of the other factors' levels, at the largest fleet the study looks at: a fleet that keeps up,
whose start-up transient ends). MSER-5 (fleet_sim.analysis.stats.mser5_truncation) on each
pilot's lead times, in order of creation, says how many of the first orders to delete; the
warm-up is the creation time of the first order kept, rounded up to 0.05 h, and the longest
over the pilots becomes `warmup_h` of every run (an override, so the run folders and their
resolved configs record it, and a sweep and a sizing search of one experiment share it).

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from fleet_sim.analysis.stats import mser5_truncation
from fleet_sim.config.experiment import Experiment, RunSpec
from fleet_sim.study.pools import DaskPool, LocalPool
from fleet_sim.study.progress import Progress
from fleet_sim.study.runner import execute
from fleet_sim.study.study_folder import SweepError

ROUND_H = 0.05
WARMUP_FILE = "warmup.json"


def pilot_groups(experiment: Experiment) -> list[dict[str, Any]]:
    """The combinations of the other factors' levels (a Latin hypercube: the base scenario)."""
    if experiment.spec.design != "full_factorial":
        return [{}]
    seen: list[dict[str, Any]] = []
    for point in experiment.points:
        fixed = {k: v for k, v in point if k != experiment.fleet_factor}
        if fixed not in seen:
            seen.append(fixed)
    return seen or [{}]


def largest_fleet(experiment: Experiment) -> int | None:
    """The largest fleet the study looks at: sizing.max_agvs, else the largest fleet.size
    level (a mixed fleet sized by one type: that type's count); None when the fleet is not a
    factor."""
    levels = [v for v in (experiment.spec.factors.get(experiment.fleet_factor) or [])
              if isinstance(v, int)]
    if experiment.spec.sizing.max_agvs is not None:
        return max([experiment.spec.sizing.max_agvs, *levels])
    return max(levels) if levels else None


def pilot_specs(experiment: Experiment, groups: Sequence[dict[str, Any]],
                fleet: int | None) -> list[RunSpec]:
    """The pilot runs: per group, `pilot_replications` runs without warm-up at `fleet` AGVs
    (None: the scenario's own fleet)."""
    specs = []
    for fixed in groups:
        factors = dict(fixed) if fleet is None else {**fixed, experiment.fleet_factor: fleet}
        for r in range(experiment.spec.warmup.pilot_replications):
            spec = experiment.run(factors, r)
            specs.append(dataclasses.replace(
                spec, run_id=f"pilot__{spec.run_id}",
                overrides=(*spec.overrides, ("warmup_h", 0.0))))
    return specs


def lead_time_warmup_s(orders: pd.DataFrame) -> float:
    """MSER-5 on the lead times of the delivered orders, in order of creation: the creation
    time of the first order kept (0 when nothing is deleted)."""
    done = orders.dropna(subset=["delivered_s"]).sort_values("created_s", kind="stable")
    lead = (done["delivered_s"] - done["created_s"]).to_numpy(dtype=float)
    cut = mser5_truncation(lead)
    if cut == 0:
        return 0.0
    return float(done["created_s"].iloc[cut])


def settle_warmup(experiment: Experiment, out_dir: Path, groups: Sequence[dict[str, Any]],
                  fleet: int | None, pool: LocalPool | DaskPool,
                  progress: Progress) -> Experiment:
    """The experiment with its warm-up settled: unchanged for `fixed`, else with `warmup_h`
    estimated by MSER-5 from pilot runs (made now, or read back from warmup.json)."""
    if experiment.spec.warmup.method != "mser5":
        return experiment
    specs = pilot_specs(experiment, groups, fleet)
    record_file = out_dir / WARMUP_FILE
    wanted = sorted(s.run_id for s in specs)
    if record_file.exists():
        record = json.loads(record_file.read_text(encoding="utf-8"))
        if sorted(record.get("pilots", {})) == wanted:
            progress.note(f"warm-up {record['warmup_h']:g} h (MSER-5, from {WARMUP_FILE})")
            return experiment.with_overrides({"warmup_h": record["warmup_h"]})
    outcome = execute(specs, out_dir / "pilot", quiet=True, pool=pool)
    if outcome.failed:
        failed = ", ".join(f"{r.run_id}: {r.error}" for r in outcome.failed)
        raise SweepError(f"pilot runs for the MSER-5 warm-up failed: {failed}")
    pilots: dict[str, float] = {}
    for spec in specs:
        orders = pd.read_parquet(out_dir / "pilot" / "runs" / spec.run_id / "orders.parquet",
                                 columns=["created_s", "delivered_s"])
        pilots[spec.run_id] = lead_time_warmup_s(orders) / 3600.0
    duration_h = min(experiment.scenario(dict(fixed)).duration_h for fixed in groups or [{}])
    longest = max(pilots.values(), default=0.0)
    warmup_h = round(min(math.ceil(longest / ROUND_H - 1e-9) * ROUND_H,
                         duration_h / 2), 6)
    record_file.write_text(json.dumps({
        "method": "mser5", "warmup_h": warmup_h, "fleet": fleet,
        "pilots": {k: round(v, 6) for k, v in sorted(pilots.items())},
        "note": "MSER-5 on each pilot's lead times in order of creation; the longest, rounded "
                f"up to {ROUND_H} h, is every run's warmup_h"}, indent=2) + "\n",
        encoding="utf-8")
    progress.note(f"warm-up {warmup_h:g} h (MSER-5 over {len(specs)} pilot runs at "
                  f"{fleet if fleet is not None else 'the scenario fleet'} AGVs: "
                  + ", ".join(f"{v:.2f}" for v in pilots.values()) + " h)")
    return experiment.with_overrides({"warmup_h": warmup_h})
