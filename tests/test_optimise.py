"""`fleet-sim optimise`: the procedure's guarantee on designs whose means are known, and the
command on real runs whose answer is known by hand (experiments/tiny_loop_design.yaml: one AGV
with fast handling beats a second AGV at 33 orders/h on the tiny loop)."""

from __future__ import annotations

import io
import json
import math
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from fleet_sim.analysis.feasibility import (
    Constraint,
    check,
    error_per_check,
    fb_h2,
)
from fleet_sim.config.experiment import load_experiment
from fleet_sim.study.cheapest import CheapestSearch, Structure, simulate
from fleet_sim.study.optimise import optimise
from fleet_sim.study.sizing import size_fleet

from .conftest import ROOT

DESIGN = ROOT / "experiments" / "tiny_loop_design.yaml"
REPETITIONS = 300


# ---- the check -----------------------------------------------------------------------------


def test_h2_solves_the_papers_equation() -> None:
    # 1/2 (1 + 2 eta)^(-(n0-1)/2) = beta with h^2 = 2 eta (n0 - 1)
    n0, beta = 10, 0.01
    h2 = fb_h2(n0, beta)
    eta = h2 / (2 * (n0 - 1))
    assert 0.5 * (1 + 2 * eta) ** (-(n0 - 1) / 2) == pytest.approx(beta)
    assert h2 == pytest.approx(9 * (0.02 ** (-2 / 9) - 1))
    assert error_per_check(0.95, 10, 2) == pytest.approx(0.05 / 60)  # designs x targets x 3


def test_the_check_decides_where_its_region_says() -> None:
    at_most = Constraint(bound=600, at_least=False, tolerance=20)
    h2 = fb_h2(5, 0.01)
    # no spread: the sign of the sum decides at the first look
    assert check(np.full((5, 1), 590.0), [at_most], 5, h2).decision == "meets"
    assert check(np.full((5, 1), 610.0), [at_most], 5, h2).decision == "fails"
    # fewer than n0 replications: nothing decided
    assert check(np.full((4, 1), 100.0), [at_most], 5, h2).decision == "undecided"
    # a replication without a value fails its constraint
    values = np.array([[500.0], [math.nan], [500], [500], [500]])
    assert check(values, [at_most], 5, h2).decision == "fails"
    # far below the bound with spread: met at the first look at a relaxed level
    rng = np.random.default_rng(1)
    far = 300 + 10 * rng.standard_normal((5, 1))
    verdict = check(far, [at_most], 5, h2)
    assert verdict.decision == "meets" and verdict.at == 5
    # on the bound: the region closes only at h^2 S^2 / eps^2 replications
    near = 600 + 30 * rng.standard_normal((400, 1))
    s2 = float(np.var(near[:5], ddof=1))
    verdict = check(near, [at_most], 5, h2)
    assert verdict.decision in ("meets", "fails")
    assert verdict.at <= math.ceil(h2 * s2 / 20**2) + 1
    # an at_least constraint is the same turned round
    at_least = Constraint(bound=98, at_least=True, tolerance=0.5)
    assert check(np.full((5, 1), 99.0), [at_least], 5, h2).decision == "meets"
    # two constraints: the design fails at the first that fails
    both = np.column_stack([np.full(5, 590.0), np.full(5, 90.0)])
    assert check(both, [at_most, at_least], 5, h2).decision == "fails"


# ---- the guarantee on known designs --------------------------------------------------------


