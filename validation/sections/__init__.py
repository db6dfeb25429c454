"""The report's sections, one module each, each with ``run(ctx) -> Section`` (or two such
functions), and :data:`SECTIONS`, the one table that orders them.

A new section is a module here and one row of :data:`SECTIONS`. The modules are imported by the
runner (:func:`validation.harness.runner.validate`) when their step runs, not here; what several
sections compute alike lives in :mod:`validation.comparisons`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

__all__ = ["Step", "SECTIONS"]


class Step(NamedTuple):
    """One section of the report and its place in each run's order.

    ``target`` writes the section: ``"module"`` (its ``run(ctx) -> Section``), ``"module:function"``
    or the function itself; ``title`` is its heading. ``quick`` and ``full`` are its place in the
    order the steps *run* in a quick and in a full run (lowest first; ties run in table order);
    the report reads in table order whatever the run order.
    """

    target: str | Callable[[Any], Any]
    title: str
    quick: int = 0
    full: int = 0


#: The report's sections in reading order, with their run order. Quick: the cheap, exact-heavy
#: steps first, so that a slow solver cannot crowd them out of the time budget. Full: the Monte
#: Carlo-only steps (beyond the paper, the paper's rings) early, while the worker process solves
#: the Fokker-Planck problems the later steps announced (``prefetch``). The identities last in
#: both: they check every result the other steps computed.
SECTIONS: tuple[Step, ...] = (
    Step("validation.sections.crosscheck", "Cross-checks", quick=3, full=5),
    Step("validation.sections.errorbars", "Error bars: Monte Carlo coverage and Fokker-Planck bounds", quick=7, full=7),
    Step("validation.sections.paper", "Paper comparison", quick=4, full=4),
    Step("validation.sections.beyond", "Beyond the paper", quick=5, full=3),
    Step("validation.sections.stress:run_exact", "Stress tests: exact solver", quick=1, full=1),
    Step("validation.sections.stress:run_solvers", "Stress tests: Fokker-Planck and Monte Carlo", quick=6, full=6),
    Step("validation.sections.figures:run_exact", "The paper's figures: harmonic scenes (exact)", quick=2, full=2),
    Step("validation.sections.figures:run_solvers",
         "The paper's figures: nonlinear scenes (Fokker-Planck, Monte Carlo)", quick=8, full=8),
    Step("validation.sections.benchmarks", "Benchmarks: error versus wall time", quick=9, full=9),
    Step("validation.sections.identities",
         "Stationary identities, docs/model.md §2 (every solver, every result of this run)", quick=10, full=10),
)
