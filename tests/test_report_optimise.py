"""The optimise report (`fleet-sim report` on a `fleet-sim optimise` folder): the answer first in
a planner's words, price against each target, every design, the chosen design's layout, what
each target costs; a folder where no design meets names the binding target; the layout section
says so when the experiment file is gone and the rest stands; names from the file escaped; the
page in a real headless browser."""

from __future__ import annotations

import html as html_lib
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleet_sim.cli import main
from fleet_sim.config.experiment import load_experiment
from fleet_sim.report.optimise_report import build_optimise_report
from fleet_sim.report.render import write_report
from fleet_sim.report.sections.compare_section import CompareSection
from fleet_sim.study.optimise import optimise
from fleet_sim.study.optimise_words import answer_statements, guarantee_sentence
from tests.conftest import ROOT, in_browser, write_yaml

DESIGN_FILE = ROOT / "experiments" / "tiny_loop_design.yaml"
EVIL = "2 s handling <script>alert(1)</script> & co"


@pytest.fixture(scope="module")
def optimised(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """experiments/tiny_loop_design.yaml optimised (the answer: 1 AGV, fast handling, 130 k)
    and its report written."""
    out = tmp_path_factory.mktemp("optimise") / "out"
    optimise(load_experiment(DESIGN_FILE), out, workers=2, quiet=True)
    write_report(out)
    return out


@pytest.fixture(scope="module")
def impossible(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same space with a p95 lead time no design reaches (10 s, tolerance 5 s), a layout
    option described with markup: no design meets."""
    folder = tmp_path_factory.mktemp("impossible")
    data = yaml.safe_load(DESIGN_FILE.read_text(encoding="utf-8"))
    data["scenario"] = str(ROOT / "experiments" / data["scenario"])
    data["targets"] = [{"kpi": "throughput_pct_of_demand", "at_least": 95},
                       {"kpi": "lead_time_p95_s", "at_most": 10}]
    data["optimise"]["tolerance"]["lead_time_p95_s"] = 5
    data["optimise"]["layout_decisions"]["handling"]["fast"]["description"] = EVIL
    file = write_yaml(folder / "impossible.yaml", data)
    out = folder / "out"
    optimise(load_experiment(file), out, workers=2, quiet=True)
    return out


def page(out: Path) -> str:
    return (out / "report.html").read_text(encoding="utf-8")


def text_of(html: str) -> str:
    """The page's text, tags dropped and entities unescaped, spaces collapsed."""
    return " ".join(html_lib.unescape(re.sub(r"<[^>]+>", " ", html)).split())


def answer_box(html: str) -> str:
    found = re.search(r'<div class="rec" id="answer">(.*?)</div>', html, re.S)
    assert found, html[:2000]
    return text_of(found.group(1))


# ---- an answer ---------------------------------------------------------------------------------


def test_the_first_screen_answers_in_words(optimised: Path) -> None:
    box = answer_box(page(optimised))
    assert "The cheapest system that meets both targets (throughput at least 95 % of demand; " \
           "p95 lead time at most 600 s): 1 AGV" in box
    assert "2 s handling at both stations: 130 kEUR." in box
    assert re.search(r"Over \d+ replications it reaches throughput [\d.]+ % of demand "
                     r"\([\d.]+ to [\d.]+\) and p95 lead time [\d.]+ s", box), box
    # the one cheaper design, and why it is not the answer
    assert "No cheaper design does: the next cheaper design, 1 AGV, handling as it is " \
           "(100 kEUR), is ruled out: " in box
    assert "With probability at least 95 %, the design named meets every target (within its " \
           "tolerance: throughput within" in box
    assert re.search(r"\d+ runs used, against \d+ for the full grid \(5 designs at \d+ "
                     r"replications each\)", box), box
    assert "lead_time_p95_s" not in box  # KPIs in words, not by their keys


def test_the_report_has_every_section(optimised: Path) -> None:
    html = page(optimised)
    text = text_of(html)
    for heading in ("Price against each target", "Every design", "The chosen design's layout",
                    "What each target costs", "How the answer was found"):
        assert f"<h2>{heading}</h2>" in html.replace("&#39;", "'"), heading
    assert 'data-figure="price_against_targets"' in html
    assert 'data-figure="layout_answer"' in html
    # every design a row: its words, its decisions, its price, its verdict
    rows = re.findall(r"<tr><td>(.*?)</td><td>(.*?)</td><td>(.*?)</td><td>(.*?)</td>", html)
    designs = {html_lib.unescape(r[1]): (html_lib.unescape(r[0]), r[2], r[3]) for r in rows}
    assert designs["fleet.size=1, handling=fast"] == (
        "1 AGV, 2 s handling at both stations", "130", "meets (the answer)")
    assert designs["fleet.size=1, handling=as_it_is"][1:] == ("100", "ruled out")
    assert {"fleet.size=2, handling=as_it_is", "fleet.size=2, handling=fast",
            "fleet.size=3, handling=as_it_is", "fleet.size=3, handling=fast"} <= set(designs)
    assert "p95 lead time [s]: mean (95 % interval)" in text
    # the layout change named: the stations whose handling it changes
    assert "changed or new places: DROP, PICK" in text
    # what each target costs: each target relaxed by its tolerance
    assert "p95 lead time at most 600 s p95 lead time at most 660 s" in text


def test_the_pdf_has_a_text_page_and_the_figures(optimised: Path) -> None:
    pdf = (optimised / "report.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page\b", pdf)) == 3  # text, price chart, layout


def test_report_command_on_an_optimise_folder(optimised: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["report", str(optimised), "--no-pdf"]) == 0
    assert str((optimised / "report.html").resolve()) in capsys.readouterr().out


CHECK = """<script>
window.addEventListener('load', () => {
  const pre = document.createElement('pre');
  pre.id = 'img-check';
  const first = document.querySelector('#answer p.answer');
  pre.textContent = JSON.stringify({
    images: Array.from(document.images).map(i => ({key: i.dataset.figure,
      ok: i.complete && i.naturalWidth > 0, w: i.naturalWidth})),
    answer: Array.from(document.querySelectorAll('#answer p')).map(p => p.textContent),
    first_bottom: first ? first.getBoundingClientRect().bottom : null,
    screen: window.innerHeight, scripts: document.scripts.length,
    title: document.title});
  document.body.appendChild(pre);
});
</script></body>"""


def test_the_optimise_report_in_a_headless_browser(optimised: Path, tmp_path: Path) -> None:
    check, _ = in_browser(page(optimised), tmp_path, CHECK)
    assert check["title"] == "Cheapest design: tiny_loop_design"
    assert check["answer"][0].startswith("The cheapest system that meets both targets")
    assert "130 kEUR" in check["answer"][0]
    assert 0 < check["first_bottom"] <= check["screen"]  # the answer on the first screen
    assert {i["key"] for i in check["images"]} == {"price_against_targets", "layout_answer"}
    assert all(i["ok"] and i["w"] > 300 for i in check["images"]), check["images"]
    assert check["scripts"] == 1  # the check's own: the report has none


# ---- no design meets ---------------------------------------------------------------------------


def test_no_design_meets_names_the_binding_target(impossible: Path) -> None:
    write_report(impossible)
    html = page(impossible)
    box = answer_box(html)
    assert box.startswith("Answer No design in the space meets both targets (throughput at "
                          "least 95 % of demand; p95 lead time at most 10 s) with 95 % "
                          "confidence.")
    assert "The target that binds is p95 lead time at most 10 s: the design that comes " \
           "closest, 3 AGVs, " in box
    assert "no design in the space meets every target by more than its tolerance" in box
    assert "<h2>The closest design&#39;s layout</h2>" in html
    assert "no design meets the relaxed targets" in text_of(html)
    # the option's description is text, never markup
    assert "<script>alert" not in html and "&lt;script&gt;alert(1)&lt;/script&gt; &amp; co" in html


def test_the_layout_section_says_so_when_the_experiment_file_is_gone(impossible: Path) -> None:
    file = impossible.parent / "impossible.yaml"
    kept = file.read_text(encoding="utf-8")
    file.unlink()
    try:
        report = build_optimise_report(impossible)
    finally:
        file.write_text(kept, encoding="utf-8")
    try:
        layout = next(s for s in report.sections
                      if isinstance(s, CompareSection) and "layout" in s.heading)
        assert isinstance(layout, CompareSection)
        assert not layout.figures
        assert "could not be read again" in layout.paragraphs[0]
        assert "the rest of the report stands" in layout.paragraphs[0]
        # the rest stands, designs by their labels
        assert report.statements[0].startswith("No design in the space meets both targets")
        assert "fleet.size=3, handling=fast" in report.statements[1]
        assert any(f.key == "price_against_targets" for f in report.figures())
    finally:
        report.close()


# ---- the sentences, on a made-up folder ---------------------------------------------------------


def _row(kpi: str, bound: float, at_least: bool, mean: float | None, low: float | None = None,
         high: float | None = None) -> dict[str, Any]:
    meets = None if mean is None else (mean >= bound if at_least else mean <= bound)
    return {"kpi": kpi, "target": "", "bound": bound, "at_least": at_least, "mean": mean,
            "ci_low": low, "ci_high": high, "n": 0 if mean is None else 10,
            "meets_bound": meets}


def _design(index: int, agvs: int, price: float, verdict: str, lead: float | None,
            low: float | None = None, high: float | None = None) -> dict[str, Any]:
    return {"index": index, "label": f"fleet.size={agvs}, chargers=fifth",
            "choices": {"fleet.size": agvs, "layout:chargers": "fifth"}, "price": price,
            "verdict": verdict, "reason": "", "inferred": False,
            "replications": 0 if lead is None else 10, "decided_at": None, "check": None,
            "targets": [_row("throughput_pct_of_demand", 95, True,
                             None if lead is None else 99.0, 98.0, 100.0),
                        _row("lead_time_p95_s", 600, False, lead, low, high)]}


def test_one_agv_fewer_is_named_with_the_target_it_misses() -> None:
    designs = [_design(0, 14, 666_000, "fails", 702.0, 650.0, 754.0),
               _design(1, 15, 704_000, "fails", 631.0, 604.0, 658.0),
               _design(2, 16, 742_000, "meets", 540.0, 520.0, 560.0),
               _design(3, 17, 780_000, "not needed", None)]
    document = {"currency": "EUR", "confidence": 0.95, "stopped": None,
                "answer": {"design": designs[2]["label"]}, "undecided_cheaper": [],
                "designs": designs}
    words = [f"{d['choices']['fleet.size']} AGVs, a fifth charger at C05" for d in designs]
    said = answer_statements(document, words)
    assert said[0] == ("The cheapest system that meets both targets (throughput at least 95 % "
                       "of demand; p95 lead time at most 600 s): 16 AGVs, a fifth charger at "
                       "C05: 742,000 EUR.")
    assert said[2] == ("No cheaper design does: the same system with 15 AGVs (704,000 EUR) "
                       "misses p95 lead time 631 s (604 to 658). The other cheaper design "
                       "fails.")


def test_undecided_cheaper_designs_and_a_stopped_search_are_said() -> None:
    designs = [_design(0, 14, 666_000, "fails", 702.0, 650.0, 754.0),
               _design(1, 15, 704_000, "undecided", 601.0, 560.0, 642.0),
               _design(2, 16, 742_000, "meets", 540.0, 520.0, 560.0)]
    designs[0]["reason"] = "fails by more_agvs_never_worse: 15 AGVs with the same choices fail"
    designs[0]["inferred"] = True
    document = {"currency": "EUR", "confidence": 0.95, "stopped": None,
                "answer": {"design": designs[2]["label"]},
                "undecided_cheaper": [designs[1]["label"]], "designs": designs}
    words = [f"{d['choices']['fleet.size']} AGVs" for d in designs]
    said = answer_statements(document, words)
    assert said[2].startswith("No cheaper design is shown to meet them: the same system with "
                              "15 AGVs (704,000 EUR) is not decided at 10 replications: "
                              "throughput 99 % of demand (98 to 100) and p95 lead time 601 s "
                              "(560 to 642).")
    assert said[2].endswith("The other cheaper design fails.")
    assert said[3] == ("Not decided at the replication limit, and cheaper: 15 AGVs (more "
                       "replications could still tell).")
    guarantee = guarantee_sentence({**document, "tolerance": {"lead_time_p95_s": 25}})
    assert guarantee.endswith("no cheaper design meets them all by more than that tolerance, "
                              "but for the cheaper design undecided at the replication limit.")
    stopped = {**document, "answer": None, "undecided_cheaper": [], "closest": None,
               "stopped": "the design search would need more than 10000 runs"}
    said = answer_statements(stopped, words)
    assert said[0] == ("The search stopped before it could name an answer: the design search "
                       "would need more than 10000 runs")
    assert said[1].startswith("No design in the space meets both targets")
