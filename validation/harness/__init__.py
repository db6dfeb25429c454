"""The validation pipeline: :mod:`.runner` runs the report's sections (in the order of
:data:`validation.sections.SECTIONS`) and writes the report,
:mod:`.checks` holds the pass/fail/skip logic and the shared solve cache, :mod:`.report` the
report's data model and its Markdown/HTML writers."""

from __future__ import annotations

from .checks import CheckResult, Context, Outcome, SolveCache, agree, expect
from .report import Figure, Report, Section, Table, summary_text, write_html, write_markdown
from .runner import run_cli, validate

__all__ = ["CheckResult", "Context", "Outcome", "SolveCache", "agree", "expect", "Figure", "Report", "Section",
           "Table", "summary_text", "write_html", "write_markdown", "validate", "run_cli"]
