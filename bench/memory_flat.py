"""Does a run's memory stay flat in simulated time? Peak RSS of `fleet-sim run` on the bundled
12-AGV shift (experiments/warehouse_shift.yaml) for 1 day and for longer runs.

Each run is `python -m fleet_sim.cli run experiments/warehouse_shift.yaml --hours 24*DAYS --out
TMP --quiet` in a fresh process (the code path of `fleet-sim run`, run directory written), so
nothing of one run stays for the next. Its peak resident set size is the kernel's ru_maxrss of
that child alone (`os.wait4`). Prints, per run: simulated days, peak RSS, its ratio to the first
run's, the slope in MB per simulated day since the first run and since the previous one, wall
time, the run's files' size and the machine's 1-minute load average before and after. --root
runs another checkout (the code before a change, say) with the same script.

The target (issue 10): a 365-day run within 1.5x of a 1-day run. A 1-day run takes some 20 s
here, so 365 days is well over an hour per checkout; `--days 1 30 90` measures the slope in
less time, `--days 1 365` the target itself.

    .venv/bin/python bench/memory_flat.py [--days 1 30 90] [--root /path/to/checkout]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = Path("experiments") / "warehouse_shift.yaml"


def run_once(root: Path, days: float, out_dir: Path) -> tuple[float, float, float, str]:
    """(peak RSS MB, wall s, files MB, load averages before -> after) of one run in a fresh
    process."""
    load_before = os.getloadavg()
    command = [sys.executable, "-m", "fleet_sim.cli", "run", str(SCENARIO),
               "--hours", f"{24 * days:g}", "--out", str(out_dir), "--quiet"]
    env = {**os.environ, "PYTHONPATH": str(root)}
    start = time.perf_counter()
    child = subprocess.Popen(command, cwd=root, env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    child.returncode = os.waitstatus_to_exitcode(status)
    stderr = child.stderr.read().decode() if child.stderr else ""
    if child.returncode != 0:
        raise SystemExit(f"{days} days: exit {child.returncode}\n{stderr}")
    files_mb = sum(p.stat().st_size for p in out_dir.iterdir()) / 1e6
    load_after = os.getloadavg()
    load = f"{load_before[0]:.2f} -> {load_after[0]:.2f}"
    return usage.ru_maxrss / 1024.0, wall, files_mb, load  # ru_maxrss is in KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=float, nargs="+", default=[1.0, 30.0, 90.0],
                        help="simulated days per run; the first is the reference")
    parser.add_argument("--root", type=Path, default=ROOT,
                        help="the checkout to run (default: this one)")
    args = parser.parse_args()

    print(f"fleet-sim run {SCENARIO} (12 AGVs), checkout {args.root}, "
          f"{os.cpu_count()} cores", flush=True)
    print(f"{'days':>6} {'peak RSS MB':>12} {'x first':>8} {'MB/day':>8} {'MB/day':>8} "
          f"{'wall s':>8} {'files MB':>9}  load 1-min", flush=True)
    print(f"{'':>6} {'':>12} {'':>8} {'(first)':>8} {'(prev)':>8} {'':>8} {'':>9}  "
          "before -> after", flush=True)
    first: tuple[float, float] | None = None
    previous: tuple[float, float] | None = None
    with tempfile.TemporaryDirectory(prefix="memory_flat_") as tmp:
        for i, days in enumerate(args.days):
            rss, wall, files, load = run_once(args.root.resolve(), days,
                                              Path(tmp) / f"run{i}")
            first = first or (days, rss)
            previous = previous or (days, rss)
            ratio = rss / first[1]
            print(f"{days:>6g} {rss:>12.1f} {ratio:>8.2f} {_slope(first, days, rss):>8.2f} "
                  f"{_slope(previous, days, rss):>8.2f} {wall:>8.1f} {files:>9.1f}  {load}",
                  flush=True)
            previous = (days, rss)


def _slope(since: tuple[float, float], days: float, rss: float) -> float:
    """MB per simulated day from `since` (days, MB) to this run."""
    return (rss - since[1]) / (days - since[0]) if days != since[0] else 0.0


if __name__ == "__main__":
    main()