def _correct(answer: int | None, means: np.ndarray, constraints: Sequence[Constraint],
             prices: Sequence[float]) -> bool:
    """The named design is not unacceptable (no mean on the bad side by the tolerance or
    more) and no cheaper design is desirable (every mean on the good side by it)."""
    def turned(i: int) -> list[float]:
        return [(-m if c.at_least else m) - (-c.bound if c.at_least else c.bound)
                for m, c in zip(means[i], constraints, strict=True)]

    def desirable(i: int) -> bool:
        return all(d <= -c.tolerance for d, c in zip(turned(i), constraints, strict=True))

    def unacceptable(i: int) -> bool:
        return any(d >= c.tolerance for d, c in zip(turned(i), constraints, strict=True))

    order = sorted(range(len(prices)), key=lambda i: (prices[i], i))
    if answer is None:
        return not any(desirable(i) for i in order)
    cheaper = order[:order.index(answer)]
    return not unacceptable(answer) and not any(desirable(i) for i in cheaper)


def _share_correct(means: np.ndarray, sds: Sequence[float], constraints: Sequence[Constraint],
                   common: float = 0.0, confidence: float = 0.95, n0: int = 10,
                   h2: float | None = None, structure: Structure | None = None,
                   repetitions: int = REPETITIONS, width: int = 2) -> tuple[float, float]:
    """Share of `repetitions` in which the procedure names a correct design, and the mean
    replications it used. Noise: normal, with a component common to every design of the same
    replication (common random numbers) of weight `common`."""
    k, s = means.shape
    prices = list(range(k))
    h2 = fb_h2(n0, error_per_check(confidence, k, s)) if h2 is None else h2
    right, used = 0, 0
    for rep in range(repetitions):
        rng = np.random.default_rng([rep, k, s])
        shared = rng.standard_normal((200, s))

        def sample(i: int, r: int, rng: np.random.Generator = rng,
                   shared: np.ndarray = shared) -> list[float]:
            own = rng.standard_normal(s)
            z = common * shared[r] + math.sqrt(1 - common**2) * own
            return list(means[i] + np.asarray(sds) * z)

        search = CheapestSearch(prices, constraints, n0, 200, h2, width, structure)
        answer = simulate(search, sample)
        right += _correct(answer, means, constraints, prices)
        used += sum(st.asked for st in search.states)
    return right / repetitions, used / repetitions


LEAD = Constraint(600, False, 20)
THROUGHPUT = Constraint(98, True, 0.5)
OPEN_ORDERS = Constraint(10, False, 1)
# Eight designs by price: the first three unacceptable exactly at the tolerance (the worst
# case), then acceptable ones inside the tolerance, then desirable ones exactly at it.
HARD = np.array([[620, 98.5], [580, 97.5], [620, 97.5], [610, 98.2], [595, 97.8],
                 [580, 98.5], [560, 99.0], [500, 99.9]], dtype=float)


@pytest.mark.parametrize("common", [0.0, 0.7], ids=["independent", "common-component"])
def test_the_procedure_names_a_correct_design_at_the_stated_rate(common: float) -> None:
    share, runs = _share_correct(HARD, [40, 1.0], [LEAD, THROUGHPUT], common=common)
    assert share >= 0.95
    assert runs < 8 * 200  # it stops: fewer runs than every design at the cap


def test_three_constraints_and_a_space_where_no_design_meets() -> None:
    means = np.array([[620, 97.5, 9], [590, 98.6, 12], [560, 99.0, 11.5], [580, 98.7, 11]])
    share, _ = _share_correct(means, [40, 1.0, 2.0], [LEAD, THROUGHPUT, OPEN_ORDERS],
                              common=0.5)
    assert share >= 0.95  # the right answer here is "none": every design misses by >= tol


def test_the_guarantee_holds_at_a_lower_confidence_too() -> None:
    share, _ = _share_correct(HARD, [40, 1.0], [LEAD, THROUGHPUT], confidence=0.8, n0=8)
    assert share >= 0.8


def test_a_region_too_narrow_breaks_the_guarantee_so_the_harness_can_tell() -> None:
    # the same harness with h^2 far below the procedure's: wrong answers well above 5 %
    share, _ = _share_correct(HARD, [40, 1.0], [LEAD, THROUGHPUT], h2=0.05, n0=3)
    assert share < 0.95


