"""Comparisons the report's sections draw on, each measuring one solver against another solver
or a reference and returning numbers, figures and verdicts for a section to show:

* :mod:`.coverage`: do the Monte Carlo error bars cover another solver's value as often as they
  say (the error-bar section);
* :mod:`.kinkdensity`: the kink's density near its trap, Fokker--Planck (or the exact-flow
  construction) against Monte Carlo (the cross-checks' figure; also a study's measure);
* :mod:`.strongkink`: the product's Monte Carlo against the exact-flow construction where
  Fokker--Planck declines (the cross-checks and the stress tests).

The modules are imported by the sections that use them, not here.
"""

from __future__ import annotations

__all__: list[str] = []
