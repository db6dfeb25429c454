"""Do the Monte Carlo error bars mean what they say? Coverage against another solver.

Over a grid of cases, many independent Monte Carlo results (different seeds) are compared
with a reference from a different solver wherever one exists: the exact solver for harmonic
rings, the Fokker--Planck solver certified ``REF_FACTOR`` times tighter for single nonlinear
units; only where no other solver answers (nonlinear rings, the kink at a = 2) an independent
Monte Carlo run (another seed) ``REF_FACTOR`` times tighter. For each result and quantity
:math:`q \\in \\{\\eta, V^2, P_{in}\\}`

.. math::

    z = \\frac{q - q_{ref}}{\\sqrt{\\delta q^2 + \\delta q_{ref}^2}},

and the fractions of :math:`|z| < 1, 2, 3` are the coverage; for honest one-standard-error
bars they are close to 68.3 / 95.4 / 99.7 %. The errors fold in the time-step bias estimate
(:class:`montecarlo.MonteCarlo`), so coverage above these fractions means conservative
bars, below means optimistic ones. The fractions are checked per quantity against two-sided
limits from the binomial distribution of the number of results (:func:`binomial_limits`), so
that bars too wide fail as well as bars too narrow; a run must count enough results for that
(:func:`min_results`).
:func:`mc_coverage` runs the quick subset (seconds, for CI) or the full grid (minutes, the
report's).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpe_harvester import Harvester, Stats, Status, solve

__all__ = ["CoverageCase", "QUICK_CASES", "FULL_CASES", "NORMAL_COVERAGE", "mc_coverage",
           "binomial_limits", "coverage_checks", "usable_reference", "ALPHA", "REF_MAX_SHARE", "MISSCALED",
           "min_results", "detection"]

#: Seeds per case: the results of different cases use different seeds. With the same seeds in
#: every case, the cases' results were driven by the same noise and correlated, while the
#: binomial limits assume independent results (measured: seed 2019 gave |z| = 4.2-5.7 in three
#: cases at once, harmonic N = 1, n = 1 at a = 0.5 and n = 1.5 at a = 1).
CASE_SEEDS = 1000

#: Fractions of a normal variable within 1, 2, 3 standard deviations.
NORMAL_COVERAGE = (0.6827, 0.9545, 0.9973)
#: How much tighter the reference runs' tolerance is than the results'.
REF_FACTOR = 10.0
#: Two-sided probability that one fraction of honest bars falls outside its binomial limits.
ALPHA = 1e-3
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
        A reference computed elsewhere; None: from ``ref_method``.
    ref_method : str
        ``"auto"``: the exact solver for a harmonic ring, Fokker--Planck (``tol / REF_FACTOR``)
        for a single nonlinear unit, an independent Monte Carlo run (``tol / REF_FACTOR``,
        another seed) for a nonlinear ring; or one of ``"exact"``, ``"fpe"``, ``"mc"``.
    """

    label: str
    h: Harvester
    options: dict[str, Any]
    reference: Stats | None = None
    ref_method: str = "auto"
    runs: int | None = None

    @property
    def method(self) -> str:
        """The reference's solver."""
        if self.reference is not None:
            return self.reference.method
        if self.ref_method != "auto":
            return self.ref_method
        return "exact" if self.h.is_linear else "fpe" if self.h.N == 1 else "mc"


#: Results per case of the full grid: 10 cases x 10 + the strong kink x 4 = 104 results per
#: quantity, enough for the 2-standard-error fraction to fail bars 1.5x too small (0.82 expected
#: against a binomial lower limit of ~0.89) in about two minutes.
FULL_RUNS = 10

_QUICK_OPTS = {"tol": 0.05, "paths": 8, "t_run": 50.0, "min_replicas": 32, "progress": False}
_FULL_OPTS = {"tol": 1e-2, "progress": False}

