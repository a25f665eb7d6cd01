"""What does the design search cost? `fleet-sim optimise` on an experiment (default: the bundled
warehouse study, experiments/warehouse_design.yaml) into a throw-away folder, run twice: with
the file as it is and with `more_agvs_never_worse` turned the other way. Prints, for each, the
wall time, the runs used against the full grid (every design the analytic estimate and the
layout leave, at the replications the answer ended with), the designs examined and the answer.

    .venv/bin/python bench/optimise_runs.py [EXPERIMENT] [--workers N] [--once]

--once: the file as it is only. Load is printed before and after (a busy machine is slower).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import yaml  # noqa: E402

from fleet_sim.config.experiment import load_experiment  # noqa: E402
from fleet_sim.study.optimise import money, optimise  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("experiment", type=Path, nargs="?",
                        default=ROOT / "experiments" / "warehouse_design.yaml")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--once", action="store_true")
    args = parser.parse_args()
    print(f"load before: {os.getloadavg()[0]:.1f}; {args.workers} workers on "
          f"{os.cpu_count()} cores")
    data = yaml.safe_load(args.experiment.read_text(encoding="utf-8"))
    data["scenario"] = str((args.experiment.parent / data["scenario"]).resolve())
    assumed = bool(data["optimise"].get("more_agvs_never_worse", False))
    print(f"{'more_agvs_never_worse':<22} {'wall s':>7} {'runs':>6} {'grid':>6} "
          f"{'examined':>9}  answer")
    with tempfile.TemporaryDirectory() as tmp:
        for assume in [assumed] if args.once else [assumed, not assumed]:
            data["optimise"]["more_agvs_never_worse"] = assume
            file = Path(tmp) / f"design_{assume}.yaml"
            file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
            start = time.perf_counter()
            outcome = optimise(load_experiment(file), Path(tmp) / f"out_{assume}",
                               workers=args.workers, quiet=True)
            wall = time.perf_counter() - start
            doc = outcome.document
            answer = doc["answer"]
            said = "none" if answer is None else \
                f"{answer['words']}: {money(answer['price'], doc['currency'])}"
            print(f"{assume!s:<22} {wall:7.0f} {doc['runs_used']:6d} "
                  f"{doc['full_grid_runs']:6d} {doc['designs_examined']:9d}  {said}")
    print(f"load after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
