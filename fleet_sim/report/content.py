"""What the report templates are given: figures, tables and sections of plain data, and the
`Report` that holds them (a study's, a comparison's or an optimise report's); render.py writes
it as HTML and PDF.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar

from fleet_sim.report import figures as figs


@dataclass(frozen=True)
class Figure:
    """One figure: PNG for the HTML page, and the matplotlib figure for the PDF."""

    key: str
    caption: str
    png: bytes
    pdf_figure: Any = None
    in_html: bool = True
    """False: for the PDF only (the page shows the same otherwise, such as an inline SVG)."""

    @property
    def data_uri(self) -> str:
        """The PNG as a data: URI (base64 has no character HTML needs to escape)."""
        return "data:image/png;base64," + base64.b64encode(self.png).decode("ascii")


@dataclass(frozen=True)
class Table:
    """A table of plain-text cells (the template escapes them)."""

    header: list[str]
    rows: list[list[str]]
    css_class: str = ""


@dataclass(kw_only=True)
class Section:
    """A section of the report; each subclass has its template in templates/sections/."""

    title: ClassVar[str]
    template: ClassVar[str]
    figures: list[Figure] = field(default_factory=list)
    text: list[str] = field(default_factory=list)
    """Plain text for the PDF's text page."""


@dataclass(frozen=True)
class Report:
    """Everything the report shows, as plain data."""

    title: str
    lead: str
    statements: list[str]
    """The recommendation, one statement per series (bold in the page)."""
    estimates: list[str]
    sections: list[Section]
    template: str = "report.html.j2"
    """The page's template: a sweep's or sizing's report, or a comparison's (compare.html.j2)."""
    answer_title: str = "Recommendation"
    """The heading of the first screen's box (and of the PDF's first lines)."""

    def figures(self) -> Iterator[Figure]:
        for sec in self.sections:
            yield from sec.figures

    def close(self) -> None:
        """Free the matplotlib figures kept for the PDF."""
        for fig in self.figures():
            figs.close(fig.pdf_figure)


def png_figure(key: str, caption: str, fig: Any) -> Figure:
    """A matplotlib figure as a `Figure`: its PNG for the page, the figure kept for the PDF."""
    return Figure(key, caption, figs.png_bytes(fig), fig)
