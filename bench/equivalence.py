"""Do results move in distribution between two commits? Each bundled scenario, --reps seeds,
run on the commit before (a git worktree of --before) and on this tree; for every headline KPI
the paired difference of the means (after - before, the same seed in both: common random
numbers) and a two one-sided test (TOST) at 95 %: the two are equivalent when the 90 %
confidence interval of the mean difference lies inside the margin (+- the margin of the KPI,
below). Prints a Markdown table per scenario and a verdict; exit status 1 if any KPI is not
shown equivalent.

Margins (stated here, from the size of a difference that would change a planner's answer): 1 %
of the before mean for throughput, 3 % for mean and p95 lead time, 1 percentage point for the
blocked share and for utilisation, and 0.5 deadlocks per run.

    .venv/bin/python bench/equivalence.py --before REV [--reps 20] [--jobs 2]
        [--scenarios warehouse_shift ...] [--set rules.agv_ahead=held_back ...]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("tiny_loop", "warehouse_shift", "warehouse_same_direction", "warehouse_incidents",
             "warehouse_mixed", "dc_shift", "fulfilment_shift")
"""The bundled scenario files (experiments/*.yaml that are scenarios, not experiments)."""

Margin = Callable[[float], float]
KPIS: dict[str, tuple[str, Margin]] = {
    "throughput_per_hour": ("1 % of before", lambda before: 0.01 * abs(before)),
    "lead_time_mean_s": ("3 % of before", lambda before: 0.03 * abs(before)),
    "lead_time_p95_s": ("3 % of before", lambda before: 0.03 * abs(before)),
    "blocked_time_pct": ("1 point", lambda before: 1.0),
    "agv_utilisation_pct": ("1 point", lambda before: 1.0),
    "deadlocks_detected": ("0.5 a run", lambda before: 0.5),
}
"""Headline KPI -> the margin of equivalence (its words, and its size from the before mean)."""


def _init(tree: str) -> None:
    sys.path.insert(0, tree)


def one_run(job: tuple[str, str, int, dict[str, Any]]) -> dict[str, float]:
    """The headline KPIs of `scenario` with `seed` (and `settings`), in the tree this worker
    imports from."""
    tree, scenario, seed, settings = job
    import fleet_sim
    from fleet_sim.analysis.kpi_sums import run_kpis
    from fleet_sim.config.scenario import load_layout_for, load_scenario
    from fleet_sim.sim.engine import simulate
    assert str(Path(fleet_sim.__file__).resolve()).startswith(tree), fleet_sim.__file__
    path = Path(tree) / "experiments" / f"{scenario}.yaml"
    loaded = load_scenario(path, {**settings, "seed": seed})
    figures = run_kpis(simulate(loaded, load_layout_for(loaded, str(path))))
    return {k: float(figures.get(k) or 0.0) for k in KPIS}


def run_tree(tree: Path, scenarios: list[str], reps: int, jobs: int,
             settings: dict[str, Any]) -> dict[str, list[dict[str, float]]]:
    work = [(str(tree), s, seed, settings) for s in scenarios for seed in range(1, reps + 1)]
    with ProcessPoolExecutor(jobs, mp_context=get_context("spawn"), initializer=_init,
                             initargs=(str(tree),)) as pool:
        results = list(pool.map(one_run, work))
    out: dict[str, list[dict[str, float]]] = {s: [] for s in scenarios}
    for (_, s, _, _), figures in zip(work, results, strict=True):
        out[s].append(figures)
    return out


def tost(before: list[float], after: list[float], margin: float) -> tuple[float, float, bool]:
    """Mean paired difference, the half-width of its 90 % interval, and whether that interval
    lies within +- margin (TOST at 95 %)."""
    from scipy.stats import t

    diffs = [a - b for a, b in zip(after, before, strict=True)]
    n = len(diffs)
    mean = statistics.fmean(diffs)
    sd = statistics.stdev(diffs) if n > 1 else 0.0
    half = float(t.ppf(0.95, n - 1)) * sd / math.sqrt(n)
    return mean, half, -margin < mean - half and mean + half < margin


def worktree(rev: str) -> Path:
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                            capture_output=True, text=True).stdout.strip()
    path = Path(os.environ.get("TMPDIR", "/tmp")) / f"fleet_sim_before_{commit}"
    if not path.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(path), commit], cwd=ROOT,
                       check=True, capture_output=True)
    return path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="the commit to compare with")
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="scenario settings for every run, in both trees")
    args = parser.parse_args()
    settings = dict(item.split("=", 1) for item in args.set)
    before_tree = worktree(args.before)
    print(f"before: {args.before} ({before_tree}); after: this tree; {args.reps} seeds each; "
          f"load average {os.getloadavg()[0]:.2f}")
    start = time.perf_counter()
    before = run_tree(before_tree, args.scenarios, args.reps, args.jobs, settings)
    after = run_tree(ROOT, args.scenarios, args.reps, args.jobs, settings)
    print(f"{2 * args.reps * len(args.scenarios)} runs in {time.perf_counter() - start:.0f} s; "
          f"load average {os.getloadavg()[0]:.2f}")
    failed = 0
    for scenario in args.scenarios:
        print()
        print(f"## {scenario}")
        print()
        print("| KPI | before | after | difference [90 % CI] | margin | equivalent |")
        print("|---|---:|---:|---:|---:|---|")
        for kpi, (words, margin_of) in KPIS.items():
            b = [r[kpi] for r in before[scenario]]
            a = [r[kpi] for r in after[scenario]]
            mean_b = statistics.fmean(b)
            margin = margin_of(mean_b)
            diff, half, same = tost(b, a, margin)
            failed += not same
            print(f"| {kpi} | {mean_b:.3g} | {statistics.fmean(a):.3g} | {diff:+.3g} "
                  f"[{diff - half:+.3g}, {diff + half:+.3g}] | +-{margin:.3g} ({words}) | "
                  f"{'yes' if same else '**no**'} |")
    print()
    print("every headline KPI equivalent" if not failed
          else f"{failed} KPI(s) not shown equivalent")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
