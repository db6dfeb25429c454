"""Validation of fpe-harvester: cross-checks, the paper's numbers, stress tests, benchmarks
and the report written by ``harvester validate``.
"""

from __future__ import annotations

from .checks import CheckResult, Context, Outcome, SolveCache, agree, expect
from .report import Figure, Report, Section, Table, summary_text, write_html, write_markdown

__all__ = [
    "CheckResult",
    "Context",
    "Outcome",
    "SolveCache",
    "agree",
    "expect",
    "Figure",
    "Report",
    "Section",
    "Table",
    "summary_text",
    "write_html",
    "write_markdown",
]
