"""How long does reading a layout take? Each bundled YAML layout read with PyYAML's own parser
and with libyaml's (the one `userfiles.reading.read_yaml` uses where PyYAML has it), then the
whole `load_layout` (read, check, build the graph), medians of --repeats, in one process.

    .venv/bin/python bench/layout_loading.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.config.layout import load_layout  # noqa: E402
from userfiles import reading  # noqa: E402

LAYOUTS = ("tiny_loop", "warehouse", "distribution_centre", "fulfilment_centre")


def median_s(repeats: int, work: object) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()  # type: ignore[operator]
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}; libyaml: {yaml.__with_libyaml__}; "
          f"medians of {args.repeats}")
    print()
    print("| layout | nodes | KB | PyYAML parser s | libyaml s | ratio | load_layout s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    c_loader = reading._Loader
    py_loader = type("PyLoader", (reading.Checks, yaml.SafeLoader), {})
    for name in LAYOUTS:
        path = ROOT / "layouts" / f"{name}.yaml"
        reading._Loader = py_loader
        slow = median_s(args.repeats, lambda p=path: reading.read_yaml(p))
        reading._Loader = c_loader
        fast = median_s(args.repeats, lambda p=path: reading.read_yaml(p))
        assert reading.read_yaml(path) == yaml.safe_load(path.read_text("utf-8"))
        whole = median_s(args.repeats, lambda p=path: load_layout(p))
        layout = load_layout(path)
        print(f"| {name} | {layout.graph.number_of_nodes():,} | "
              f"{path.stat().st_size / 1024:.0f} | {slow:.3f} | {fast:.3f} | "
              f"{slow / fast:.1f}x | {whole:.3f} |")


if __name__ == "__main__":
    main()
