"""The section of a comparison's or an optimise report: a heading, paragraphs, tables and
figures, all in one template (templates/sections/compare_section.html.j2).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from fleet_sim.report.content import Section, Table


@dataclass(kw_only=True)
class CompareSection(Section):
    """A section of the comparison report: paragraphs, tables, figures (one template)."""

    title: ClassVar[str] = ""
    template: ClassVar[str] = "compare_section.html.j2"
    heading: str
    paragraphs: list[str] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