#: Quick subset: one harmonic unit (exact), and two nonlinear ones against Fokker--Planck, one
#: with a smooth wall (n = 3) and the kink (n = 1).
QUICK_CASES = (
    CoverageCase("harmonic N = 1, a = 0.5", Harvester.build(a=0.5), _QUICK_OPTS),
    CoverageCase("n = 3, a = 0.5", Harvester.build(a=0.5, n=3.0), _QUICK_OPTS),
    CoverageCase("n = 1, a = 0.5", Harvester.build(a=0.5, n=1.0), _QUICK_OPTS),
)

FULL_CASES = (
    CoverageCase("harmonic N = 1, a = 0.5", Harvester.build(a=0.5), _FULL_OPTS),
    CoverageCase("harmonic N = 3, k = -0.3", Harvester.build(a=0.5, N=3, k=-0.3), _FULL_OPTS),
    CoverageCase("n = 1, a = 0.5", Harvester.build(a=0.5, n=1.0), _FULL_OPTS),
    CoverageCase("n = 1, a = 1", Harvester.build(a=1.0, n=1.0), _FULL_OPTS),
    # the Fokker-Planck solver does not converge at the strong kink: independent long run. Its
    # results run at tol 2e-2: eta is small there (0.12), and tol 1e-2 needs ~200 replicas (13 s
    # a result, against 3-6 s with 55-64 replicas at 2e-2)
    CoverageCase("n = 1, a = 2", Harvester.build(a=2.0, n=1.0), {**_FULL_OPTS, "tol": 2e-2}, ref_method="mc",
                 runs=4),
    CoverageCase("n = 1.5, a = 1", Harvester.build(a=1.0, n=1.5), _FULL_OPTS),
    CoverageCase("n = 3, a = 0.5", Harvester.build(a=0.5, n=3.0), _FULL_OPTS),
    CoverageCase("n = 4, a = 1", Harvester.build(a=1.0, n=4.0), _FULL_OPTS),
    CoverageCase("n = 8, a = 0.5", Harvester.build(a=0.5, n=8.0), _FULL_OPTS),
    CoverageCase("n = 3, N = 3, k = -0.5", Harvester.build(a=0.5, n=3.0, N=3, k=-0.5), _FULL_OPTS),
    CoverageCase("n = 4, N = 3, k = -0.5", Harvester.build(a=0.5, n=4.0, N=3, k=-0.5), _FULL_OPTS),
)


def _table_reference(case: CoverageCase, method: str = "mc", max_rel_err: float = math.inf) -> Stats | None:
    """The entry of the project's reference table (:mod:`validation.references.reftable`: solver, seed,
    command and commit recorded) for ``case``'s system and ``method``, or None (also when its
    relative error on eta exceeds ``max_rel_err``)."""
    from ..references import reftable

    entry = reftable.lookup(case.h, method, max_rel_err)
    return None if entry is None else reftable.as_stats(entry)


def _reference(case: CoverageCase, seed: int) -> Stats:
    """The case's reference: given, exact, Fokker--Planck or Monte Carlo ``tol / REF_FACTOR``,
    taken from the reference table when it holds the system that accurately (a Fokker--Planck
    value to 1e-4...1e-7, or a long Monte Carlo run: computing one at the strong kink costs up to
    an hour), else solved now."""
    if case.reference is not None:
        return case.reference
    tol = case.options["tol"] / REF_FACTOR
    if case.method == "exact":
        return solve(case.h, "exact")
    if case.method == "fpe":
        stored = _table_reference(case, "fpe", max_rel_err=tol)
        return stored if stored is not None else solve(case.h, "fpe", tol=tol, max_seconds=600.0)
    stored = _table_reference(case)
    if stored is not None:
        return stored
    opts = {**case.options, "tol": tol, "max_time": 3600.0}
    return solve(case.h, "mc", seed=seed, **opts)


def _stale(ref: Stats) -> str:
    """The reason a reference taken from the reference table is stale ("" when it is current or
    was computed in this run): :func:`validation.references.reftable.stale_note` marks its message."""
    i = ref.message.find("STALE: ")
    return ref.message[i + len("STALE: "):] if i >= 0 else ""


