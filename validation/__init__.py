"""Validation of fpe-harvester: cross-checks, the paper's numbers, stress tests, benchmarks
and the report written by ``harvester validate`` (or ``python -m validation``).

Steps (each ``run(ctx) -> Section``, or two such functions): :mod:`.crosscheck`, :mod:`.paper`,
:mod:`.beyond`, :mod:`.stress`, :mod:`.figures` (the shipped scenes), :mod:`.bench.combined`
(runs the benchmark modules of :mod:`.bench`); :mod:`.runner` orders them and writes the
report (:mod:`.report`); :mod:`.checks` holds the pass/fail/skip logic and
:mod:`.references` the independent references of the exact solver (40-digit Lyapunov solve,
rational arithmetic).
"""

from __future__ import annotations

from .checks import CheckResult, Context, Outcome, SolveCache, agree, expect
from .report import Figure, Report, Section, Table, summary_text, write_html, write_markdown
from .runner import run_cli, validate

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
