"""Statistics against values computed by hand (t quantiles from tables)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from fleet_sim.analysis.stats import (
    check_targets,
    decide,
    factor_effect,
    mean_ci,
    mser5_truncation,
    one_factor_pairs,
    pair_difference,
    paired_differences,
    point_stats,
    replications_needed,
    t_quantile,
)
from fleet_sim.config.experiment import Target

T_3DF = 3.182446  # two-sided 95 %, 3 degrees of freedom (any t table)
T_2DF = 4.302653


def test_t_quantiles_match_the_table() -> None:
    assert t_quantile(4) == pytest.approx(T_3DF, abs=1e-6)
    assert t_quantile(3) == pytest.approx(T_2DF, abs=1e-6)
    assert t_quantile(1000) == pytest.approx(1.962339, abs=1e-5)


def test_mean_and_interval_by_hand() -> None:
    ci = mean_ci([1.0, 2.0, 3.0, 4.0])
    sd = math.sqrt(((1.5**2) * 2 + (0.5**2) * 2) / 3)  # 1.290994
    assert (ci.n, ci.mean, ci.sd) == (4, 2.5, pytest.approx(sd))
    assert ci.half_width == pytest.approx(T_3DF * sd / 2, rel=1e-6)  # 2.054260
    assert ci.half_width == pytest.approx(2.054260, abs=1e-6)
    assert (ci.low, ci.high) == (pytest.approx(0.445740, abs=1e-6),
                                 pytest.approx(4.554260, abs=1e-6))
    one = mean_ci([5.0])
    assert one.mean == 5.0 and math.isnan(one.half_width)
    assert mean_ci([1.0, np.nan, 3.0]).n == 2


def test_decisions_against_targets() -> None:
    values = np.array([1.0, 2.0, 3.0, 4.0])  # 95 % CI 0.4457 .. 4.5543 (see above)
    assert decide(values, Target(kpi="k", at_least=0.4)) == "meets"
    assert decide(values, Target(kpi="k", at_least=4.6)) == "fails"
    assert decide(values, Target(kpi="k", at_least=3.0)) == "undecided"
    assert decide(values, Target(kpi="k", at_most=4.6)) == "meets"
    assert decide(values, Target(kpi="k", at_most=0.4)) == "fails"
    assert decide(values, Target(kpi="k", at_most=2.0)) == "undecided"
    assert decide(np.array([1.0, np.nan]), Target(kpi="k", at_most=100)) == "fails"


def test_replications_needed_by_hand() -> None:
    sd = math.sqrt(5 / 3)  # of 1, 2, 3, 4
    # t(27 df) * sd / sqrt(28) = 0.5006 > 0.5 ; t(28 df) * sd / sqrt(29) = 0.4911 < 0.5
    assert replications_needed(sd, 0.5, 4) == 29
    assert replications_needed(sd, -0.5, 4) == 29  # the side does not matter
    assert replications_needed(sd, 0.0, 4) is None  # mean on the bound: none decides
    assert replications_needed(0.0, 1.0, 3) == 3


def summary_frame() -> pd.DataFrame:
    # fleet.size 1 and 2, replications 0..2; kpi x; one failed run that must be ignored
    return pd.DataFrame({
        "run_id": ["a", "b", "c", "d", "e", "f", "g"],
        "status": ["ok"] * 6 + ["failed"],
        "fleet.size": [1, 1, 1, 2, 2, 2, 2],
        "replication": [0, 1, 2, 0, 1, 2, 3],
        "x": [10.0, 12.0, 14.0, 11.0, 15.0, 14.0, 999.0],
    })


def test_point_stats_per_level() -> None:
    stats = point_stats(summary_frame(), ["fleet.size"]).set_index(["fleet.size", "kpi"])
    one = stats.loc[(1, "x")]
    assert one["n"] == 3 and one["mean"] == pytest.approx(12.0)
    assert one["half_width"] == pytest.approx(T_2DF * 2.0 / math.sqrt(3), rel=1e-6)
    two = stats.loc[(2, "x")]
    assert two["n"] == 3 and two["mean"] == pytest.approx(40 / 3)  # the failed run is out


def test_paired_differences_by_replication() -> None:
    diffs = paired_differences(summary_frame(), ["fleet.size"], ["x"])
    row = diffs.iloc[0]
    assert (row["factor"], row["from_level"], row["to_level"], row["pairs"]) == \
        ("fleet.size", 1, 2, 3)
    # differences 1, 3, 0: mean 4/3, sd 1.527525, half-width t(2) * sd / sqrt(3)
    assert row["mean_diff"] == pytest.approx(4 / 3)
    assert row["half_width"] == pytest.approx(T_2DF * 1.527525 / math.sqrt(3), rel=1e-6)
    assert (row["from_mean"], row["to_mean"]) == (pytest.approx(12.0), pytest.approx(40 / 3))


def two_factor_frame() -> pd.DataFrame:
    """demand 30/60 x policy b/a (the file lists b first), replications 0..2 (demand 60 with
    policy a also ran replication 3, as a sizing search adds replications); KPIs x and y."""
    rows = []
    x = {(30, "b"): [10.0, 12.0, 14.0], (60, "b"): [13.0, 16.0, 14.0],
         (30, "a"): [11.0, 12.0, 16.0], (60, "a"): [15.0, 15.0, 20.0, 99.0]}
    for (demand, policy), values in x.items():
        for r, value in enumerate(values):
            rows.append({"run_id": f"{demand}{policy}{r}", "status": "ok", "replication": r,
                         "demand": demand, "policy": policy, "x": value, "y": 2.0 * r})
    return pd.DataFrame(rows)


def test_pairs_differ_in_one_factor_adjacent_numbers_and_against_the_first_listed() -> None:
    frame = two_factor_frame()
    pairs = one_factor_pairs(frame, ["demand", "policy"], listed={"policy": ["b", "a"]})
    got = [(p.factor, p.from_level, p.to_level, p.fixed) for p in pairs]
    assert got == [("demand", 30, 60, {"policy": "a"}), ("demand", 30, 60, {"policy": "b"}),
                   ("policy", "b", "a", {"demand": 30}), ("policy", "b", "a", {"demand": 60})]
    # unlisted: the first level in the summary is the reference
    unlisted = one_factor_pairs(frame, ["demand", "policy"], factors=["policy"])
    assert [(p.from_level, p.to_level) for p in unlisted] == [("b", "a"), ("b", "a")]
    three = pd.DataFrame({"status": "ok", "replication": 0, "n": [3, 1, 2], "x": 1.0})
    assert [(p.from_level, p.to_level) for p in one_factor_pairs(three, ["n"])] == \
        [(1, 2), (2, 3)]  # numbers: adjacent levels in increasing order
    flags = pd.DataFrame({"status": "ok", "replication": 0, "on": [True, False, None],
                          "x": 1.0})
    assert [(p.from_level, p.to_level) for p in one_factor_pairs(
        flags, ["on"], listed={"on": [False, True]})][:2] == [(False, True), (False, None)]


def test_paired_differences_of_every_kpi_over_every_factor_by_hand() -> None:
    diffs = paired_differences(two_factor_frame(), ["demand", "policy"], ["x", "y"],
                               listed={"policy": ["b", "a"]})
    assert len(diffs) == 8  # 4 pairs x 2 KPIs
    one = diffs[(diffs["factor"] == "demand") & (diffs["policy"] == "a")
                & (diffs["kpi"] == "x")].iloc[0]
    # 60a - 30a over replications 0..2 (replication 3 ran at 60a only): 4, 3, 4
    assert one["pairs"] == 3 and one["mean_diff"] == pytest.approx(11 / 3)
    sd = float(np.std([4.0, 3.0, 4.0], ddof=1))
    assert one["half_width"] == pytest.approx(T_2DF * sd / math.sqrt(3), rel=1e-6)
    assert one["from_mean"] == pytest.approx(13.0) and one["to_mean"] == pytest.approx(50 / 3)
    assert pd.isna(one["demand"])  # the factor that varies has no fixed level
    policy = diffs[(diffs["factor"] == "policy") & (diffs["demand"] == 30)
                   & (diffs["kpi"] == "x")].iloc[0]
    # a - b at demand 30: 1, 0, 2
    assert (policy["from_level"], policy["to_level"]) == ("b", "a")
    assert policy["mean_diff"] == pytest.approx(1.0)
    same = diffs[diffs["kpi"] == "y"]  # y is the same at every point: exactly zero
    assert (same["mean_diff"] == 0).all() and (same["half_width"] == 0).all()


def test_pair_difference_pairs_only_replications_both_points_have_with_values() -> None:
    frame = two_factor_frame()
    frame.loc[(frame["demand"] == 30) & (frame["policy"] == "b") & (frame["replication"] == 1),
              "x"] = np.nan
    diff = pair_difference(frame, {"demand": 30, "policy": "b"}, {"demand": 60, "policy": "b"},
                           "x")
    assert diff.pairs == 2 and diff.interval.mean == pytest.approx(1.5)  # 3 and 0
    assert not diff.excludes_zero
    missing = pair_difference(frame, {"demand": 30, "policy": "b"}, {"demand": 90}, "x")
    assert missing.pairs == 0 and math.isnan(missing.interval.mean)


def test_a_factors_effect_is_averaged_over_the_other_factors_replication_by_replication() -> None:
    effect = factor_effect(two_factor_frame(), ["demand", "policy"], "demand", 30, 60, "x")
    # replication r: mean over policies of (60 - 30): (3 + 4) / 2, (4 + 3) / 2, (0 + 4) / 2
    per_rep = [3.5, 3.5, 2.0]
    assert effect.pairs == 3 and effect.interval.mean == pytest.approx(np.mean(per_rep))
    assert effect.interval.half_width == pytest.approx(
        T_2DF * float(np.std(per_rep, ddof=1)) / math.sqrt(3), rel=1e-6)
    assert effect.excludes_zero  # 3 +- 1.9
    alone = factor_effect(two_factor_frame(), ["demand"], "demand", 30, 60, "y")
    assert alone.interval.mean == 0.0


def test_wide_interval_warning_says_how_many_replications() -> None:
    frame = pd.DataFrame({"status": ["ok"] * 4, "fleet.size": [3] * 4,
                          "replication": [0, 1, 2, 3], "x": [1.0, 2.0, 3.0, 4.0]})
    checks = check_targets(frame, ["fleet.size"], [Target(kpi="x", at_least=3.0),
                                                   Target(kpi="x", at_least=0.1)])
    assert [c.decision for c in checks] == ["undecided", "meets"]
    warning = checks[0].warning()
    assert warning is not None
    assert "fleet.size=3" in warning and "straddles" in warning
    assert "about 29 replications" in warning
    assert checks[1].warning() is None


def test_warnings_name_levels_as_the_experiment_file_writes_them() -> None:
    """A factor with a null level (no admission limit) makes pandas hold the column as floats:
    messages still say 40 and null, not 40.0 and nan."""
    frame = pd.DataFrame({"status": ["ok"] * 4, "fleet.size": [50] * 4,
                          "dispatch.max_active_agvs": [40, 40, None, None],
                          "replication": [0, 1, 0, 1], "x": [1.0, 2.0, 1.0, 2.0]})
    assert frame["dispatch.max_active_agvs"].dtype == float
    checks = check_targets(frame, ["fleet.size", "dispatch.max_active_agvs"],
                           [Target(kpi="x", at_least=1.4)])
    warnings = sorted(str(c.warning()) for c in checks)
    assert warnings[0].startswith("fleet.size=50, dispatch.max_active_agvs=40: the 95 % CI")
    assert warnings[1].startswith("fleet.size=50, dispatch.max_active_agvs=null: the 95 % CI")


def test_a_code_no_run_raised_counts_zero_times() -> None:
    frame = pd.DataFrame({"fleet.size": [3, 3, 3], "status": ["ok"] * 3,
                          "errors_by_code.E_101": [1.0, 0.0, 2.0]})
    checks = check_targets(frame, ["fleet.size"], [
        Target(kpi="errors_by_code.E_101", at_most=0.0),  # raised 0 to 2 times: undecided
        Target(kpi="errors_by_code.E_999", at_most=0.0),  # never raised, no column: zero, meets
        Target(kpi="lead_time_p95_s", at_most=600.0)])  # no value at all: fails
    assert [c.decision for c in checks] == ["undecided", "meets", "fails"]


def test_mser5_cuts_the_initial_transient_and_nothing_of_a_stationary_series() -> None:
    rng = np.random.default_rng(3)
    noise = rng.normal(0.0, 1.0, 1000)
    transient = np.where(np.arange(1000) < 200, 20.0 * (1 - np.arange(1000) / 200), 0.0)
    cut = mser5_truncation(noise + transient)
    assert cut % 5 == 0 and 150 <= cut <= 250  # the ramp ends at observation 200
    assert mser5_truncation(noise) <= 25  # no transient: little or nothing deleted
    assert mser5_truncation([1.0, 2.0, 3.0]) == 0  # shorter than two batches


def test_mser5_by_hand() -> None:
    """Batch means 10, 0, 0, 0 (k = 4, d up to 2): MSER(0) = 75 / 16, MSER(1) = 0: cut 5."""
    series = [10.0] * 5 + [0.0] * 15
    assert mser5_truncation(series) == 5
    assert mser5_truncation([0.0] * 20) == 0  # all equal: ties go to the shorter warm-up
