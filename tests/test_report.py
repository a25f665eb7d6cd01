"""The report: every figure there and loaded in a real headless browser; names from user files
escaped by the templates (HTML text and browser DOM); a missing template value is an error; the
PDF is written."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from html.parser import HTMLParser
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pandas as pd
import pytest
import yaml
from jinja2 import UndefinedError

from fleet_sim.analysis.kpis import CATALOGUE
from fleet_sim.analysis.paired import number_text
from fleet_sim.analysis.stats import t_quantile
from fleet_sim.config.experiment import Target, load_experiment
from fleet_sim.report.answer import recommendations
from fleet_sim.report.content import Figure, Report, Table
from fleet_sim.report.render import environment, render_html, write_report
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.sections.idle_waiting import section_idle_waiting
from fleet_sim.report.sections.runs import RunsSection
from fleet_sim.report.sections.scenario import ScenarioSection
from fleet_sim.report.study_report import question
from fleet_sim.report.wording import fmt
from fleet_sim.study.sizing import size_fleet
from fleet_sim.study.sweep import sweep

from .conftest import LAYOUTS, ROOT, write_yaml
from .conftest import in_browser as browser_check

EVIL = '<script>alert("x")</script><img src=x onerror=alert(1)> & "quotes"'
FIGURES = {"layout", "kpis", "states-0", "blocked", "heatmap", "incidents", "leads"}

CHECK = """<script>
window.addEventListener('load', () => {
  const imgs = Array.from(document.images);
  const pre = document.createElement('pre');
  pre.id = 'img-check';
  pre.textContent = JSON.stringify({
    images: imgs.map(i => ({key: i.dataset.figure || i.src.slice(0, 20),
                            ok: i.complete && i.naturalWidth > 0, w: i.naturalWidth})),
    scripts: document.scripts.length,
    handlers: Array.from(document.querySelectorAll('*')).filter(
      e => Array.from(e.attributes).some(a => a.name.startsWith('on'))).length,
    settings: Object.fromEntries(Array.from(document.querySelectorAll('table.settings tr'))
      .filter(r => r.cells.length === 2)
      .map(r => [r.cells[0].textContent, r.cells[1].textContent])),
    answer: document.querySelector('.rec').textContent,
    title: document.title});
  document.body.appendChild(pre);
});
</script></body>"""


class _Page(HTMLParser):
    """The tags, the text and the tables of an HTML page, as a browser's parser sees them."""

    def __init__(self, html: str) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.text: list[str] = []
        self.tables: dict[str, list[list[str]]] = {}
        """Rows of cells by the tables' class (tables of one class in one list)."""
        self._rows: list[list[str]] | None = None
        self._cell: list[str] | None = None
        self.feed(html)
        self.close()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag == "table":
            self._rows = self.tables.setdefault(dict(attrs).get("class") or "", [])
        elif tag == "tr" and self._rows is not None:
            self._rows.append([])
        elif tag in ("td", "th") and self._rows is not None:
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._rows is not None and self._cell is not None:
            self._rows[-1].append("".join(self._cell))
            self._cell = None
        elif tag == "table":
            self._rows = None

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sweep and a sizing search with a hostile scenario name and description, experiment
    description and factor level; the experiment's name is made hostile in the results folder
    (the experiment loader accepts only a folder-safe name, the report reads what is there)."""
    tmp = tmp_path_factory.mktemp("report")
    scenario = write_yaml(tmp / "evil_scenario.yaml", {
        "name": EVIL, "description": EVIL, "layout": str(LAYOUTS / "tiny_loop.yaml"),
        "duration_h": 2, "warmup_h": 0.25, "demand": {"rate_per_hour": 45}})
    path = write_yaml(tmp / "evil.yaml", {
        "name": "evil", "description": EVIL, "scenario": str(scenario),
        "factors": {"fleet.size": [1, 2, 3], "description": [EVIL, "plain & simple"]},
        "replications": 2, "master_seed": 5,
        "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 95},
                    {"kpi": "lead_time_p95_s", "at_most": 1200}],
        "sizing": {"max_replications": 4}})
    experiment = load_experiment(path)
    out = tmp / "out"
    sweep(experiment, out, workers=2, quiet=True)
    size_fleet(experiment, out, workers=2, quiet=True)
    resolved = out / "experiment.resolved.yaml"
    data = yaml.safe_load(resolved.read_text(encoding="utf-8"))
    resolved.write_text(yaml.safe_dump({**data, "name": EVIL}), encoding="utf-8")
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
    # the tiny loop has no charger, and charging is on: every run recorded the warning
    text = " ".join("".join(_Page(html).text).split())
    assert "Settings warnings" in text and \
        "charging is on but the layout has no charger" in text
    assert "In none of the" in text  # no AGV stood Idle while orders waited


CATALOGUE_NAMES = {k.name for k in CATALOGUE}


def test_the_settings_say_the_replications_each_design_point_ran(results: Path) -> None:
    """The sizing search added replications to the sweep's 2 (up to 4): the settings table
    counts them from the summary, design point by design point."""
    page = _Page((results / "report.html").read_text(encoding="utf-8"))
    settings = dict(row for row in page.tables["settings"] if len(row) == 2 and row[0])
    summary = pd.read_parquet(results / "summary.parquet")
    ok = summary[summary["status"] == "ok"]
    counts = ok.groupby(["fleet.size", "description"]).size()
    assert counts.max() > 2  # the search did add replications somewhere
    ran = f"{counts.min()} to {counts.max()}" if counts.min() < counts.max() else \
        str(counts.min())
    assert settings["replications"].startswith(
        f"{ran} per design point ({len(ok)} finished runs at {len(counts)} design points)")
    assert "the file asks for 2, and `fleet-sim size` added replications" in \
        settings["replications"]
    assert "2 replications" not in settings["design"]


def test_paired_differences_of_every_target_kpi_named_from_the_catalogue(results: Path) -> None:
    """Every target's KPI and throughput, between fleet sizes and between the levels of the
    other factor, named with their units; the difference is the replication-by-replication
    one of the summary."""
    page = _Page((results / "report.html").read_text(encoding="utf-8"))
    rows = page.tables["differences"]
    header, body = rows[0], rows[1:]
    assert header[:4] == ["factor", "change", "other factors", "KPI"]
    assert {r[3] for r in body} == {"throughput [% of demand]", "p95 lead time [s]",
                                    "throughput [orders/h]"}
    assert {r[0] for r in body} == {"fleet.size", "description"}
    for table in ("stats", "differences"):  # no raw KPI key in a header or a KPI cell
        cells = page.tables[table][0] + [r[3] for r in body]
        assert not CATALOGUE_NAMES & set(cells), cells
    # one row by hand: fleet 1 -> 2 at description "plain & simple", p95 lead time
    summary = pd.read_parquet(results / "summary.parquet")
    ok = summary[(summary["status"] == "ok") & (summary["description"] == "plain & simple")]
    one = ok[ok["fleet.size"] == 1].set_index("replication")["lead_time_p95_s"]
    two = ok[ok["fleet.size"] == 2].set_index("replication")["lead_time_p95_s"]
    common = one.index.intersection(two.index)
    diff = (two[common] - one[common]).dropna()
    (row,) = [r for r in body if r[:4] == ["fleet.size", "1 \u2192 2",
                                           "description=plain & simple", "p95 lead time [s]"]]
    assert row[4] == str(len(diff))
    mean = float(diff.mean())
    assert row[6].startswith(("+" if mean >= 0 else "") + fmt(mean) + " s (")


def run_query_hint(html: str, cwd: Path) -> tuple[str, str]:
    """The query the report prints, run as printed (from another folder): (command, output)."""
    import html as html_lib

    found = re.search(r'<pre class="query">(.*?)</pre>', html, re.S)
    assert found
    command = html_lib.unescape(found.group(1))
    result = subprocess.run(shlex.split(command), cwd=cwd, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, (command, result.stderr)
    return command, result.stdout


def test_the_query_hint_runs_without_the_duckdb_command(results: Path, tmp_path: Path) -> None:
    command, out = run_query_hint((results / "report.html").read_text(encoding="utf-8"),
                                  tmp_path)
    assert not command.startswith("duckdb") and " -c " in command
    assert "fleet.size" in out and "description" in out and "lead_time_mean_s" in out
    assert "plain & simple" in out


def test_names_from_user_files_are_text_in_the_page(results: Path) -> None:
    """Experiment name and description, scenario name and a factor level: shown as written,
    never parsed as markup."""
    page = _Page((results / "report.html").read_text(encoding="utf-8"))
    assert [tag for tag, _ in page.tags].count("script") == 0
    assert not [attrs for _, attrs in page.tags if any(a.startswith("on") for a in attrs)]
    imgs = [attrs for tag, attrs in page.tags if tag == "img"]
    assert all(str(a["src"]).startswith("data:image/png;base64,") for a in imgs)
    text = "".join(page.text)
    assert f"Fleet sizing report: {EVIL}" in text  # the experiment's name, in <title> and <h1>
    assert text.count(f"Fleet sizing report: {EVIL}") == 2
    settings = dict(row for row in page.tables["settings"] if len(row) == 2 and row[0])
    assert settings["experiment"] == EVIL
    assert settings["description"] == EVIL  # the experiment's
    assert settings["scenario"] == f"{EVIL}: {EVIL}"  # the scenario's name and description
    assert settings["factor description"] == str([EVIL, "plain & simple"])
    assert page.tables["stats"][1][:2] == [EVIL, "1"]  # the factor level in the statistics
    assert f"Utilisation by state (description={EVIL})" in text  # the factor level
    assert f"description = {EVIL}: " in text  # the sizing statement of that series
    captions = [a["alt"] for tag, a in page.tags if tag == "img"]
    assert f"Utilisation by state (description={EVIL})" in captions


def test_the_report_shows_a_run_in_detail(results: Path) -> None:
    """The recommended fleet's first replication: its timeline (inline SVG, one bar per state
    spell with a hover text, each AGV's row covering the run) and its lead-time breakdown."""
    html = (results / "report.html").read_text(encoding="utf-8")
    page = _Page(html)
    sizing = json.loads((results / "sizing.json").read_text())
    recommended = sizing["groups"][0]["recommended"]
    section = html[html.index("A run in detail"):html.index("<h2>Incidents")]
    found = re.search(r"Run <code>([^<]+)</code>", section)
    assert found
    import html as html_lib

    run_id = html_lib.unescape(found.group(1))
    assert f"fleet.size={recommended}__r00" in run_id
    assert f"(fleet.size = {recommended})" in section
    run_dir = results / "runs" / run_id
    from fleet_sim.analysis.replay import state_spells

    events = pd.read_parquet(run_dir / "events.parquet")
    kpis = json.loads((run_dir / "kpis.json").read_text())
    spells = state_spells(events, 0.0, kpis["duration_h"] * 3600.0)
    bars = re.findall(r'<rect x="([0-9.]+)" y="([0-9.]+)" width="([0-9.]+)" height="10" '
                      r'fill="#[0-9a-f]{6}"><title>([^<]*)</title></rect>', section)
    assert len(bars) == len(spells)
    widths: dict[str, float] = {}
    for _, y, width, _ in bars:
        widths[y] = widths.get(y, 0.0) + float(width)
    assert len(widths) == kpis["agvs"]
    assert all(w == pytest.approx(1000.0, rel=0.02) for w in widths.values())
    assert all(html_lib.unescape(t).startswith("AGV ") and "reason: Event_" in
               html_lib.unescape(t) for *_, t in bars)
    leads = {row[0]: row for row in page.tables["leads"]}
    assert list(leads)[1:] == ["wait for assignment", "drive empty", "load", "drive loaded",
                               "unload", "blocked by traffic", "lead time (all parts)"]
    assert float(leads["lead time (all parts)"][1].replace(",", "")) == pytest.approx(
        kpis["lead_time_mean_s"], rel=1e-3)


