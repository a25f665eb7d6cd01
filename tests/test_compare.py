"""`fleet-sim compare`: paired differences with common random numbers, the sequential looks,
KN selection, resume after a kill, bad compare sections, and the comparison report in a
headless browser."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from fleet_sim.analysis.paired import (
    Correction,
    kn_h2,
    kn_select,
    looks,
    paired_difference,
    verdict,
)
from fleet_sim.cli import main
from fleet_sim.config.experiment import load_experiment
from fleet_sim.study.compare import compare
from fleet_sim.study.pools import LocalPool
from tests.conftest import in_browser, write_yaml

ROOT = Path(__file__).resolve().parents[1]
TINY = str(ROOT / "experiments" / "tiny_loop.yaml")
SHORT = {"duration_h": 0.75, "warmup_h": 0.1, "demand.rate_per_hour": 40}


def tiny_compare(tmp_path: Path, name: str = "cmp", **fields: Any) -> Path:
    data: dict[str, Any] = {
        "name": name, "scenario": TINY, "overrides": dict(SHORT), "master_seed": 5,
        "variants": {
            "noop": {"description": "A speed limit set to the one it has",
                     "layout_changes": [{"speed_limit": {"chain": ["SW", "S1", "P"],
                                                         "speed_mps": 1.0}}]},
            "slow_drop": {"description": "Slower drop-off",
                          "layout_changes": [{"station_handling": {
                              "id": "DROP", "handling": {"dist": "fixed", "mean_s": 90}}}]}},
        "compare": {"kpis": ["lead_time_mean_s", "throughput_per_hour"],
                    "precision": {"throughput_per_hour": 50},
                    "min_replications": 3, "max_replications": 6}}
    data.update(fields)
    return write_yaml(tmp_path / f"{name}.yaml", data)


# ---- statistics on synthetic data -------------------------------------------------------------


def test_paired_difference_by_hand() -> None:
    base = [10.0, 12.0, 11.0, 13.0]
    var = [11.0, 14.0, 12.0, 15.0]  # differences 1, 2, 1, 2: mean 1.5, sd 0.57735
    d = paired_difference(base, var, 0.95)
    assert (d.pairs, d.mean, d.baseline_mean, d.variant_mean) == (4, 1.5, 11.5, 13.0)
    assert d.half_width == pytest.approx(3.182446 * 0.5773503 / 2, rel=1e-6)
    assert verdict(d, "lower", None) == "worse" and verdict(d, "higher", None) == "better"
    assert verdict(d, None, None) == "higher"
    # a NaN on either side drops the pair
    assert paired_difference([1.0, math.nan, 3.0], [2.0, 5.0, math.nan], 0.95).pairs == 1


def test_verdicts_precision_and_zero_width() -> None:
    same = paired_difference([5.0, 6.0, 7.0], [5.0, 6.0, 7.0], 0.99)
    assert same.mean == 0.0 and same.half_width == 0.0
    assert verdict(same, "lower", None) == "no_difference"  # every pair equal: decided
    noisy = paired_difference([1.0, 2.0, 3.0, 4.0], [1.5, 1.5, 3.5, 3.5], 0.95)
    assert verdict(noisy, "lower", None) == "undecided"
    assert verdict(noisy, "lower", noisy.half_width) == "no_difference"
    assert verdict(noisy, "lower", noisy.half_width * 0.99) == "undecided"


def test_bonferroni_over_comparisons_and_looks() -> None:
    assert looks(5, 20) == [5, 10, 20] and looks(3, 3) == [3] and looks(2, 12) == [2, 4, 8, 12]
    c = Correction(0.95, comparisons=8, looks=3)
    assert c.alpha_each == pytest.approx(0.05 / 24) and c.level == pytest.approx(1 - 0.05 / 24)


def _any_false_verdict(diffs: np.ndarray, level: float) -> np.ndarray:
    """Per simulated study (axis 0) of null differences (comparisons x replications), whether
    any interval at any look of looks(5, 20) excluded zero (vectorised paired_difference)."""
    from scipy.special import stdtrit

    wrong = np.zeros(diffs.shape[0], dtype=bool)
    for n in looks(5, 20):
        d = diffs[:, :, :n]
        half = stdtrit(n - 1, 0.5 + level / 2) * d.std(axis=2, ddof=1) / math.sqrt(n)
        wrong |= (np.abs(d.mean(axis=2)) > half).any(axis=1)
    return wrong


def test_sequential_intervals_hold_their_joint_coverage() -> None:
    """No true difference, 4 comparisons, 3 looks, stop at the first interval off zero: with
    the correction the share of studies with a false verdict stays under 5 %; without it
    (95 % at every look) it is far above."""
    rng = np.random.default_rng(7)
    diffs = rng.normal(0.0, 1.0, (4000, 4, 20))
    level = Correction(0.95, comparisons=4, looks=3).level
    d = paired_difference(np.zeros(5), diffs[0, 0, :5], level)  # the same interval
    half = __import__("scipy.special").special.stdtrit(4, 0.5 + level / 2) * \
        diffs[0, 0, :5].std(ddof=1) / math.sqrt(5)
    assert d.half_width == pytest.approx(half)
    assert _any_false_verdict(diffs, level).mean() <= 0.05
    assert _any_false_verdict(diffs, 0.95).mean() > 0.2


def test_kn_constants_by_hand() -> None:
    # k = 2, n0 = 10, PCS 0.95: eta = ((2 * 0.05) ** (-2 / 9) - 1) / 2
    eta = ((0.1) ** (-2 / 9) - 1) / 2
    assert kn_h2(2, 10, 0.95) == pytest.approx(2 * eta * 9)


@pytest.mark.parametrize("common", [0.0, 3.0])
def test_kn_selects_the_best_at_least_as_often_as_promised(common: float) -> None:
    """Slippage configuration (the best exactly one indifference zone ahead), normal data, with
    and without a large common component (common random numbers): PCS >= 0.9."""
    rng = np.random.default_rng(2024)
    k, delta, pcs, n0 = 4, 1.0, 0.9, 8
    trials, correct, used = 300, 0, []
    for _ in range(trials):
        shared = rng.normal(0.0, common, 400)
        x = rng.normal(0.0, 2.0, (k, 400)) + shared
        x[2] += delta  # system 2 is best
        result = kn_select(x, delta, pcs, n0)
        assert result.selected is not None
        correct += result.selected == 2
        used.append(result.replications)
    assert correct / trials >= pcs
    assert max(used) < 400


def test_kn_minimises_and_stops_at_a_cap_without_promise() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(0.0, 1.0, (3, 200))
    x[0] -= 3.0
    assert kn_select(x, 0.5, 0.95, 5, maximise=False).selected == 0
    # two systems alike within the noise, cut off at 10 replications: no promise
    close = rng.normal(0.0, 1.0, (2, 10))
    capped = kn_select(close, 0.1, 0.95, 5, final=True)
    assert capped.selected is None and not capped.guaranteed
    assert capped.best_at_cap == int(np.argmax(close.mean(axis=1)))
    # identical results (a variant that changes nothing): one system, the first stands for it
    twins = kn_select(np.vstack([x[1], x[1], x[2] - 5]), 0.5, 0.95, 5)
    assert twins.selected == 0 and twins.identical == (1,) and 2 in twins.eliminated_at


# ---- real runs ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("compare")
    out = tmp / "out"
    code = main(["compare", str(tiny_compare(tmp)), "--out", str(out), "--workers", "2",
                 "--quiet"])
    assert code == 0
    return out


def _kpis(run: Path) -> dict[str, Any]:
    figures = json.loads((run / "kpis.json").read_text())
    figures.pop("wall_s")
    return figures


def test_noop_variant_gives_identical_runs_and_exactly_zero(compared: Path) -> None:
    runs = compared / "runs"
    for r in range(3):
        base, noop = runs / f"r{r:02d}", runs / f"v=noop__r{r:02d}"
        for table in ("events.parquet", "orders.parquet", "node_waits.parquet"):
            assert (base / table).read_bytes() == (noop / table).read_bytes()
        assert _kpis(base) == _kpis(noop)
    result = json.loads((compared / "compare.json").read_text())
    noop = [c for c in result["comparisons"] if c["variant"] == "noop"]
    assert {c["kpi"] for c in noop} == {"lead_time_mean_s", "throughput_per_hour"}
    assert all(c["difference"] == 0 and c["ci_low"] == 0 and c["ci_high"] == 0
               and c["verdict"] == "no_difference" for c in noop)


def test_slower_handling_is_worse_with_an_interval_clear_of_zero(compared: Path) -> None:
    result = json.loads((compared / "compare.json").read_text())
    slow = {c["kpi"]: c for c in result["comparisons"] if c["variant"] == "slow_drop"}
    lead = slow["lead_time_mean_s"]
    assert lead["verdict"] == "worse" and lead["ci_low"] > 0
    assert lead["variant_mean"] > lead["baseline_mean"]
    assert "worse" in lead["words"]
    # every comparison decided (the throughput's by its precision) before the limit
    assert result["stopped"] == "decided" and result["looks_done"] in ([3], [3, 6])
    assert result["correction"]["comparisons"] == 4 and result["correction"]["looks"] == 2
    n = result["replications"]
    summary = pd.read_parquet(compared / "summary.parquet")
    assert sorted(summary["variant"].unique()) == ["baseline", "noop", "slow_drop"]
    assert len(summary) == 3 * n and (summary["status"] == "ok").all()
    # the baseline's runs are a sweep's: the same run ids
    assert set(summary[summary["variant"] == "baseline"]["run_id"]) == \
        {f"r{r:02d}" for r in range(n)}


def test_on_a_dask_cluster_the_same_comparison(compared: Path, tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    import yaml

    file = yaml.safe_load((compared / "experiment.resolved.yaml").read_text())["experiment_file"]
    outcome = compare(load_experiment(file), tmp_path / "dask", workers=2, scheduler="local",
                      quiet=True)
    local = json.loads((compared / "compare.json").read_text())
    assert [c.as_dict() for c in outcome.comparisons] == local["comparisons"]
    assert (tmp_path / "dask" / "runs" / "r01" / "events.parquet").read_bytes() == \
        (compared / "runs" / "r01" / "events.parquet").read_bytes()


def test_selection_picks_the_known_best_in_the_stated_share(tmp_path: Path) -> None:
    """Variants that differ only in drop-off handling (20 s, 45 s, 70 s): the fastest has the
    lowest mean lead time by far more than the indifference zone; KN at PCS 0.9 picks it in
    at least 9 of 10 experiments with different master seeds."""
    variants = {f"drop_{s}s": {"layout_changes": [{"station_handling": {
        "id": "DROP", "handling": {"dist": "fixed", "mean_s": s}}}]} for s in (45, 70)}
    picked = []
    with LocalPool(2) as pool:
        for seed in range(10):
            path = tiny_compare(tmp_path, f"sel{seed}", master_seed=100 + seed,
                                overrides={**SHORT, "duration_h": 0.4},
                                variants=variants, compare={
                                    "kpis": ["lead_time_mean_s"], "min_replications": 3,
                                    "max_replications": 6, "objective": {
                                        "kpi": "lead_time_mean_s", "direction": "min",
                                        "indifference_zone": 5,
                                        "probability_correct_selection": 0.9}})
            outcome = compare(load_experiment(path), tmp_path / f"out{seed}", workers=2,
                              quiet=True, pool=pool)
            (selection,) = outcome.selections
            picked.append(selection.selected)
    assert picked.count("baseline") >= 9, picked  # the baseline drops off in 30 s


def test_compare_killed_midway_resumes_and_recomputes_nothing(tmp_path: Path) -> None:
    path = tiny_compare(tmp_path, "long", overrides={**SHORT, "duration_h": 6},
                        compare={"kpis": ["lead_time_mean_s"], "min_replications": 4,
                                 "max_replications": 4})
    out = tmp_path / "out"
    command = [sys.executable, "-m", "fleet_sim.cli", "compare", str(path), "--out", str(out),
               "--workers", "2", "--quiet"]
    proc = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 120
    try:
        while len(list(out.glob("runs/*/kpis.json"))) < 2:
            assert proc.poll() is None, "the comparison ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    finished = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.glob("runs/*/kpis.json")}
    assert 2 <= len(finished) < 12
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert f"{12 - len(finished)} runs made, {len(finished)} already finished" in result.stdout
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in finished} == finished
    again = subprocess.run([c for c in command if c != "--quiet"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=300)
    assert "0 runs made, 12 already finished" in again.stdout
    assert "all 12 planned runs are in the summary (12 finished)" in again.stderr


@pytest.mark.parametrize(("compare_section", "variants", "element"), [
    ({"kpis": ["lead_time_p95"]}, None, "compare.kpis[0]"),
    ({"precision": {"blocked_time_pct": 5}}, None, "compare.precision.blocked_time_pct"),
    ({"kpis": ["throughput_per_hour"], "precision": {"lead_time_p95_s": 5}}, None,
     "compare.precision.lead_time_p95_s"),
    ({"min_replications": 6, "max_replications": 4}, None, "compare.max_replications"),
    ({"min_replications": 1}, None, "compare.min_replications"),
    ({"confidence": 1.5}, None, "compare.confidence"),
    ({"objective": {"kpi": "lead_time_p95", "direction": "min", "indifference_zone": 5}},
     None, "compare.objective.kpi"),
    ({"objective": {"kpi": "lead_time_p95_s", "direction": "down",
                    "indifference_zone": 5}}, None, "compare.objective.direction"),
    ({"objective": {"kpi": "lead_time_p95_s", "direction": "min",
                    "indifference_zone": 0}}, None, "compare.objective.indifference_zone"),
    ({"objective": {"kpi": "lead_time_p95_s", "direction": "min", "indifference_zone": 5,
                    "probability_correct_selection": 0.5}}, None,
     "compare.objective.probability_correct_selection"),
    ({"replications": 3}, None, "compare.replications"),
    ({}, {}, "variants"),
])
def test_bad_compare_sections_are_refused_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], compare_section: dict[str, Any],
        variants: dict[str, Any] | None, element: str) -> None:
    fields: dict[str, Any] = {"compare": compare_section}
    if variants is not None:
        fields["variants"] = variants
    path = tiny_compare(tmp_path, **fields)
    code = main(["compare", str(path), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert str(path) in err and element in err, err
    assert not (tmp_path / "out" / "runs").exists()


def test_max_replications_below_the_first_look_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["compare", str(tiny_compare(tmp_path)), "--max-replications", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "--max-replications" in err and "min_replications (3)" in err
    code = main(["compare", str(tiny_compare(tmp_path)), "--max-replications", "5000"])
    err = capsys.readouterr().err
    assert code == 2 and "at most 10000 runs in one comparison (15000 = 3 variants" in err


# ---- the report --------------------------------------------------------------------------------

CHECK = """<script>
window.addEventListener('load', () => {
  const pre = document.createElement('pre');
  pre.id = 'img-check';
  pre.textContent = JSON.stringify({
    images: Array.from(document.images).map(i => ({key: i.dataset.figure,
      ok: i.complete && i.naturalWidth > 0, w: i.naturalWidth})),
    answer: Array.from(document.querySelectorAll('#answer p.answer')).map(p => p.textContent),
    title: document.title});
  document.body.appendChild(pre);
});
</script></body>"""


def test_comparison_report_in_a_headless_browser(compared: Path, tmp_path: Path) -> None:
    assert main(["report", str(compared)]) == 0
    assert (compared / "report.pdf").read_bytes()[:5] == b"%PDF-"
    html = (compared / "report.html").read_text(encoding="utf-8")
    check, _ = in_browser(html, tmp_path, CHECK)
    assert check["title"] == "What-if comparison: cmp"
    answer = check["answer"]
    assert answer[0].startswith("A speed limit set to the one it has changes nothing we can "
                                "detect: mean lead time +0 s (+0 to +0 s)")
    assert answer[1].startswith("Slower drop-off raises mean lead time by ")
    keys = {i["key"] for i in check["images"]}
    assert {"forest", "side_by_side", "layout_slow_drop", "waits_slow_drop"} <= keys
    assert all(i["ok"] and i["w"] > 200 for i in check["images"]), check["images"]
    # KPI names and units from the catalogue, never raw keys, in the tables
    assert "mean lead time [s]" in html and ">lead_time_mean_s<" not in html


def test_a_variant_undecided_at_the_limit_is_not_said_to_change_nothing() -> None:
    from fleet_sim.report.compare_report import variant_sentence

    none = {"kpi": "throughput_per_hour", "verdict": "none", "difference": 0.01,
            "ci_low": -0.2, "ci_high": 0.2}
    undecided = {"kpi": "lead_time_p95_s", "verdict": "undecided", "difference": -31.6,
                 "ci_low": -112.0, "ci_high": 48.4}
    text = variant_sentence("Opportunity charging", [none, undecided])
    assert "nothing we can detect" not in text
    assert text.startswith("Opportunity charging is not decided at the replication limit on "
                           "p95 lead time -31.6 s (-112 to +48.4 s)")
    assert "no difference we can detect in throughput" in text
    assert variant_sentence("A fifth charger", [none]).startswith(
        "A fifth charger changes nothing we can detect: throughput")