#: A reference that stopped short of its tolerance still serves when its relative error on eta
#: is at most this fraction of the results' tolerance: its error enters every z in quadrature.
REF_MAX_SHARE = 0.25


def usable_reference(ref: Stats, tol: float) -> str | None:
    """None when ``ref`` can serve as the reference of results at relative tolerance ``tol``
    (stable, or not converged with a relative error on eta of at most ``REF_MAX_SHARE * tol``
    for eta, V2 and Pin alike), else the reason."""
    if ref.status is Status.STABLE:
        return None
    if ref.status is Status.NOT_CONVERGED and all(
            v is not None and e is not None and v != 0 and e / abs(v) <= REF_MAX_SHARE * tol
            for v, e in (ref.value(q) for q in _QUANTITIES)):
        return None
    return f"{ref.status.value}: {ref.message}"


def binomial_limits(count: int, p: float, alpha: float = ALPHA) -> tuple[float, float]:
    """Fractions between which the share of ``count`` independent results within an interval
    of probability ``p`` falls with probability at least 1 - ``alpha`` (equal tails)."""
    import scipy.stats

    lo = scipy.stats.binom.ppf(alpha / 2, count, p) / count
    hi = scipy.stats.binom.ppf(1 - alpha / 2, count, p) / count
    return float(lo), float(hi)


def coverage_checks(z: dict[str, list[float]], alpha: float = ALPHA) -> list[tuple[str, bool, str]]:
    """Per quantity and k = 1, 2, 3: is the fraction of |z| < k inside the two-sided binomial
    limits of the normal coverage? Bars too wide fail (a fraction above the upper limit) as well
    as bars too narrow (below the lower one); at k = 3 the upper limit is 1 for any count below
    several thousand. Returns (label, passed, detail) triples."""
    out = []
    for q, values in z.items():
        a = np.abs(np.asarray(values))
        if a.size == 0:
            out.append((f"mc coverage of {q}", False, "no result had a usable reference"))
            continue
        for k, p in zip((1, 2, 3), NORMAL_COVERAGE):
            f = float((a < k).mean())
            lo, hi = binomial_limits(a.size, p, alpha)
            ok = lo <= f <= hi
            verdict = "" if ok else (" (bars too narrow)" if f < lo else " (bars too wide)")
            out.append((f"mc coverage of {q} within {k} standard error{'s' if k > 1 else ''}", ok,
                        f"{f:.3f} of {a.size} results (normal {p:.3f}; binomial limits [{lo:.3f}, {hi:.3f}] at "
                        f"alpha {alpha:g}){verdict}"))
    return out


#: Mis-scaled error bars the coverage checks must catch: reported errors 1.5x too small (z 1.5x
#: too large) and 2x too large (z halved).
MISSCALED = (1.5, 0.5)


def detection(count: int, scale: float, alpha: float = ALPHA) -> float:
    """Probability that :func:`coverage_checks` fails a quantity of ``count`` results whose z
    are ``scale`` times a standard normal's (reported errors off by 1/scale), at least: the
    larger of the probabilities that its fraction within 1 error, or within 2, leaves its limits."""
    import scipy.stats

    best = 0.0
    for k, p in zip((1, 2), NORMAL_COVERAGE):
        lo, hi = binomial_limits(count, p, alpha)
        q = 2.0 * float(scipy.stats.norm.cdf(k / scale)) - 1.0  # P(|z| < k) for the mis-scaled bars
        inside = scipy.stats.binom.cdf(round(hi * count), count, q) - scipy.stats.binom.cdf(round(lo * count) - 1,
                                                                                             count, q)
        best = max(best, 1.0 - float(inside))
    return best