def test_the_assumption_skips_designs_and_keeps_the_guarantee() -> None:
    # two combinations x counts 1..6; lead time falls with the count (monotone)
    counts = [1, 2, 3, 4, 5, 6]
    means = np.array([[900 - 70 * n, 99.0] for n in counts]
                     + [[860 - 60 * n, 99.0] for n in counts], dtype=float)
    prices = [100 * n for n in counts] + [100 * n + 30 for n in counts]
    structure = Structure(["a"] * 6 + ["b"] * 6, counts + counts)
    k, s = means.shape
    h2 = fb_h2(10, error_per_check(0.95, k, s))
    right, inferred = 0, 0
    for rep in range(REPETITIONS):
        rng = np.random.default_rng([rep, 99])

        def sample(i: int, r: int, rng: np.random.Generator = rng) -> list[float]:
            return list(means[i] + np.array([40, 1.0]) * rng.standard_normal(2))

        search = CheapestSearch(prices, [LEAD, THROUGHPUT], 10, 200, h2, 2, structure)
        answer = simulate(search, sample)
        right += _correct(answer, means, [LEAD, THROUGHPUT], prices)
        inferred += sum(st.inferred_from is not None and st.asked == 0
                        for st in search.states)
    assert right / REPETITIONS >= 0.95
    assert inferred >= REPETITIONS  # designs decided without a run of their own


def test_neighbours_of_the_answer_are_checked_and_a_broken_assumption_is_seen() -> None:
    # count 2 meets, 3 fails (not monotone), 1 fails, 4 meets
    counts = [1, 2, 3, 4]
    means = np.array([[900, 99], [500, 99], [900, 99], [500, 99]], dtype=float)
    structure = Structure(["a"] * 4, counts)
    h2 = fb_h2(10, error_per_check(0.95, 4, 2))
    search = CheapestSearch([100, 200, 300, 400], [LEAD, THROUGHPUT], 10, 100, h2, 2,
                            structure)
    rng = np.random.default_rng(5)
    simulate(search, lambda i, r: list(means[i] + np.array([10, 0.1]) * rng.standard_normal(2)))
    assert search.answer() == 1

    def run_batch(request: list[tuple[int, int]]) -> None:
        for i, r in request:
            search.record(i, r, list(means[i] + np.array([10, 0.1]) * rng.standard_normal(2)))

    from fleet_sim.study.search import drive

    checks = drive(search.check_neighbours(), run_batch)
    below, above = (next(c for c in checks if c["agvs"] == n) for n in (1, 3))
    assert below["seen"] == "fails" and below["agrees"] is True
    assert above["seen"] == "fails" and above["agrees"] is False
    assert search.checks == {2: "fails"}  # run only to check: design 3 was never needed


# ---- real runs -----------------------------------------------------------------------------


def _experiment_file(tmp_path: Path, name: str = "design.yaml", **changes: Any) -> Path:
    data = yaml.safe_load(DESIGN.read_text(encoding="utf-8"))
    data["scenario"] = str((DESIGN.parent / data["scenario"]).resolve())
    optimise_changes = changes.pop("optimise", {})
    data.update(changes)
    data["optimise"].update(optimise_changes)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def test_the_known_answer_on_real_runs_in_nine_of_ten_master_seeds(tmp_path: Path) -> None:
    right = 0
    for seed in range(10):
        file = _experiment_file(tmp_path, f"design{seed}.yaml", master_seed=100 + seed)
        outcome = optimise(load_experiment(file), tmp_path / f"o{seed}", workers=2, quiet=True)
        answer = outcome.document["answer"]
        right += answer is not None and answer["choices"] == {
            "fleet.size": 1, "layout:handling": "fast"}
    assert right >= 9


