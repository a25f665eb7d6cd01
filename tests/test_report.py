"""The report in a real headless browser: every figure there and loaded; names escaped."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fleet_sim.config.experiment import load_experiment
from fleet_sim.report.render import write_report
from fleet_sim.study.sizing import size_fleet
from fleet_sim.study.sweep import sweep

from .conftest import LAYOUTS, write_yaml

EVIL = '<script>alert("x")</script><img src=x onerror=alert(1)> & "quotes"'
FIGURES = {"layout", "kpis", "states-0", "blocked", "heatmap", "incidents"}

CHECK = """<script>
window.addEventListener('load', () => {
  const imgs = Array.from(document.images);
  const pre = document.createElement('pre');
  pre.id = 'img-check';
  pre.textContent = JSON.stringify(imgs.map(i => ({key: i.dataset.figure || i.src.slice(0, 20),
    ok: i.complete && i.naturalWidth > 0, w: i.naturalWidth})));
  document.body.appendChild(pre);
});
</script></body>"""


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("report")
    scenario = write_yaml(tmp / "evil_scenario.yaml", {
        "name": EVIL, "description": EVIL, "layout": str(LAYOUTS / "tiny_loop.yaml"),
        "duration_h": 2, "warmup_h": 0.25, "demand": {"rate_per_hour": 45}})
    path = write_yaml(tmp / "evil.yaml", {
        "name": "evil", "description": EVIL, "scenario": str(scenario),
        "factors": {"fleet.size": [1, 2, 3]}, "replications": 2, "master_seed": 5,
        "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 95},
                    {"kpi": "lead_time_p95_s", "at_most": 1200}],
        "sizing": {"max_replications": 4}})
    experiment = load_experiment(path)
    out = tmp / "out"
    sweep(experiment, out, workers=2, quiet=True)
    size_fleet(experiment, out, workers=2, quiet=True)
    write_report(out)
    return out


def test_report_files(results: Path) -> None:
    html = (results / "report.html").read_text(encoding="utf-8")
    assert set(re.findall(r'data-figure="([^"]+)"', html)) >= FIGURES
    assert "Recommendation" in html and "with 95 % confidence" in html
    assert "<img src=x" not in html and "<script>" not in html  # nothing from the files runs
    assert "&lt;script&gt;alert(&#34;x&#34;)&lt;/script&gt;" in html
    pdf = (results / "report.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page\b(?!s)", pdf)) >= 1 + len(FIGURES)
    sizing = json.loads((results / "sizing.json").read_text())
    recommended = sizing["groups"][0]["recommended"]
    assert recommended is not None and f"{recommended} AGVs meet every target" in html


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_report_in_a_headless_browser(results: Path, tmp_path: Path) -> None:
    browser = chromium()
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing (.ci/run installs it)")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    html = (results / "report.html").read_text(encoding="utf-8")
    page = tmp_path / "report.html"
    page.write_text(html.replace("</body>", CHECK), encoding="utf-8")
    result = subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=10000",
         "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert result.returncode == 0, result.stderr[-2000:]
    dom = result.stdout
    found = re.search(r'<pre id="img-check">(.*?)</pre>', dom, re.S)
    assert found, dom[-2000:]
    import html as html_lib

    images = json.loads(html_lib.unescape(found.group(1)))
    assert {i["key"] for i in images} >= FIGURES
    assert len(images) == html.count("<img ")  # no image smuggled in by a name
    assert all(i["ok"] and i["w"] > 100 for i in images), images
    # the malicious name is text in the page, not markup
    assert dom.count("<script>") == 1  # ours
    assert "&lt;script&gt;alert" in dom


def test_report_cli_prints_where_it_is(results: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "report", str(results),
                             "--no-pdf"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert str((results / "report.html").resolve()) in result.stdout
