"""Validation of fpe-harvester: cross-checks, the paper's numbers, stress tests, benchmarks
and the report written by ``harvester validate`` (or ``python -m validation``).

* :mod:`.harness`: the pipeline (runner, checks, report);
* :mod:`.sections`: one module per section of the report, and the table that orders them;
* :mod:`.comparisons`: what sections compute alike (error-bar coverage, the kink's density, the
  strong kink's second Monte Carlo construction);
* :mod:`.references`: independent references and the table of long runs;
* :mod:`.studies`: the benchmarks and design studies by subject, each
  ``python -m validation.studies.<subject>.<name>``.
"""

from __future__ import annotations

from .harness.checks import CheckResult, Context, Outcome, SolveCache, agree, expect
from .harness.report import Figure, Report, Section, Table, summary_text, write_html, write_markdown
from .harness.runner import run_cli, validate

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
    "validate",
    "run_cli",
]
