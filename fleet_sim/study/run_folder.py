"""A run's folder: what it holds, the manifest that says the run finished, the check that a
finished run is what it says it is, and a run's outcome (its status, error.json).

A run's folder (``<results>/runs/<run id>/``)::

    spec.json              factors, replication, seed, overrides (written first)
    config.resolved.yaml   the run's scenario, every default written out
    events.parquet, orders.parquet, run_info.json    as `fleet-sim run` writes them
    node_waits.parquet     per node: AGV passes and seconds AGVs stood there waiting
                           (fleet_sim.analysis.congestion)
    kpis.json              the run's KPIs
    manifest.json          written last: each file's size and SHA-256 (a finished run)
    error.json             instead of the manifest when the run failed (type, message, trace)

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from userfiles.writing import write_json_atomic

OK, FAILED, CRASHED, DAMAGED = "ok", "failed", "crashed", "damaged"


@dataclass(frozen=True)
class RunResult:
    run_id: str
    status: str
    wall_s: float
    error: str = ""


# ---- is a finished run what it says it is? -------------------------------------------------

MANIFEST = "manifest.json"
"""Written last into a finished run's folder: each file's size and SHA-256."""
CHECKED_BY = "checked_by"
"""The key of spec.json that says the run is finished only with its manifest (absent in the
runs of a fleet_sim that wrote no manifest)."""
MODEL_VERSION = "2026-11-28"
"""The model that made a run, in spec.json: changed whenever a change moves the results of runs
with the same settings (new defaults, a fix in the engine). A finished run of another model
(or of a fleet_sim that did not say) is made again, with one line naming it, so a resumed
study never mixes runs of two models."""
MODEL_KEY = "model_version"
CHECKED_ASIDE = ("spec.json", "error.json", MANIFEST)
"""Files of a run folder the manifest does not cover (written before, or instead of, it)."""
HASH_CHUNK = 1 << 20


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def write_manifest(run_dir: Path) -> None:
    """The manifest of the run's files in `run_dir` (everything but spec.json and error.json)."""
    files = {p.name: {"size_bytes": p.stat().st_size, "sha256": file_sha256(p)}
             for p in sorted(run_dir.iterdir())
             if p.is_file() and not p.name.startswith(".") and p.name not in CHECKED_ASIDE}
    write_json_atomic(run_dir / MANIFEST, {"files": files})


def run_problem(run_dir: Path) -> str | None:
    """What is wrong with a run folder that looks finished (it has a manifest or a
    kpis.json), in a few words; None when every file it should hold is there, whole and
    readable. A run of a fleet_sim that wrote no manifest (kpis.json only) is checked by
    reading: its kpis.json must hold KPIs and every Parquet file must open."""
    spec, spec_problem = _read_json(run_dir / "spec.json", "run_id",
                                    "does not say which run this is")
    if spec_problem is not None:  # the summary could not place the run: it would vanish
        return spec_problem
    if spec["run_id"] != run_dir.name:  # the summary would file it under another run's name
        return f"spec.json names another run ({spec['run_id']})"
    if spec.get(MODEL_KEY) != MODEL_VERSION:
        return (f"it was made by another version of the model ({spec.get(MODEL_KEY) or 'older'}"
                f", now {MODEL_VERSION})")
    manifest_file = run_dir / MANIFEST
    if not manifest_file.exists() and spec.get(CHECKED_BY) == MANIFEST:
        return f"{MANIFEST} is missing"
    if manifest_file.exists():
        try:
            manifest = json.loads(manifest_file.read_text(encoding="utf-8"))
            files = manifest["files"]
            assert isinstance(files, dict)
        except (OSError, ValueError, KeyError, AssertionError, TypeError):
            return f"{MANIFEST} is damaged"
        for name, entry in sorted(files.items()):
            path = run_dir / name
            if not path.is_file():
                return f"{name} is missing"
            try:
                size = path.stat().st_size
                if size != entry.get("size_bytes"):
                    return (f"{name} has {size} bytes where {entry.get('size_bytes')} were "
                            "written")
                if file_sha256(path) != entry.get("sha256"):
                    return f"{name} is damaged (its content changed since it was written)"
            except OSError as exc:
                return f"{name} cannot be read ({exc.strerror or exc})"
        if "kpis.json" not in files:
            return "kpis.json is missing"
    return _kpis_problem(run_dir) or (None if manifest_file.exists()
                                      else _tables_problem(run_dir))


def _kpis_problem(run_dir: Path) -> str | None:
    return _read_json(run_dir / "kpis.json", "throughput_per_hour", "holds no KPIs")[1]


def _read_json(path: Path, key: str, without_key: str) -> tuple[dict[str, Any], str | None]:
    """A run's JSON file that must be an object holding `key`, and what is wrong with it:
    None when nothing is (when something is, the object is empty)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}, f"{path.name} is missing"
    except (OSError, ValueError):
        return {}, f"{path.name} is damaged (not JSON)"
    if not isinstance(data, dict) or key not in data:
        return {}, f"{path.name} {without_key}"
    return data, None


def _tables_problem(run_dir: Path) -> str | None:
    import pyarrow.parquet as pq

    for path in sorted(run_dir.glob("*.parquet")):
        try:
            pq.read_metadata(path)
        except Exception as exc:  # pyarrow raises its own errors for a damaged file
            return f"{path.name} is damaged ({type(exc).__name__})"
    return None


def record_failure(run_dir: Path, status: str, message: str, trace: str, wall_s: float) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / "error.json", {"status": status, "error": message,
                                                "traceback": trace, "wall_s": round(wall_s, 3)})