def min_results(power: float = 0.5, alpha: float = ALPHA, upto: int = 1000) -> int:
    """The fewest results per quantity at which each of :data:`MISSCALED` fails the coverage
    checks with probability at least ``power`` (:func:`detection`): 48 for 0.5 and 95 for 0.9 at
    alpha 1e-3 (bars 1.5x too small are the harder to tell; 2x too wide fail with probability
    0.994 at 60 results)."""
    for count in range(10, upto + 1):
        if all(detection(count, s, alpha) >= power for s in MISSCALED):
            return count
    raise ValueError(f"no count up to {upto} detects mis-scaled bars with probability {power:g}")


def mc_coverage(quick: bool = True, runs: int | None = None, seed: int = 0,
                cases: tuple[CoverageCase, ...] | None = None) -> dict[str, Any]:
    """Coverage of the Monte Carlo error bars over a grid of cases.

    Parameters
    ----------
    quick : bool
        :data:`QUICK_CASES` with 12 runs each (about ten seconds), else :data:`FULL_CASES`
        with :data:`FULL_RUNS` runs each (a case's own ``runs`` where set; minutes).
    runs : int, optional
        Results per case, >= 2 (overrides the defaults, also the cases' own).
    seed : int
        First seed; result ``i`` of case number ``c`` uses ``seed + CASE_SEEDS * c + i``, a
        reference run ``seed + 10**6 + CASE_SEEDS * c`` (:data:`CASE_SEEDS`).
    cases : tuple of CoverageCase, optional
        Replaces the grid.

    Returns
    -------
    dict
        ``fractions`` (quantity -> fractions within 1, 2, 3 errors), ``expected`` (:data:`NORMAL_COVERAGE`), ``count``, and
        ``cases``: per case the reference, the z values per quantity, the statuses, the
        median relative error and the wall time.
    """
    if cases is None:
        cases = QUICK_CASES if quick else FULL_CASES
    if runs is not None and not 2 <= runs <= CASE_SEEDS:
        raise ValueError(f"runs must be an integer in [2, {CASE_SEEDS}], got {runs!r}")
    default_runs = runs if runs is not None else (12 if quick else FULL_RUNS)
    out_cases = []
    zs: dict[str, list[float]] = {q: [] for q in _QUANTITIES}
    for c, case in enumerate(cases):
        t0 = time.perf_counter()
        ref = _reference(case, seed + 10**6 + CASE_SEEDS * c)
        why = usable_reference(ref, case.options["tol"])
        if why is not None:
            # no reference, nothing to count: the case is reported (and fails), the others run
            out_cases.append({"label": case.label, "reference_method": ref.method, "reference_eta": ref.eta,
                              "reference_eta_err": ref.eta_err, "unusable_reference": why,
                              "z": {q: [] for q in _QUANTITIES}, "statuses": [], "median_rel_err_eta": None,
                              "wall_s": time.perf_counter() - t0})
            continue
        z_case: dict[str, list[float]] = {q: [] for q in _QUANTITIES}
        statuses, rel = [], []
        for i in range(runs if runs is not None else case.runs or default_runs):
            r = solve(case.h, "mc", seed=seed + CASE_SEEDS * c + i, **case.options)
            statuses.append(r.status.value)
            rel.append(r.eta_err / abs(r.eta))
            for q in _QUANTITIES:
                (v, dv), (vr, dvr) = r.value(q), ref.value(q)
                z = (v - vr) / math.hypot(dv, dvr)
                z_case[q].append(float(z))
                zs[q].append(float(z))
        out_cases.append({
            "label": case.label, "reference_method": ref.method, "reference_eta": ref.eta,
            "reference_eta_err": ref.eta_err, "reference_stale": _stale(ref), "z": z_case, "statuses": statuses,
            "median_rel_err_eta": float(np.median(rel)), "wall_s": time.perf_counter() - t0,
        })

    def fractions(values: list[float]) -> list[float]:
        a = np.abs(np.asarray(values))
        return [float((a < k).mean()) if a.size else 0.0 for k in (1, 2, 3)]

    return {
        "quick": quick, "runs": default_runs, "count": len(zs["eta"]), "expected": list(NORMAL_COVERAGE),
        "fractions": {q: fractions(zs[q]) for q in _QUANTITIES},
        "cases": out_cases,
    }
