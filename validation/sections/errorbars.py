"""Do the error bars hold? Monte Carlo coverage and Fokker--Planck error bounds, measured.

Every number the library returns for a nonlinear system carries an error estimate. This step
checks those estimates against actual errors:

* **Monte Carlo** (:func:`validation.comparisons.coverage.mc_coverage`): many results with independent
  seeds against another solver (exact for harmonic rings, Fokker--Planck ten times tighter
  for single nonlinear units; an independent run ten times tighter only where no other
  solver answers); the fractions of results within 1, 2, 3 reported standard errors of the
  reference, per quantity, within the binomial limits of 68.3 / 95.4 / 99.7 %.
* **Fokker--Planck**: results at a requested tolerance against the exact solver (n = 2, also
  with deliberately wrong Gaussian weights, so that the expansion is not exact), long Monte
  Carlo runs (the kink n = 1) or a much tighter solve of the same problem. The reported error
  is meant as a bound: the actual error :math:`|\\eta - \\eta_{ref}|` must not exceed the
  reported error plus the reference's own (three standard errors for Monte Carlo), and a
  result that says it met tol must have reported an error within it. The ratio reported /
  actual says how conservative the bound is.

Each of these is a check that fails when the promise breaks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status

from ..harness.checks import CheckResult, Context, expect
from ..harness.report import Figure, Section, Table, new_figure, save_figure

__all__ = ["run", "FpeCase", "QUICK_FPE", "FULL_FPE", "fpe_bounds"]

_SECTION = "Error bars"
#: Monte Carlo results per coverage case in quick mode (the full run: the coverage default): 3 x 20
#: = 60 per quantity. Bars 1.5x too small then fail with probability 0.68, 2x too wide 0.994
#: (:func:`validation.comparisons.coverage.detection`; the full run's 104: 0.92 and 1), and the typical
#: sample of either fails (at 48, the fewest with probability 0.5, that of bars 1.5x too small
#: still passes: the binomial limits move in steps of 1/count).
_QUICK_MC_RUNS = 20
#: Least probability that the run's coverage checks fail mis-scaled bars (quick, full).
_POWER = {True: 0.5, False: 0.9}



@dataclass(frozen=True)
class FpeCase:
    """A Fokker--Planck problem, the tolerances checked, and its reference.

    ``ref_tol`` None: the exact solver (n = 2), else the same solver at that tolerance (the
    reference table's value, :mod:`validation.references.reftable`, when it holds the system at least
    that accurately; else solved in the run); ``reference = "mc"``: an independent long Monte
    Carlo run, recorded in ``validation/references/data/kink_mc_reference_values.json`` (n = 1) or in the
    reference table (smooth walls). ``weight`` is the Gaussian
    weight of the 1-D scheme: ``"default"``, ``"marginal"`` (not centred on the conditional
    mean) or ``"wide"`` (covariance x 2.25): for n = 2 the default weight is the exact
    covariance, which a wrong weight takes away from the check.
    """

    n: float
    a: float
    tols: tuple[float, ...]
    ref_tol: float | None
    weight: str = "default"
    reference: str = "auto"

    @property
    def h(self) -> Harvester:
        return Harvester.build(a=self.a, n=self.n)

    @property
    def label(self) -> str:
        w = "" if self.weight == "default" else f", {self.weight} weight"
        return f"n = {self.n:g}, a = {self.a:g}{w}"

    @property
    def reference_name(self) -> str:
        if self.reference == "mc":
            return "Monte Carlo (long run)"
        return "exact" if self.ref_tol is None else f"fpe tol {self.ref_tol:g}"

    def options(self) -> dict[str, Any]:
        """Solver settings beyond ``tol`` (the weight)."""
        if self.weight == "default":
            return {}
        from fpe_harvester.fpe.schemes.x.discretize import Whitening

        w = Whitening.of(self.h, conditional=self.weight != "marginal")
        if self.weight == "wide":
            w = Whitening(2.25 * w.Sigma, 1.5 * w.chol, w.kappa, w.x2, w.shift)
        return {"weight": w}


QUICK_FPE = (
    FpeCase(2.0, 0.5, (1e-4,), None),
    FpeCase(2.0, 2.0, (1e-3, 1e-6), None, weight="marginal"),
    FpeCase(3.0, 0.5, (1e-3, 1e-4), 1e-5),
    FpeCase(4.0, 0.5, (1e-2, 1e-3), 1e-5),
    FpeCase(3.0, 0.5, (1e-2, 1e-3), None, reference="mc"),
)
FULL_FPE = QUICK_FPE + (
    FpeCase(1.5, 1.0, (1e-2, 1e-3), None, reference="mc"),
    FpeCase(4.0, 1.0, (1e-2, 1e-3), None, reference="mc"),
    FpeCase(8.0, 0.5, (1e-2, 1e-3), None, reference="mc"),
    FpeCase(2.0, 0.5, (1e-3, 1e-6), None, weight="wide"),
    FpeCase(1.0, 0.5, (1e-2, 1e-3), None, reference="mc"),
    FpeCase(1.0, 1.0, (1e-2, 1e-3), None, reference="mc"),
    FpeCase(1.5, 0.5, (1e-2, 1e-3), 1e-4),
    FpeCase(3.0, 1.0, (1e-3, 1e-4), 1e-6),
    FpeCase(3.0, 2.0, (1e-3, 1e-4), 1e-5),
    FpeCase(4.0, 2.0, (1e-3, 1e-4), 1e-5),
    FpeCase(6.0, 0.5, (1e-3, 1e-4), 1e-5),
    FpeCase(8.0, 0.5, (1e-3, 1e-4), 1e-5),
)

#: Standard errors of a statistical (Monte Carlo) reference allowed on top of a bound.
REF_SIGMAS = 3.0


@dataclass(frozen=True)
class Bound:
    """One Fokker--Planck result against its reference."""

    label: str
    tol: float
    reported: float
    actual: float
    ref_err: float
    status: str
    seconds: float  # the solver's own time (info["seconds"]): a result cached in the run costs none here
    eta: float = 1.0
    #: the reference's error counts this many times (1 for a bound, REF_SIGMAS for a standard error)
    ref_sigmas: float = 1.0
    reference: str = ""
    #: eta, V2 or Pin (``tol`` is on eta: only eta's bound must be within it for a stable result)
    quantity: str = "eta"

    @property
    def holds(self) -> bool:
        """The actual error is within the reported one (plus the reference's own), and the
        status agrees with the error: a stable result met its tol (on eta), a not converged
        one says so."""
        if self.status not in ("stable", "not_converged") or not math.isfinite(self.reported):
            return False
        if (self.quantity == "eta" and self.status == "stable"
                and self.reported > self.tol * abs(self.eta) * (1 + 1e-9)):
            return False
        return self.actual <= self.reported + self.ref_sigmas * self.ref_err

    @property
    def resolved(self) -> float:
        """The actual error floored at what the reference resolves (its own error; > 0)."""
        return max(self.actual, self.ref_err, 1e-300)

    @property
    def ratio(self) -> float:
        """Reported / actual error, the actual floored at the reference's own error."""
        return self.reported / self.resolved


def _mc_reference(n: float, a: float) -> Stats:
    """The long Monte Carlo run recorded for the unit ``U = a|x|^n`` (:func:`validation.references.reftable.recorded_mc`)."""
    from ..references.reftable import recorded_mc

    ref = recorded_mc(Harvester.build(a=a, n=n))
    if ref is None:
        raise RuntimeError(f"no recorded Monte Carlo reference for n = {n:g}, a = {a:g} "
                           "(python -m validation.references.reftable)")
    return ref


def _table_fpe(case: FpeCase) -> dict[str, Any] | None:
    """The reference table's Fokker--Planck entry of ``case`` when it is at least ``ref_tol``
    accurate and has a number (computed once, with its commit recorded), else None."""
    from ..references import reftable

    d = reftable.lookup(case.h, "fpe", float(case.ref_tol or 0.0))
    return d if d is not None and d["status"] in ("stable", "not_converged") else None


#: Settings of a Fokker--Planck reference solved in the run (tol: the case's ``ref_tol``).
_REF_SECONDS = 600.0


def _fpe_reference(ctx: Context, case: FpeCase) -> Stats:
    """The Fokker--Planck reference ``ref_tol``: the reference table's value (:func:`_table_fpe`),
    else solved in this run."""
    from ..references import reftable

    d = _table_fpe(case)
    if d is not None:
        return reftable.as_stats(d, Status.STABLE)
    return ctx.solve(case.h, "fpe", tol=float(case.ref_tol or 0.0), max_seconds=_REF_SECONDS)


def prefetch(ctx: Context) -> None:
    """Announce the Fokker--Planck solves of the bounds (:meth:`Context.prefetch`): the references
    solved in the run, then every tolerance of every case without a weight object."""
    cases = QUICK_FPE if ctx.quick else FULL_FPE
    for case in cases:
        if case.reference != "mc" and case.ref_tol is not None and _table_fpe(case) is None:
            ctx.prefetch(case.h, "fpe", tol=float(case.ref_tol), max_seconds=_REF_SECONDS)
    for case in cases:
        if not case.options():
            for tol in case.tols:
                ctx.prefetch(case.h, "fpe", tol=tol)


def fpe_bounds(ctx: Context, cases: tuple[FpeCase, ...]) -> list[Bound]:
    """Solve every case at each tolerance and compare eta, V2 and Pin with the reference."""
    out = []
    for case in cases:
        h = case.h
        if case.reference == "mc":
            ref = _mc_reference(case.n, case.a)
        elif case.ref_tol is None:
            ref = ctx.solve(h, "exact")
        else:
            ref = _fpe_reference(ctx, case)
        if ref.status is not Status.STABLE or ref.eta is None:
            raise RuntimeError(f"reference for {case.label} is {ref.status.value}: {ref.message}")
        stale = ref.message.find("STALE: ")
        name = case.reference_name + (f" ({ref.message[stale:]})" if stale >= 0 else "")
        for tol in case.tols:
            opts = case.options()
            if opts:  # a weight object: solved outside the run's cache (its key must be hashable)
                from fpe_harvester.fpe import stationary

                r: Stats = stationary(h, tol=tol, max_seconds=ctx.fpe_options["max_seconds"], **opts).stats
            else:
                r = ctx.solve(h, "fpe", tol=tol)
            if r.eta is None:
                raise RuntimeError(f"{case.label}, tol {tol:g}: {r.status.value} without a number: {r.message}")
            for q in ("eta", "V2", "Pin"):
                (v, e), (vr, er) = r.value(q), ref.value(q)
                if v is None or vr is None:
                    raise RuntimeError(f"{case.label}, tol {tol:g}: no {q} to compare")
                out.append(Bound(case.label, tol, float(e if e is not None else math.inf), abs(v - vr),
                                 float(er or 0.0), r.status.value, float(r.info["seconds"]), float(r.eta),
                                 REF_SIGMAS if case.reference == "mc" else 1.0, name, q))
    return out


def _fpe_checks(ctx: Context, sec: Section) -> list[CheckResult]:
    ctx.require("fpe")
    bounds = fpe_bounds(ctx, QUICK_FPE if ctx.quick else FULL_FPE)
    table = Table("Fokker-Planck: reported against actual error of eta, V2 and Pin",
                  ("problem", "quantity", "reference", "tol", "status", "reported", "actual", "reference error",
                   "reported / actual", "bound holds", "time [s]"))
    checks = []
    for b in bounds:
        table.rows.append((b.label, b.quantity, b.reference, f"{b.tol:g}", b.status, f"{b.reported:.2e}",
                           f"{b.actual:.2e}", f"{b.ref_err:.1e}", f"{b.ratio:.3g}", "yes" if b.holds else "NO",
                           f"{b.seconds:.2f}"))
        checks.append(expect(f"fpe error bound: {b.label}, tol {b.tol:g}: {b.quantity}", _SECTION, b.holds,
                             f"actual {b.actual:.2e} vs reported {b.reported:.2e} (+ {b.ref_sigmas:g} x "
                             f"reference error {b.ref_err:.1e}, {b.reference}); status {b.status}"))
    ratios = np.array([b.ratio for b in bounds])
    summary = []
    for q in ("eta", "V2", "Pin"):
        for kind, pick in (("another solver", lambda b: not b.reference.startswith("fpe")),
                           ("the same solver, tighter", lambda b: b.reference.startswith("fpe"))):
            sel = [b for b in bounds if b.quantity == q and pick(b)]
            if sel:
                summary.append(f"{q} against {kind}: {sum(b.holds for b in sel)} of {len(sel)}")
    table.note = (f"The bound held in {sum(b.holds for b in bounds)} of {len(bounds)} results ("
                  + "; ".join(summary) + f"); reported / actual: median {np.median(ratios):.3g}, range "
                  f"{ratios.min():.3g} - {ratios.max():.3g} (> 1 is conservative). 'Another solver' is the "
                  "exact solver (n = 2, with a deliberately wrong Gaussian weight where marked, so that the "
                  "expansion is not exact by construction) or an independent long Monte Carlo run (its "
                  f"standard error counted {REF_SIGMAS:g} times); 'fpe tol' references are the same solver, "
                  "taken from the reference table when it holds the system. The actual error is floored at "
                  "the reference's own error, so large ratios may be limited by the reference.")
    sec.tables.append(table)
    sec.figures.append(_plot_bounds(ctx, bounds))
    return checks


def _mc_checks(ctx: Context, sec: Section) -> list[CheckResult]:
    from ..comparisons.coverage import ALPHA, MISSCALED, NORMAL_COVERAGE, coverage_checks, detection, mc_coverage, min_results

    ctx.require("mc")
    res = mc_coverage(quick=ctx.quick, runs=_QUICK_MC_RUNS if ctx.quick else None, seed=ctx.seed)
    table = Table("Monte Carlo: fraction of results within 1, 2, 3 reported standard errors",
                  ("quantity", "within 1", "within 2", "within 3", "results"))
    for q, f in res["fractions"].items():
        table.rows.append((q, *(f"{x:.3f}" for x in f), str(res["count"])))
    table.rows.append(("normal", *(f"{x:.3f}" for x in NORMAL_COVERAGE), "-"))
    table.note = ("Cases: " + "; ".join(f"{c['label']} (reference {c['reference_method']}"
                                         + (f", STALE reference-table entry: {c['reference_stale']}"
                                            if c["reference_stale"] else "")
                                         + f", median relative error {c['median_rel_err_eta']:.1e}, {c['wall_s']:.0f} s)"
                                         for c in res["cases"] if "unusable_reference" not in c)
                  + f". Each quantity is checked on its own, against the binomial limits of the normal "
                    f"coverage for the number of results (two-sided probability {ALPHA:g} per fraction).")
    sec.tables.append(table)
    sec.figures.append(_plot_coverage(ctx, res))
    z = {q: [v for c in res["cases"] for v in c["z"][q]] for q in res["fractions"]}
    missing = [expect(f"mc coverage: reference for {c['label']}", _SECTION, False,
                      f"no usable reference, the case was not counted: {c['unusable_reference']}")
               for c in res["cases"] if "unusable_reference" in c]
    need, power = min_results(_POWER[ctx.quick]), _POWER[ctx.quick]
    enough = expect("mc coverage: enough results to fail bars too narrow or too wide", _SECTION,
                    res["count"] >= need,
                    f"{res['count']} results per quantity (at least {need} for probability {power:g}); bars 1.5x too "
                    f"small fail with probability {detection(res['count'], MISSCALED[0]):.2f}, 2x too wide "
                    f"{detection(res['count'], MISSCALED[1]):.4f}")
    return missing + [enough] + [expect(label, _SECTION, ok, detail) for label, ok, detail in coverage_checks(z)]


def _plot_coverage(ctx: Context, res: dict) -> Figure:
    z = np.concatenate([np.asarray(c["z"][q]) for c in res["cases"] for q in c["z"]])
    fig, ax = new_figure()
    ax.hist(np.clip(z, -5, 5), bins=np.linspace(-5, 5, 41), density=True, alpha=0.6,
            label=f"Monte Carlo, {z.size} values")
    x = np.linspace(-5, 5, 400)
    ax.plot(x, np.exp(-x * x / 2) / math.sqrt(2 * math.pi), "k-", label="standard normal")
    ax.set_xlabel("(result - reference) / combined reported error")
    ax.set_ylabel("density")
    ax.legend()
    return save_figure(fig, ctx.out / "errorbars_mc_coverage.png",
                       "Monte Carlo: normalized errors of eta, V2 and Pin against the reference; honest "
                       "one-standard-error bars give the standard normal (values beyond 5 are drawn at 5).")


def _plot_bounds(ctx: Context, bounds: list[Bound]) -> Figure:
    fig, ax = new_figure((5.5, 4.5))
    for label in dict.fromkeys(b.label for b in bounds):
        for q, marker in (("eta", "o"), ("V2", "s"), ("Pin", "^")):
            pts = [(max(b.resolved, 1e-16), b.reported) for b in bounds if b.label == label and b.quantity == q]
            if pts:
                ax.loglog(*zip(*pts), marker, label=label if q == "eta" else None, mfc="none" if q != "eta" else None)
    lo = min(min(b.reported for b in bounds), min(max(b.resolved, 1e-16) for b in bounds))
    hi = max(max(b.reported for b in bounds), max(b.actual for b in bounds))
    ax.loglog([lo, hi], [lo, hi], "k--", lw=1, label="reported = actual")
    ax.set_xlabel("actual error (vs reference)")
    ax.set_ylabel("reported error")
    ax.legend(fontsize=8)
    return save_figure(fig, ctx.out / "errorbars_fpe_bounds.png",
                       "Fokker-Planck: reported against actual error of eta (filled circles), V2 (open "
                       "squares) and Pin (open triangles); points above the diagonal are bounds that hold.")


def run(ctx: Context) -> Section:
    """Monte Carlo coverage and Fokker--Planck error bounds."""
    sec = Section("errorbars", _SECTION)
    sec.text.append(
        "Every number for a nonlinear system carries an error estimate; here they are checked against "
        "actual errors. Monte Carlo errors are one standard error (statistical, Student-t scaled, with "
        "the time-step bias estimate in quadrature): over independent seeds about 68 / 95 / 99.7 % of "
        "results should lie within 1 / 2 / 3 errors of a much tighter reference. Fokker-Planck errors "
        "are refinement estimates meant as bounds: the actual error should not exceed them."
        + (f" Quick mode: a subset of the cases and {_QUICK_MC_RUNS} Monte Carlo results per case." if ctx.quick else ""))
    sec.checks += ctx.check("Monte Carlo coverage", _SECTION, lambda: _mc_checks(ctx, sec))
    sec.checks += ctx.check("Fokker-Planck error bounds", _SECTION, lambda: _fpe_checks(ctx, sec))
    return sec
