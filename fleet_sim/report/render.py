"""`fleet-sim report RESULTS_DIR`: the `Report` of a study, a comparison or an optimise search
(fleet_sim.report.study_report, compare_report, optimise_report) as a self-contained HTML page
(Jinja2 templates in ``templates/``) and a PDF, for a planner to hand on.

Every value a template prints is HTML-escaped (autoescape) and nothing is marked safe but
our own scripts, so names from user files stay text.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path

from jinja2 import Environment, PackageLoader, StrictUndefined
from markupsafe import Markup

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Report
from fleet_sim.report.study_report import build_report
from userfiles.writing import atomic_path, write_text_atomic


@cache
def environment() -> Environment:
    """The report's Jinja2 environment: templates from the package, autoescape on."""
    env = Environment(loader=PackageLoader("fleet_sim.report", "templates"),
                      autoescape=True, undefined=StrictUndefined, trim_blocks=True,
                      lstrip_blocks=True, keep_trailing_newline=True)
    # `tojson` (the replay page's data): keys sorted for identical bytes, no spaces for size
    env.policies["json.dumps_kwargs"] = {"sort_keys": True, "separators": (",", ":"),
                                         "allow_nan": False}
    return env


@cache
def static_script(name: str) -> Markup:
    """The text of our script ``static/<name>``, to inline in a <script> element."""
    text = resources.files("fleet_sim.report").joinpath("static", name).read_text(
        encoding="utf-8")
    lowered = text.lower()
    if "</script" in lowered or "<!--" in lowered:
        raise ValueError(f"static/{name} would end its <script> element early")
    return Markup(text)


def render_html(report: Report) -> str:
    """The report as one HTML page (figures embedded)."""
    return environment().get_template(report.template).render(report=report)


def write_pdf(report: Report, path: Path) -> None:
    """A text page (recommendation, each section's text), then every figure, one a page."""
    from matplotlib.backends.backend_pdf import PdfPages

    lines = [report.answer_title.upper(), *report.statements, "", *report.estimates, ""]
    for sec in report.sections:
        if sec.text:  # a comparison's or optimise report's section has its own heading
            heading = str(getattr(sec, "heading", "")) or sec.title
            lines += [heading.upper(), *sec.text, ""]
    with PdfPages(path) as pdf:
        page = figs.text_page(report.title, lines)
        pdf.savefig(page)
        figs.close(page)
        for fig in report.figures():
            if fig.pdf_figure is not None:
                pdf.savefig(fig.pdf_figure)


def write_report(out_dir: Path, pdf: bool = True) -> tuple[Path, Path | None]:
    """Write report.html (and report.pdf) into `out_dir`; returns their paths. A folder of
    `fleet-sim compare` (with compare.json) gets the comparison report, one of `fleet-sim
    optimise` (with optimise.json) the optimise report."""
    from fleet_sim.report.compare_report import build_compare_report, is_compare_folder
    from fleet_sim.report.optimise_report import build_optimise_report, is_optimise_folder

    if is_compare_folder(out_dir):
        report = build_compare_report(out_dir)
    elif is_optimise_folder(out_dir):
        report = build_optimise_report(out_dir)
    else:
        report = build_report(out_dir)
    try:
        html_path = out_dir / "report.html"
        write_text_atomic(html_path, render_html(report))
        pdf_path: Path | None = None
        if pdf:
            pdf_path = out_dir / "report.pdf"
            with atomic_path(pdf_path) as tmp:
                write_pdf(report, tmp)
    finally:
        report.close()
    return html_path, pdf_path
