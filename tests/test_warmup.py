"""The warm-up estimated from the data (fleet_sim.study.warmup): MSER-5 on pilot runs' lead
times becomes every run's warmup_h, recorded and read back on a rerun."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import yaml

from fleet_sim.config.experiment import load_experiment
from fleet_sim.errors import InputError
from fleet_sim.study.sizing import size_fleet
from fleet_sim.study.warmup import lead_time_warmup_s

from .conftest import ROOT, write_yaml


def test_the_warmup_ends_where_mser5_cuts_the_lead_times() -> None:
    """Orders every 60 s; the first 20 wait long (a queue at the start), the rest 100 s: MSER-5
    deletes the first 20 (four batches), so the warm-up ends when order 20 was created."""
    created = [60.0 * i for i in range(200)]
    lead = [1000.0 - 40.0 * i if i < 20 else 100.0 for i in range(200)]
    orders = pd.DataFrame({"created_s": created,
                           "delivered_s": [c + w for c, w in zip(created, lead, strict=True)]})
    assert lead_time_warmup_s(orders) == 20 * 60.0
    steady = orders.assign(delivered_s=orders["created_s"] + 100.0)
    assert lead_time_warmup_s(steady) == 0.0


def mser_experiment(tmp_path: Path) -> Path:
    data = yaml.safe_load((ROOT / "experiments" / "tiny_loop_sizing.yaml").read_text())
    data["scenario"] = str(ROOT / "experiments" / "tiny_loop.yaml")
    data["overrides"] = {"duration_h": 3, "demand.rate_per_hour": 45}  # no warmup_h: estimated
    data["warmup"] = {"method": "mser5", "pilot_replications": 2}
    return write_yaml(tmp_path / "mser.yaml", data)


def test_sizing_with_the_mser5_warmup_records_and_reuses_it(tmp_path: Path) -> None:
    experiment = load_experiment(mser_experiment(tmp_path))
    out = tmp_path / "out"
    (result,) = size_fleet(experiment, out, workers=2, quiet=True)
    assert result.recommended == 2  # the known answer stands
    record = json.loads((out / "warmup.json").read_text())
    assert record["method"] == "mser5" and record["fleet"] == 4  # the largest fleet searched
    assert set(record["pilots"]) == {"pilot__fleet.size=4__r00", "pilot__fleet.size=4__r01"}
    warmup = record["warmup_h"]
    assert warmup == pytest.approx(round(warmup / 0.05) * 0.05)  # rounded up to 0.05 h
    assert warmup >= max(record["pilots"].values()) and 0 <= warmup <= 1.5
    for run in (out / "runs").iterdir():  # every run of the search uses it
        resolved = yaml.safe_load((run / "config.resolved.yaml").read_text())
        assert resolved["warmup_h"] == warmup
        assert json.loads((run / "kpis.json").read_text())["warmup_h"] == warmup
    pilots = {p.name for p in (out / "pilot" / "runs").iterdir()}
    assert pilots == set(record["pilots"])
    assert json.loads((out / "sizing.json").read_text())["warmup_h"] == warmup
    before = {p.name: p.stat().st_mtime_ns for p in (out / "pilot" / "runs").iterdir()}
    size_fleet(experiment, out, workers=2, quiet=True)  # again: read back, nothing rerun
    assert {p.name: p.stat().st_mtime_ns for p in (out / "pilot" / "runs").iterdir()} == before


def test_mser5_and_a_fixed_warmup_override_do_not_mix(tmp_path: Path) -> None:
    data = yaml.safe_load(mser_experiment(tmp_path).read_text())
    data["overrides"]["warmup_h"] = 0.5
    with pytest.raises(InputError, match=r"warmup.method: got 'mser5'; expected fixed when "
                                         r"warmup_h is an override or a factor"):
        load_experiment(write_yaml(tmp_path / "both.yaml", data))