def test_optimise_writes_the_answer_and_every_design(tmp_path: Path) -> None:
    out = tmp_path / "o"
    stream = io.StringIO()
    outcome = optimise(load_experiment(DESIGN), out, workers=2, stream=stream)
    doc = json.loads((out / "optimise.json").read_text(encoding="utf-8"))
    assert doc == outcome.document
    # every run the search asked for is in the summary, and it says so
    assert stream.getvalue().rstrip().endswith(f"all {doc['runs_used']} planned runs are in "
                                               f"the summary ({doc['runs_used']} finished)")
    assert doc["answer"]["price"] == 130
    assert doc["statement"].startswith("The cheapest system that meets both targets")
    assert "1 AGV, 2 s handling at both stations: 130 kEUR" in doc["statement"]
    assert "p95 lead time at most 600 s" in doc["statement"]  # KPIs in words
    verdicts = {d["label"]: d["verdict"] for d in doc["designs"]}
    # one AGV at 20 s + 30 s handling carries 31.2 orders/h < 33: ruled out without a run
    assert verdicts["fleet.size=1, handling=as_it_is"] == "ruled out"
    assert verdicts["fleet.size=1, handling=fast"] == "meets"
    assert verdicts["fleet.size=3, handling=fast"] == "not needed"
    assert doc["runs_used"] < doc["full_grid_runs"]
    assert len(doc["designs"]) == doc["design_count"] == 6
    # the runs are the experiment's: a design without layout changes shares size's run ids
    runs = {p.name for p in (out / "runs").iterdir()}
    assert "fleet.size=1__layout-handling=fast__r00" in runs
    assert all(t["decided"] for t in doc["target_costs"])