def in_browser(html: str, tmp_path: Path) -> tuple[dict[str, Any], str]:
    """The page in headless Chromium with this file's CHECK (conftest.in_browser)."""
    return browser_check(html, tmp_path, CHECK)


def test_report_in_a_headless_browser(results: Path, tmp_path: Path) -> None:
    html = (results / "report.html").read_text(encoding="utf-8")
    check, dom = in_browser(html, tmp_path)
    images = check["images"]
    assert {i["key"] for i in images} >= FIGURES
    assert len(images) == html.count("<img ")  # no image smuggled in by a name
    assert all(i["ok"] and i["w"] > 100 for i in images), images
    # the malicious names are text in the page, not markup
    assert check["scripts"] == 1  # ours
    assert check["handlers"] == 0  # no element with an on... attribute
    assert check["title"] == f"Fleet sizing report: {EVIL}"
    assert check["settings"]["experiment"] == EVIL
    assert check["settings"]["description"] == EVIL
    assert check["settings"]["factor description"] == str([EVIL, "plain & simple"])
    assert dom.count("<script>") == 1
    assert "&lt;script&gt;alert" in dom


def test_report_cli_prints_where_it_is(results: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "report", str(results),
                             "--no-pdf"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert str((results / "report.html").resolve()) in result.stdout


# ---- a sweep that is not a sizing study ------------------------------------------------------


@pytest.fixture(scope="module")
def demand_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Demand 30 and 60 orders/h x two dispatch policies on the tiny loop, 3 replications,
    targets on throughput and p95 lead time: a sweep, not a fleet sizing."""
    tmp = tmp_path_factory.mktemp("demand")
    path = write_yaml(tmp / "demand.yaml", {
        "name": "demand_policy", "scenario": str(ROOT / "experiments" / "tiny_loop.yaml"),
        "overrides": {"duration_h": 1.0, "warmup_h": 0.1},
        "factors": {"demand.rate_per_hour": [30, 60],
                    "dispatch.policy": ["nearest_idle", "fcfs"]},
        "replications": 3, "master_seed": 2,
        "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 90},
                    {"kpi": "lead_time_p95_s", "at_most": 1200}]})
    out = tmp / "out"
    sweep(load_experiment(path), out, workers=2, quiet=True)
    write_report(out, pdf=False)
    return out


def test_a_sweep_report_says_what_it_varies_and_answers_in_words(demand_sweep: Path) -> None:
    html = (demand_sweep / "report.html").read_text(encoding="utf-8")
    page = _Page(html)
    text = " ".join("".join(page.text).split())
    title = "Sweep over demand rate per hour and dispatch policy: demand_policy"
    assert text.count(title) == 2  # <title> and <h1>
    assert "Fleet sizing" not in text and "No recommendation" not in text
    assert "What the sweep shows" in text and "Recommendation" not in text
    assert ("How throughput and p95 lead time change with demand rate per hour and dispatch "
            "policy: scenario tiny_loop on layout tiny_loop, 4 design points") in text
    # the first sentence, by hand: per replication, the mean over the policies of
    # (throughput at 60 - at 30), and its 95 % t interval
    summary = pd.read_parquet(demand_sweep / "summary.parquet")
    wide = summary.pivot_table(index="replication", columns=["demand.rate_per_hour",
                                                             "dispatch.policy"],
                               values="throughput_per_hour")
    per_rep = (wide[60] - wide[30]).mean(axis=1)
    mean = float(per_rep.mean())
    half = t_quantile(3) * float(per_rep.std(ddof=1)) / 3 ** 0.5
    assert mean - half > 0  # doubling the demand clearly raises throughput
    answer = text[text.index("What the sweep shows"):text.index("Scenario and layout")]
    assert answer.startswith("What the sweep shows Raising demand rate per hour from 30 to 60 "
                             "(mean over the levels of dispatch policy) ")
    assert (f"raises throughput by {number_text(mean)} orders/h ({number_text(mean - half)} to "
            f"{number_text(mean + half)} orders/h)") in answer
    assert "Dispatch policy fcfs instead of nearest_idle (mean over the levels of demand rate " \
        "per hour)" in answer
    assert answer.count("(paired over 3 replications, 95 % intervals).") == 2


def test_a_sweep_reports_paired_differences_for_every_target_kpi(demand_sweep: Path) -> None:
    page = _Page((demand_sweep / "report.html").read_text(encoding="utf-8"))
    body = page.tables["differences"][1:]
    assert {(r[0], r[1], r[3]) for r in body} == {
        (factor, change, kpi)
        for factor, change in (("demand.rate_per_hour", "30 \u2192 60"),
                               ("dispatch.policy", "nearest_idle \u2192 fcfs"))
        for kpi in ("throughput [% of demand]", "p95 lead time [s]", "throughput [orders/h]")}
    assert len(body) == 12  # each change at both levels of the other factor, 3 KPIs
    settings = dict(row for row in page.tables["settings"] if len(row) == 2 and row[0])
    assert settings["replications"] == "3 per design point (12 finished runs at 4 design points)"


def test_the_sweeps_query_hint_groups_by_its_own_factors(demand_sweep: Path,
                                                         tmp_path: Path) -> None:
    command, out = run_query_hint((demand_sweep / "report.html").read_text(encoding="utf-8"),
                                  tmp_path)
    assert "fleet.size" not in command
    assert "demand.rate_per_hour" in out and "dispatch.policy" in out
    assert "nearest_idle" in out and "fcfs" in out
    assert len(re.findall(r"\u2502\s+(30|60)\s+\u2502", out)) == 4  # one row per design point


def test_a_study_that_ran_only_some_combinations_of_levels_is_reported(
        demand_sweep: Path, tmp_path: Path) -> None:
    """A sizing search runs each demand level at its own fleet sizes, so not every
    combination of levels has runs (`make run` crashed on that: NaN replications). Here the
    sweep with one combination's runs taken away: the report is written and its statistics
    table lists the three combinations that ran, with their replications."""
    out = tmp_path / "out"
    shutil.copytree(demand_sweep, out)
    for run in (out / "runs").glob("*dispatch.policy=fcfs*"):
        if "demand.rate_per_hour=60" in run.name:
            shutil.rmtree(run)
    (out / "summary.parquet").unlink()
    (out / "stats.parquet").unlink()
    html_path, _ = write_report(out, pdf=False)
    html = html_path.read_text(encoding="utf-8")
    table = html[html.index('class="stats"'):]
    table = table[:table.index("</table>")]
    assert table.count("<tr>") - 1 == 3, table


def test_a_sweep_report_in_a_headless_browser(demand_sweep: Path, tmp_path: Path) -> None:
    html = (demand_sweep / "report.html").read_text(encoding="utf-8")
    check, _ = in_browser(html, tmp_path)
    assert check["title"] == "Sweep over demand rate per hour and dispatch policy: demand_policy"
    answer = " ".join(check["answer"].split())
    assert answer.startswith("What the sweep shows Raising demand rate per hour from 30 to 60")
    assert {i["key"] for i in check["images"]} >= {"layout", "kpis", "states-0"}
    assert all(i["ok"] and i["w"] > 100 for i in check["images"]), check["images"]


# ---- the templates, without a sweep --------------------------------------------------------


def test_idle_with_orders_waiting_is_shown_where_it_is_above_zero(tmp_path: Path) -> None:
    by = "idle_with_orders_waiting_pct_by_reason."
    summary = pd.DataFrame({
        "run_id": ["a", "b", "c", "d"], "status": ["ok"] * 4, "fleet.size": [1, 1, 2, 2],
        "idle_with_orders_waiting_pct": [30.0, 20.0, 0.0, 0.0],
        f"{by}battery_low": [30.0, 10.0, 0.0, 0.0], f"{by}link_lost": [0.0, 10.0, 0.0, 0.0],
        f"{by}status_poll": [0.0] * 4,
        "setup_warnings": ["charging.enabled is false but ..."] * 2 + ["", ""]})
    data = ReportData(tmp_path, {}, summary, ["fleet.size"], [], None, None, None)
    sec = section_idle_waiting(data)
    assert sec.runs_above_zero == 2
    assert sec.points is not None
    assert sec.points.header == ["fleet.size", "Idle with orders waiting [% of AGV time]",
                                 "battery_low", "link_lost"]  # reasons above zero somewhere
    assert sec.points.rows == [["1", "25", "20", "5"]]  # means; the 2-AGV point is all zero
    assert sec.warnings == ["charging.enabled is false but ... (2 of 4 runs)"]
    page = _Page(render_html(Report("t", "l", [], [], [sec])))
    assert page.tables["stats"][1] == ["1", "25", "20", "5"]
    text = " ".join("".join(page.text).split())
    assert "battery_low: SOC at or below P_050" in text
    quiet = section_idle_waiting(ReportData(tmp_path, {}, summary.iloc[2:], ["fleet.size"], [],
                                            None, None, None))
    assert quiet.points is None and quiet.warnings == []
    assert "In none of the 2 runs did an AGV stand Idle while an order waited" in " ".join(
        "".join(_Page(render_html(Report("t", "l", [], [], [quiet]))).text).split())


def test_the_kind_of_study_sets_the_question_and_the_first_screen(tmp_path: Path) -> None:
    """Without runs: a sweep over the fleet size with targets is a sizing sweep (its grid's
    smallest fleet meeting the target), without targets or over another factor a sweep."""
    summary = pd.DataFrame({
        "run_id": [f"r{i}" for i in range(6)], "status": ["ok"] * 6,
        "fleet.size": [1, 1, 2, 2, 3, 3], "replication": [0, 1] * 3,
        "throughput_pct_of_demand": [60.0, 62.0, 97.0, 97.2, 99.0, 99.5],
        "throughput_per_hour": [24.0, 25.0, 38.0, 39.0, 40.0, 40.0],
        "lead_time_p95_s": [900.0, 950.0, 300.0, 310.0, 200.0, 205.0]})
    target = Target(kpi="throughput_pct_of_demand", at_least=95)
    experiment = {"name": "e", "factors": {"fleet.size": [1, 2, 3]}, "replications": 2}
    sizing = ReportData(tmp_path, experiment, summary, ["fleet.size"], [target], None, None,
                        None)
    assert sizing.kind == "sizing sweep"
    assert question(sizing).startswith("How many AGVs does scenario ? on layout ? need to meet "
                                       "its targets (throughput at least 95 % of demand)?")
    _, statements, _ = recommendations(sizing)
    assert statements == ["2 AGVs is the smallest fleet of the grid that meets every target "
                          "with 95 % confidence (grid of the sweep; `fleet-sim size` refines "
                          "it)."]
    plain = ReportData(tmp_path, experiment, summary, ["fleet.size"], [], None, None, None)
    assert plain.kind == "sweep" and plain.compared_kpis == ["throughput_per_hour",
                                                             "lead_time_p95_s"]
    _, statements, _ = recommendations(plain)
    (first,) = statements  # one numeric factor: lowest to highest fleet
    assert first.startswith("Raising fleet size from 1 to 3 raises throughput by 15.5 "
                            "orders/h (") and "cuts p95 lead time by 722 s (" in first
    assert first.endswith("(paired over 2 replications, 95 % intervals).")


def _hostile_report() -> Report:
    png = b"\x89PNG\r\n\x1a\n"
    runs = RunsSection(runs=2, finished=1, failed=1, wall_s="3", database=EVIL, query=EVIL,
                       failed_runs=Table(["run", "status", "error"], [[EVIL, "failed", EVIL]]))
    return Report(
        title=f"Fleet sizing report: {EVIL}", lead=EVIL, statements=[EVIL], estimates=[EVIL],
        sections=[ScenarioSection(settings=Table([EVIL, ""], [[EVIL, EVIL]], "settings"),
                                  problem=EVIL, figures=[Figure(EVIL, EVIL, png)]), runs])


def test_every_value_the_templates_print_is_escaped() -> None:
    page = _Page(render_html(_hostile_report()))
    tags = [tag for tag, _ in page.tags]
    assert "script" not in tags
    assert tags.count("img") == 1  # the figure, none from the text
    assert not [attrs for _, attrs in page.tags if "onerror" in attrs]
    img = next(attrs for tag, attrs in page.tags if tag == "img")
    assert img["alt"] == EVIL and img["data-figure"] == EVIL  # attributes keep their quotes
    assert img["src"] == "data:image/png;base64,iVBORw0KGgo="
    text = "".join(page.text)
    # title (twice), lead, statement, estimate, header, cell x2, problem, caption,
    # failed run x2, database, query
    assert text.count(EVIL) == 14


def test_a_value_the_code_did_not_give_is_an_error() -> None:
    """StrictUndefined: a template printing a missing value fails instead of leaving a blank."""
    section = SimpleNamespace(title="Runs", template="runs.html.j2", figures=[], runs=2,
                              finished=2, failed=0, failed_runs=None, database="db",
                              gridlocked_runs=None, out_of_service_runs=None,
                              out_of_service_advice="", open_orders="", query="q")
    report = SimpleNamespace(title="t", lead="l", statements=[], estimates=[],
                             sections=[section], answer_title="Recommendation")
    with pytest.raises(UndefinedError, match="wall_s"):
        environment().get_template("report.html.j2").render(report=report)
    section.wall_s = "5"
    assert "2 runs: 2 finished, 0 failed" in " ".join(
        environment().get_template("report.html.j2").render(report=report).split())


def test_an_installed_package_has_every_template() -> None:
    """Every template file is matched by the package data of pyproject.toml."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = pyproject["tool"]["setuptools"]["package-data"]["fleet_sim.report"]
    package = ROOT / "fleet_sim" / "report"
    templates = {p for p in (package / "templates").rglob("*") if p.is_file()}
    assert len(templates) >= 3
    assert {p.relative_to(package / "templates").as_posix() for p in templates} == set(
        environment().list_templates())
    packaged = {p for pattern in patterns for p in package.glob(pattern)}
    assert templates - packaged == set()
