"""Do the Monte Carlo error bars mean what they say? Coverage against much longer runs.

Over a grid of cases, many independent Monte Carlo results (different seeds) are compared
with a reference: the exact solver for harmonic rings, else a Monte Carlo run with a
tolerance ``REF_FACTOR`` times tighter. For each result and quantity
:math:`q \\in \\{\\eta, V^2, P_{in}\\}`

.. math::

    z = \\frac{q - q_{ref}}{\\sqrt{\\delta q^2 + \\delta q_{ref}^2}},

and the fractions of :math:`|z| < 1, 2, 3` are the coverage; for honest one-standard-error
bars they are close to 68.3 / 95.4 / 99.7 %. The errors fold in the time-step bias estimate
(:class:`montecarlo.MonteCarlo`), so coverage above these fractions means conservative
bars, below means optimistic ones. :func:`mc_coverage` runs the quick subset (seconds, for
CI) or the full grid (minutes, the report's).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpe_harvester import Harvester, Stats, Status, solve

__all__ = ["CoverageCase", "QUICK_CASES", "FULL_CASES", "NORMAL_COVERAGE", "COVERAGE_LIMITS", "mc_coverage"]

#: Fractions of a normal variable within 1, 2, 3 standard deviations.
NORMAL_COVERAGE = (0.6827, 0.9545, 0.9973)
#: Limits on the pooled fractions within 1, 2, 3 errors, by ``quick``: (lowest and highest
#: at 1, lowest at 2, lowest at 3). Quick runs have few results, so wider limits. Honest bars
#: give 0.683 / 0.954 / 0.997; bars wrong by 2x give about 0.38 / 0.68 / 0.87 (too small) or
#: 0.95 / 1.0 / 1.0 (too large).
COVERAGE_LIMITS = {True: (0.45, 0.95, 0.80, 0.93), False: (0.55, 0.92, 0.88, 0.97)}
#: How much tighter the reference runs' tolerance is than the results'.
REF_FACTOR = 10.0
_QUANTITIES = ("eta", "V2", "Pin")


@dataclass(frozen=True)
class CoverageCase:
    """One problem of the coverage grid.

    Attributes
    ----------
    label : str
        Short description for tables.
    h : Harvester
        The problem.
    options : dict
        Monte Carlo settings of the results (the reference uses them with ``tol / REF_FACTOR``).
    reference : Stats or None
        A reference computed elsewhere (e.g. a Fokker--Planck solve); None: the exact solver
        for a harmonic ring, else a Monte Carlo run ``REF_FACTOR`` times tighter.
    """

    label: str
    h: Harvester
    options: dict[str, Any]
    reference: Stats | None = None


_QUICK_OPTS = {"tol": 0.05, "paths": 8, "t_run": 50.0, "min_replicas": 32, "progress": False}
_FULL_OPTS = {"tol": 1e-2, "progress": False}

QUICK_CASES = (
    CoverageCase("harmonic N = 1, a = 0.5", Harvester.build(a=0.5), _QUICK_OPTS),
    CoverageCase("harmonic N = 3, k = -0.2", Harvester.build(a=0.5, N=3, k=-0.2), _QUICK_OPTS),
    CoverageCase("n = 3, a = 0.5", Harvester.build(a=0.5, n=3.0), _QUICK_OPTS),
)

FULL_CASES = (
    CoverageCase("harmonic N = 1, a = 0.5", Harvester.build(a=0.5), _FULL_OPTS),
    CoverageCase("harmonic N = 3, k = -0.3", Harvester.build(a=0.5, N=3, k=-0.3), _FULL_OPTS),
    CoverageCase("n = 1, a = 0.5", Harvester.build(a=0.5, n=1.0), _FULL_OPTS),
    CoverageCase("n = 1, a = 1", Harvester.build(a=1.0, n=1.0), _FULL_OPTS),
    CoverageCase("n = 1.5, a = 1", Harvester.build(a=1.0, n=1.5), _FULL_OPTS),
    CoverageCase("n = 3, a = 0.5", Harvester.build(a=0.5, n=3.0), _FULL_OPTS),
    CoverageCase("n = 8, a = 0.5", Harvester.build(a=0.5, n=8.0), _FULL_OPTS),
    CoverageCase("n = 3, N = 3, k = -0.5", Harvester.build(a=0.5, n=3.0, N=3, k=-0.5), _FULL_OPTS),
    CoverageCase("n = 4, N = 3, k = -0.5", Harvester.build(a=0.5, n=4.0, N=3, k=-0.5), _FULL_OPTS),
)


def _reference(case: CoverageCase, seed: int) -> Stats:
    if case.reference is not None:
        return case.reference
    if case.h.is_linear:
        return solve(case.h, "exact")
    opts = {**case.options, "tol": case.options["tol"] / REF_FACTOR, "max_time": 3600.0}
    return solve(case.h, "mc", seed=seed, **opts)


def mc_coverage(quick: bool = True, runs: int | None = None, seed: int = 0,
                cases: tuple[CoverageCase, ...] | None = None) -> dict[str, Any]:
    """Coverage of the Monte Carlo error bars over a grid of cases.

    Parameters
    ----------
    quick : bool
        :data:`QUICK_CASES` with 12 runs each (about ten seconds), else :data:`FULL_CASES`
        with 20 runs each (tens of minutes).
    runs : int, optional
        Results per case, >= 2 (overrides the default).
    seed : int
        First seed; result ``i`` of a case uses ``seed + i``, its reference ``seed + 10**6``.
    cases : tuple of CoverageCase, optional
        Replaces the grid.

    Returns
    -------
    dict
        ``fractions`` (quantity -> fractions within 1, 2, 3 errors), ``fractions_all``
        (pooled over quantities), ``expected`` (:data:`NORMAL_COVERAGE`), ``count``, and
        ``cases``: per case the reference, the z values per quantity, the statuses, the
        median relative error and the wall time.
    """
    if cases is None:
        cases = QUICK_CASES if quick else FULL_CASES
    runs = runs if runs is not None else (12 if quick else 20)
    if runs < 2:
        raise ValueError(f"runs must be an integer >= 2, got {runs!r}")
    out_cases = []
    zs: dict[str, list[float]] = {q: [] for q in _QUANTITIES}
    for case in cases:
        t0 = time.perf_counter()
        ref = _reference(case, seed + 10**6)
        if ref.status not in (Status.STABLE,):
            raise RuntimeError(f"coverage reference for {case.label} is {ref.status.value}: {ref.message}")
        z_case: dict[str, list[float]] = {q: [] for q in _QUANTITIES}
        statuses, rel = [], []
        for i in range(runs):
            r = solve(case.h, "mc", seed=seed + i, **case.options)
            statuses.append(r.status.value)
            rel.append(r.eta_err / abs(r.eta))
            for q in _QUANTITIES:
                (v, dv), (vr, dvr) = r.value(q), ref.value(q)
                z = (v - vr) / math.hypot(dv, dvr)
                z_case[q].append(float(z))
                zs[q].append(float(z))
        out_cases.append({
            "label": case.label, "reference_method": ref.method, "reference_eta": ref.eta,
            "reference_eta_err": ref.eta_err, "z": z_case, "statuses": statuses,
            "median_rel_err_eta": float(np.median(rel)), "wall_s": time.perf_counter() - t0,
        })

    def fractions(values: list[float]) -> list[float]:
        a = np.abs(np.asarray(values))
        return [float((a < k).mean()) for k in (1, 2, 3)]

    pooled = [z for q in _QUANTITIES for z in zs[q]]
    return {
        "quick": quick, "runs": runs, "count": len(zs["eta"]), "expected": list(NORMAL_COVERAGE),
        "fractions": {q: fractions(zs[q]) for q in _QUANTITIES},
        "fractions_all": fractions(pooled), "cases": out_cases,
    }