def test_an_interrupted_search_resumes_to_the_same_bytes(tmp_path: Path) -> None:
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    experiment = load_experiment(DESIGN)
    optimise(experiment, whole, workers=2, quiet=True)
    optimise(experiment, cut, workers=2, quiet=True)
    # as if killed mid-search: half the runs never finished, one was left half-written
    runs = sorted((cut / "runs").iterdir())
    for run in runs[len(runs) // 2:]:
        shutil.rmtree(run)
    (runs[0] / "kpis.json").write_text("{", encoding="utf-8")
    (cut / "optimise.json").unlink()
    optimise(experiment, cut, workers=2, quiet=True)
    assert (cut / "optimise.json").read_bytes() == (whole / "optimise.json").read_bytes()


def test_when_no_design_meets_it_names_the_binding_target_and_the_closest(
        tmp_path: Path) -> None:
    file = _experiment_file(tmp_path, targets=[
        {"kpi": "throughput_pct_of_demand", "at_least": 95},
        {"kpi": "lead_time_p95_s", "at_most": 40}])
    outcome = optimise(load_experiment(file), tmp_path / "o", workers=2, quiet=True)
    doc = outcome.document
    assert doc["answer"] is None
    assert doc["closest"]["binding_target"] == "lead_time_p95_s"
    assert doc["statement"].startswith("No design in the space meets both targets")
    assert "The target that binds is p95 lead time at most 40 s" in doc["statement"]


def test_a_one_decision_space_gives_the_answer_of_size(tmp_path: Path) -> None:
    sizing = ROOT / "experiments" / "tiny_loop_sizing.yaml"
    data = yaml.safe_load(sizing.read_text(encoding="utf-8"))
    data["scenario"] = str((sizing.parent / data["scenario"]).resolve())
    data.pop("factors")
    data["optimise"] = {"decisions": {"fleet.size": {"min": 1, "max": 4,
                                                     "price_per_unit": 1}},
                        "tolerance": {"throughput_pct_of_demand": 2, "lead_time_p95_s": 60},
                        "more_agvs_never_worse": True}
    file = tmp_path / "one.yaml"
    file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    out = tmp_path / "o"
    (sized,) = size_fleet(load_experiment(sizing), out, workers=2, quiet=True)
    shared = out / "runs" / "fleet.size=2__r00" / "kpis.json"
    before = shared.stat().st_mtime_ns
    outcome = optimise(load_experiment(file), out, workers=2, quiet=True)
    assert outcome.document["answer"]["choices"] == {"fleet.size": sized.recommended} \
        == {"fleet.size": 2}
    assert shared.stat().st_mtime_ns == before  # size's run, shared: not made again
    assumption = outcome.document["assumption"]
    assert assumption["more_agvs_never_worse"] and assumption["held"]
    # 1 AGV is ruled out by the analytic estimate (1.66 busy), so only 3 AGVs is checked
    assert [c["agvs"] for c in assumption["checked"]] == [3]
    assert outcome.document["designs"][0]["verdict"] == "ruled out"


def test_on_a_dask_cluster_the_same_answer_to_the_byte(tmp_path: Path) -> None:
    pytest.importorskip("dask.distributed")
    experiment = load_experiment(DESIGN)
    optimise(experiment, tmp_path / "pool", workers=2, quiet=True)
    optimise(experiment, tmp_path / "dask", workers=2, scheduler="local", quiet=True)
    assert (tmp_path / "dask" / "optimise.json").read_bytes() == \
        (tmp_path / "pool" / "optimise.json").read_bytes()


def test_a_fleet_the_layout_cannot_hold_is_refused_without_a_run(tmp_path: Path) -> None:
    # the tiny loop parks 4 AGVs (and starts none elsewhere): 5 and 6 do not fit
    file = _experiment_file(tmp_path, optimise={"decisions": {"fleet.size": {
        "min": 1, "max": 6, "price_per_unit": 100}}})
    outcome = optimise(load_experiment(file), tmp_path / "o", workers=2, quiet=True)
    rows = {d["label"]: d for d in outcome.document["designs"]}
    for n in (5, 6):
        for handling in ("as_it_is", "fast"):
            row = rows[f"fleet.size={n}, handling={handling}"]
            assert row["verdict"] == "refused" and row["replications"] == 0
            assert "parking" in row["reason"] or "start" in row["reason"], row["reason"]
    assert outcome.document["procedure"]["designs_counted"] == 12 - 4 - 1  # 1 ruled out
    assert outcome.document["answer"]["price"] == 130


def test_at_the_run_limit_it_stops_keeping_what_was_decided(tmp_path: Path) -> None:
    from fleet_sim.study.optimise import OptimiseLimit

    out = tmp_path / "o"
    with pytest.raises(OptimiseLimit, match="needs more than 8 runs, the limit"):
        optimise(load_experiment(DESIGN), out, workers=2, quiet=True, max_runs=8)
    doc = json.loads((out / "optimise.json").read_text(encoding="utf-8"))
    assert doc["stopped"] and doc["runs_used"] <= 8
    assert doc["statement"].startswith("The search stopped before it could name an answer")
    assert "its guarantee does not hold yet" in doc["statement"]
    assert (out / "summary.parquet").exists()  # the runs made are in the tables


@pytest.mark.parametrize(("extra", "words"), [
    ({}, "optimise: got None; expected an optimise section"),
    ({"optimise": {"decisions": {"fleet.sise": {"min": 1, "max": 3}},
                   "tolerance": {"lead_time_p95_s": 20}}},
     "optimise.decisions.fleet.sise: got 1; expected no such key here: did you mean 'size'?"),
])
def test_the_command_refuses_a_bad_optimise_file_in_one_line(tmp_path: Path,
                                                             extra: dict[str, Any],
                                                             words: str) -> None:
    import subprocess
    import sys

    file = tmp_path / "x.yaml"
    file.write_text(yaml.safe_dump({
        "scenario": str(ROOT / "experiments" / "tiny_loop.yaml"),
        "targets": [{"kpi": "lead_time_p95_s", "at_most": 600}], **extra}), encoding="utf-8")
    done = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "optimise", str(file),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fleet-sim: error: ") and words in lines[0]
    assert not (tmp_path / "o").exists()  # refused before anything was made
