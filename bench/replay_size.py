"""How big is a replay, and how long does it take to write? An 8-hour shift of 50 AGVs, two ways:

* the planner's shift: experiments/warehouse_shift.yaml with 50 AGVs (90 orders/h with the
  mid-shift peak: most AGVs park, as a sizing sweep's larger fleets do);
* every AGV busy: the 627-node distribution centre (layouts/distribution_centre.yaml) with 50
  AGVs and 375 orders/h (7.5 per AGV and hour; the warehouse's 186 nodes lock solid under 50
  busy AGVs), the largest page a 50-AGV shift makes.

For each: the run's wall time with and without the moves recorded, the size of moves.parquet
(what a sweep would keep per run to replay it without simulating again), the time to write
replay.html from the run directory (median of --repeats) and its size, the time `fleet-sim
replay` takes on a run without moves.parquet (a sweep's run: simulated again), and, when
Debian's chromium is installed, the time headless Chromium takes to open the page and its
mean time per drawn frame (60 seeks across the shift), medians of --repeats. Prints the
machine's load at start and end; these machines are shared and noisy, so compare figures within
one run of this script.

    .venv/bin/python bench/replay_size.py [--repeats 3] [--hours 8]
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.analysis.replay import MOVES_FILE, write_moves  # noqa: E402
from fleet_sim.analysis.tables import write_run  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.report.replay import write_replay  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402

SHIFT = ROOT / "experiments" / "warehouse_shift.yaml"
CASES: dict[str, dict[str, Any]] = {
    "warehouse_shift, 50 AGVs, 90 orders/h": {"fleet.size": 50},
    "distribution centre, 50 AGVs all busy (375 orders/h)": {
        "fleet.size": 50, "layout": "../layouts/distribution_centre.yaml",
        "demand.rate_per_hour": 375, "demand.profile": []},
}


def browser_figures(page: Path, profile: Path) -> dict[str, float] | None:
    """Chromium's time to open the page and draw the first frame, and ms per frame."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        return None
    started = time.perf_counter()
    result = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1400,1100", f"--user-data-dir={profile}", "--dump-dom",
         page.as_uri() + "#t=14400"],
        capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - started
    found = re.search(r'<pre id="replay-check">(.*?)</pre>', result.stdout, re.S)
    if not found:
        return None
    import html

    check = json.loads(html.unescape(found.group(1)))
    return {"ready_s": check["readyMs"] / 1000.0, "frame_ms": check["frameMs"], "wall_s": wall}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--hours", type=float, default=8.0)
    args = parser.parse_args()
    from machine import machine_line  # bench/machine.py, beside this script

    print(machine_line("at start"), flush=True)
    for name, overrides in CASES.items():
        scenario = load_scenario(SHIFT, {**overrides, "duration_h": args.hours})
        layout = load_layout_for(scenario, str(SHIFT))
        started = time.perf_counter()
        simulate(scenario, layout)
        plain_s = time.perf_counter() - started
        started = time.perf_counter()
        run = simulate(scenario, layout, record_moves=True)
        traced_s = time.perf_counter() - started
        with tempfile.TemporaryDirectory() as tmp:
            run_dir = Path(tmp) / "run"
            write_run(run, run_dir, run_kpis(run))
            write_moves(run.recorder, run_dir)
            moves = len(run.recorder.moves)
            delivered = sum(1 for o in run.recorder.orders if o.delivered_s is not None)
            del run
            moves_mb = (run_dir / MOVES_FILE).stat().st_size / 1e6
            runs_mb = sum(p.stat().st_size for p in run_dir.iterdir()) / 1e6 - moves_mb
            writes = []
            for _ in range(args.repeats):
                started = time.perf_counter()
                page = write_replay(run_dir)
                writes.append(time.perf_counter() - started)
            page_mb = page.stat().st_size / 1e6
            (run_dir / MOVES_FILE).unlink()
            started = time.perf_counter()
            write_replay(run_dir)
            again_s = time.perf_counter() - started
            opened = [browser_figures(page, Path(tmp) / "profile") for _ in range(args.repeats)]
            shown = None if None in opened else {
                key: statistics.median(o[key] for o in opened if o is not None)
                for key in ("ready_s", "frame_ms", "wall_s")}
        print(f"\n{name}, {args.hours:g} h: {delivered} orders delivered, {moves:,} moves")
        print(f"  run                 {plain_s:6.1f} s wall; with moves recorded {traced_s:6.1f} s")
        print(f"  moves.parquet       {moves_mb:6.2f} MB (the run's other files: {runs_mb:.2f} MB)")
        each = ", ".join(f"{w:.1f}" for w in writes)
        print(f"  replay.html         {page_mb:6.2f} MB, written in "
              f"{statistics.median(writes):.1f} s (median of {len(writes)}: {each})")
        print(f"  without moves       {again_s:6.1f} s to simulate again and write the page")
        if shown is not None:
            print(f"  headless Chromium   page ready {shown['ready_s']:.2f} s after opening, "
                  f"{shown['frame_ms']:.1f} ms per frame (mean of 60 seeks), "
                  f"{shown['wall_s']:.1f} s for the whole browser run (medians of "
                  f"{args.repeats})")
    print()
    print(machine_line("at end"))


if __name__ == "__main__":
    main()
