"""The documents: pictures and relative links point at files that exist; quoted messages are
today's; the README's DuckDB one-liner works."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import ROOT

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: p.name)
def test_relative_links_resolve(doc: Path) -> None:
    targets = [t.split("#", 1)[0] for t in LINK.findall(doc.read_text(encoding="utf-8"))
               if not re.match(r"[a-z]+:|#", t)]
    missing = [t for t in targets if not (doc.parent / t).exists()]
    assert missing == []


def test_the_studies_page_shows_its_three_plots() -> None:
    text = (ROOT / "docs" / "agv-model-studies.md").read_text(encoding="utf-8")
    shown = re.findall(r"!\[[^\]]*\]\((img/[^)]+\.png)\)", text)
    assert len(shown) == 3


def test_every_picture_is_shown_by_a_page() -> None:
    shown = {m for doc in sorted((ROOT / "docs").glob("*.md"))
             for m in re.findall(r"!\[[^\]]*\]\((img/[^)]+\.png)\)",
                                 doc.read_text(encoding="utf-8"))}
    assert shown == {f"img/{p.name}" for p in (ROOT / "docs" / "img").glob("*.png")}


def test_the_readme_quotes_todays_error_messages(tmp_path: Path) -> None:
    """The README's two example errors are what the command prints today, word for word."""
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    (tmp_path / "s.yaml").write_text(
        "name: s\nlayout: " + str(ROOT / "layouts" / "tiny_loop.yaml")
        + "\nfleet: {size: 1, colour: red}\n", encoding="utf-8")
    for args in (["run", "s.yaml"],
                 ["run", str(ROOT / "experiments" / "tiny_loop.yaml"), "--hours", "nan"]):
        result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", *args], cwd=tmp_path,
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 2
        message = result.stderr.strip().splitlines()[-1]
        assert message.startswith("fleet-sim: error: ")
        assert f"`{message}`" in readme


def test_the_readme_duckdb_one_liner_queries_a_sweep(tmp_path: Path) -> None:
    """The README's query of sweep.duckdb runs as shown, from the folder `make run` is run in,
    on a (one-run) sweep written where the README says."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.sweep import sweep

    from .conftest import write_yaml

    (line,) = [line for line in (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
               if line.startswith('.venv/bin/python -c "import duckdb')]
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "warehouse_sizing", "scenario": str(ROOT / "experiments" / "tiny_loop.yaml"),
        "overrides": {"duration_h": 0.5, "warmup_h": 0.1}, "factors": {"fleet.size": [1]},
        "replications": 1}))
    sweep(experiment, tmp_path / "results" / "warehouse_sizing", workers=1, quiet=True)
    command = [sys.executable, *shlex.split(line)[1:]]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "throughput_per_hour" in result.stdout and "fleet.size=1__r00" in result.stdout
