"""The report's sections, one module each, each with ``run(ctx) -> Section`` (or two such
functions): :mod:`.crosscheck`, :mod:`.errorbars` (with :mod:`.coverage`), :mod:`.paper`,
:mod:`.beyond`, :mod:`.stress`, :mod:`.figures` (the shipped scenes) and :mod:`.benchmarks`;
:mod:`.kinkdensity` draws the cross-check section's kink figure. The modules are imported by
the runner when their step runs, not here."""

from __future__ import annotations

__all__: list[str] = []
