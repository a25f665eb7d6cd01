"""`fleet-sim report RESULTS_DIR`: the `Report` of fleet_sim.report.report as a self-contained
HTML page (Jinja2 templates in ``templates/``) and a PDF, for a planner to hand on.

Decisions:

* Escaping by construction: the templates are rendered with ``autoescape=True`` (for every
  template: ``select_autoescape`` matches on the name's last suffix, and ours end in ``.j2``), so
  every value a template prints is HTML-escaped, names from user files included. Nothing is
  marked safe: the one value that is not plain text, a figure's data: URI, is base64, which has
  no character to escape. The report has no scripts. The replay page's scripts are our own
  plain files in ``static/`` (`static_script`): each is marked safe whole, after checking it
  cannot end its script element early (no ``</script``, no ``<!--``), as a Jinja ``{% raw %}``
  include did before; data never goes through it.
* ``StrictUndefined``: a template that prints a value the code did not give fails loudly
  instead of leaving a blank in the page.
* The PDF is written with matplotlib (a text page with the recommendation and each section's
  plain text, then every figure); it needs no HTML engine.
"""

from __future__ import annotations

from functools import cache
from importlib import resources
from pathlib import Path

from jinja2 import Environment, PackageLoader, StrictUndefined
from markupsafe import Markup

from fleet_sim.report import figures as figs
from fleet_sim.report.report import Report, build_report
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
