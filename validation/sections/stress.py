"""Stress tests of numerical stability.

Each case passes only if its status is true for the problem and its numbers are accurate to
their stated errors; a case with no stationary state must say so. A refusal of these
well-posed cases fails, and a result without numbers is a skip (nothing was checked). NaN or
inf cannot reach the user (:class:`Stats` rejects them); a hang is caught by a wall-time budget.

References: harmonic cases are compared with a 40-digit Lyapunov solve
(:func:`.references.mp_ring_moments`: mpmath, 16 x 16 vectorized system per mode, 3 x 3 for
a zero-stiffness mode), built from the exact binary
values of the inputs, so it is independent of the closed form and of its round-off. The
N = 10^6 ring is compared with the N -> inf integral over modes. Nonlinear cases are
compared with the other, independent solver (Fokker--Planck with Monte Carlo and back) and with
the stationary identities (docs/model.md §2), within their stated errors.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace

from fpe_harvester.errors import HarvesterError, MethodNotAvailableError
from fpe_harvester.exact import k_di
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status

from ..comparisons.strongkink import declines, product
from ..harness.checks import CheckResult, Context, agree, expect, skipped, solver_available
from ..harness.report import Section, Table
from ..references.analytic import mp_ring_moments
from .crosscheck import MAX_REL_TOL as CROSS_MAX_REL_TOL
from .crosscheck import mc_within_cap
from .identities import identity_checks

__all__ = ["run_exact", "run_solvers"]

_SECTION = "Stress tests"
#: Relative round-off floor allowed on top of the exact solver's stated error of 0.
EXACT_FLOOR = 1e-9
#: Largest tolerance of a Fokker-Planck / Monte Carlo stress comparison relative to the
#: reference value (quick, full): the cross-checks' (:mod:`validation.sections.crosscheck`).
MAX_REL_TOL = CROSS_MAX_REL_TOL


def _vs_mp(label: str, r: Stats, h: Harvester, names: tuple[str, ...] = ("eta", "V2", "Pin"),
           marginal: bool = False) -> list[CheckResult]:
    ref = mp_ring_moments(h, zero_below=1e-12 if marginal else 0.0)
    out = []
    for q in names:
        val, err = r.value(q)
        out.append(agree(f"stress: {label}: {q}", _SECTION, val, err, float(ref[q]), 0.0, rel_floor=EXACT_FLOOR,
                         note=f"status {r.status.value}; reference: 40-digit Lyapunov solve"))
    return out


def _harmonic_cases(ctx: Context) -> list[tuple[str, Callable[[], list[CheckResult]]]]:
    kd3 = k_di(3, 0.5)

    def near() -> list[CheckResult]:
        h = Harvester.build(a=0.5, n=2, N=3, k=kd3 * (1 - 1e-12))
        r = ctx.solve(h, "exact")
        out = [expect("stress: k = k_di(1 - 1e-12): status stable", _SECTION, r.status is Status.STABLE,
                      f"status {r.status.value}: {r.message}")]
        out += _vs_mp("k = k_di(1 - 1e-12), N = 3", r, h)
        x2 = _vs_mp("k = k_di(1 - 1e-12), N = 3 (x2 ~ 1/kappa_min)", r, h, ("x2",))[0]
        cond = 2.0 * h.a / float(h.mode_stiffness().min())
        note = (f"; x2 is ill-conditioned in k (relative condition number ~ 2a/kappa_min = {cond:.1e}, so "
                f"round-off allows ~{cond * 2.2e-16:.0e}); the stated error should say so")
        return out + [replace(x2, detail=x2.detail + note)]

    def at(N: int) -> Callable[[], list[CheckResult]]:
        def case() -> list[CheckResult]:
            h = Harvester.build(a=0.5, n=2, N=N, k=k_di(N, 0.5))
            r = ctx.solve(h, "exact")
            out = [expect(f"stress: k = k_di, N = {N}: marginal, x2 reported as None", _SECTION,
                          r.status is Status.MARGINAL and r.x2 is None and r.eta is not None,
                          f"status {r.status.value}, x2 = {r.x2}: {r.message}")]
            return out + _vs_mp(f"k = k_di, N = {N} (finite limit)", r, h, marginal=True)
        return case

    def beyond() -> list[CheckResult]:
        import numpy as np

        from fpe_harvester.exact import ring_drift_matrix

        h = Harvester.build(a=0.5, n=2, N=3, k=kd3 * 1.01)
        r = ctx.solve(h, "exact")
        eig = float(np.linalg.eigvals(ring_drift_matrix(h)).real.max())
        return [expect("stress: k = 1.01 k_di (beyond): flagged unstable, no numbers", _SECTION,
                       r.status is Status.UNSTABLE and r.V2 is None and r.eta is None and bool(r.message),
                       f"status {r.status.value}, eta = {r.eta}: {r.message}"),
                agree("stress: k = 1.01 k_di: growth rate vs dense eigenvalues", _SECTION, r.growth_rate, 0.0,
                      eig, 0.0, rel_floor=1e-8)]

    def simple(label: str, N: int = 1, k: float = 0.0, a: float = 0.5, **params: float) -> Callable[[], list]:
        def case() -> list[CheckResult]:
            h = Harvester.build(a=a, n=2, N=N, k=k, **params)
            return _vs_mp(label, ctx.solve(h, "exact"), h, ("eta", "V2", "Pin", "v2", "vV"))
        return case

    def million() -> list[CheckResult]:
        import time

        import scipy.integrate

        from fpe_harvester.exact import mode_moments

        h = Harvester.build(a=0.5, n=2, N=1_000_000, k=-0.2)
        t0 = time.perf_counter()
        r = ctx.solve(h, "exact")
        dt = time.perf_counter() - t0
        mom = {key: scipy.integrate.quad(lambda t: float(mode_moments(1.0 - 0.8 * math.sin(t) ** 2, h.params)[key]),
                                         0, math.pi, epsabs=0, epsrel=1e-13)[0] / math.pi for key in ("V2", "Pin")}
        return [agree("stress: N = 1e6 ring (exact) vs N -> inf integral: eta", _SECTION, r.eta, r.eta_err,
                      mom["V2"] / mom["Pin"], 0.0, rel_floor=EXACT_FLOOR, note=f"solve time {dt:.2f} s"),
                agree("stress: N = 1e6 ring (exact) vs N -> inf integral: V2", _SECTION, r.V2, r.V2_err,
                      mom["V2"], 0.0, rel_floor=EXACT_FLOOR)]

    return [
        ("k = k_di(1 - 1e-12)", near),
        ("k = k_di (N = 3)", at(3)),
        ("k = k_di (N = 4)", at(4)),
        ("k beyond k_di", beyond),
        ("tiny a = 1e-3 (exact)", simple("a = 1e-3 (exact)", a=1e-3)),
        ("tiny a = 1e-3, N = 3 ring near k_di (exact)", simple("a = 1e-3, N = 3, k = 0.9 k_di", N=3,
                                                               k=0.9 * k_di(3, 1e-3), a=1e-3)),
        ("tau = 1e-4 (exact)", simple("tau = 1e-4 (exact)", tau=1e-4)),
        ("tau = 100 (exact)", simple("tau = 100 (exact)", tau=100.0)),
        ("tau_p = 1e4 (exact)", simple("tau_p = 1e4 (exact)", tau_p=1e4)),
        ("m = 1e-4 (exact)", simple("m = 1e-4, stiff (exact)", m=1e-4)),
        ("D = 100 (exact)", simple("D = 100 (exact)", D=100.0)),
        ("N = 1e6 (exact)", million),
    ]


def _judge(label: str, method: str, run: Callable[[], Stats], h: Harvester,
           reference: Callable[[], Stats] | None = None, quick: bool = True,
           expected: Status | None = None) -> list[CheckResult]:
    """One stress case: the true status, and numbers accurate to their stated errors.

    * ``expected`` set (a case with no stationary state): PASS iff the result has that status
      and no numbers.
    * Otherwise the status must be true for the problem (``unstable`` never, ``metastable`` only
      for a metastable ring) and the numbers, converged or not, must agree with the independent
      ``reference`` (another solver) and with the stationary identities within 4 combined error
      bars, the tolerance capped at :data:`MAX_REL_TOL` of the reference (an error bar that
      wide cannot tell right from wrong).
    * A refusal (:class:`HarvesterError`) of a well-posed case fails; a result without numbers
      (``not_converged``, or ``metastable`` with every path escaped) is a SKIP: nothing was checked,
      which the quick run lists and the full run counts as a failure.
    """
    name = f"stress: {label} [{method}]"
    why = solver_available(method)
    if why:
        return [skipped(name, _SECTION, f"solver not available ({why})")]
    try:
        r = run()
    except HarvesterError as exc:
        return [expect(name, _SECTION, False, f"refused a well-posed case ({type(exc).__name__}): {exc}")]
    if expected is not None:
        return [expect(name, _SECTION, r.status is expected and r.eta is None,
                       f"expected {expected.value} without numbers; got {r.status.value}, eta = {r.eta}: {r.message}")]
    truth = "metastable" if h.confinement == "metastable" else "confined"
    if r.status is Status.UNSTABLE or (r.status is Status.METASTABLE and truth != "metastable"):
        return [expect(name, _SECTION, False, f"false status {r.status.value} for a {truth} system: {r.message}")]
    if r.eta is None:
        return [skipped(name, _SECTION, f"{r.status.value} without numbers, nothing to check: {r.message}")]
    out: list[CheckResult] = []
    if reference is not None:
        try:
            ref = reference()
        except HarvesterError as exc:
            ref = None
            out.append(expect(f"{name}: reference", _SECTION, False, f"the reference refused the case: {exc}"))
        if ref is not None and not (ref.ok and ref.eta is not None):
            out.append(skipped(f"{name}: reference", _SECTION, f"reference {ref.method} is {ref.status.value} "
                               f"without a converged number ({ref.message}); judged by the identities only"))
        elif ref is not None:
            for q in ("eta", "V2", "Pin"):
                out.append(agree(f"{name}: {q}", _SECTION, *r.value(q), *ref.value(q),
                                 max_rel_tol=MAX_REL_TOL[quick],
                                 note=f"status {r.status.value}; reference: {ref.method} ({ref.status.value}) on the "
                                      "same problem"))
    out += identity_checks(label + ("" if r.ok else f", {r.status.value}"), r, h, _SECTION)
    return out


#: Monte Carlo tolerance on eta of a stress case that has no reference number: its status and the
#: two identities are all that is judged, and they hold at any accuracy. (At the strong kink, where
#: Fokker-Planck declines, the case reuses the cross-checks' run, which the second Monte Carlo
#: construction checks: :mod:`validation.comparisons.strongkink`.)
IDENTITIES_TOL = 0.02

#: Longest wall time [s] Fokker--Planck may take to decline a unit outside its domain ("at once").
DECLINE_SECONDS = 5.0


def _declines(label: str, h: Harvester) -> list[CheckResult]:
    """Fokker--Planck outside its domain: it must decline at once, naming Monte Carlo."""
    from fpe_harvester import solve

    name = f"stress: {label} [fpe]"
    t0 = time.perf_counter()
    try:
        r = solve(h, "fpe")
    except MethodNotAvailableError as exc:
        dt, msg = time.perf_counter() - t0, str(exc)
        names_mc = "'mc'" in msg or "monte carlo" in msg.lower()
        return [expect(f"{name}: declines at once, naming Monte Carlo", _SECTION, dt <= DECLINE_SECONDS and names_mc,
                       f"declined in {dt:.2f} s (at most {DECLINE_SECONDS:g} s); names Monte Carlo: "
                       f"{'yes' if names_mc else 'no'}; message: {msg}")]
    return [expect(f"{name}: declines at once, naming Monte Carlo", _SECTION, False,
                   f"its domain rule declines this unit, but solve(h, 'fpe') answered ({r.status.value}) after "
                   f"{time.perf_counter() - t0:.1f} s")]


def _nonlinear_cases(ctx: Context) -> list[tuple[str, Callable[[], list[CheckResult]]]]:
    def run(h: Harvester, method: str) -> Stats:
        # a Monte Carlo run (result or reference) at an accuracy at which the check's cap can be met
        return mc_within_cap(ctx, h) if method == "mc" else ctx.solve(h, method)

    def independent(h: Harvester, method: str) -> Callable[[], Stats]:
        return lambda: run(h, "mc" if method == "fpe" else "fpe")

    def fpe(label: str, h: Harvester, checked: bool = True) -> tuple:
        if declines(h):
            return (f"{label} [fpe]", lambda: _declines(label, h))
        ref = independent(h, "fpe") if checked else None
        return (f"{label} [fpe]", lambda: _judge(label, "fpe", lambda: ctx.solve(h, "fpe"), h, ref, ctx.quick))

    def mc(label: str, h: Harvester, checked: bool = True, expected: Status | None = None) -> tuple:
        # where Fokker-Planck declines (the strong kink), the cross-checks' two Monte Carlo
        # constructions check the numbers; here the run they share is judged by status and identities
        strong = h.N == 1 and declines(h) is not None
        ref = independent(h, "mc") if checked and not strong else None

        def result() -> Stats:
            # narrowed to the cap only when a reference number is there to compare with; without
            # one the result is judged by its status and the identities only, at IDENTITIES_TOL
            if strong:
                return product(ctx, h)
            try:
                usable = ref is not None and (r := ref()).ok and r.eta is not None
            except HarvesterError:
                usable = False
            if usable or expected is not None or ctx.quick:
                return run(h, "mc")
            return ctx.solve(h, "mc", tol=max(IDENTITIES_TOL, ctx.mc_options["tol"]))

        return (f"{label} [mc]", lambda: _judge(label, "mc", result, h, ref, ctx.quick, expected))

    return [fpe(label, h, checked) if kind == "fpe" else mc(label, h, checked, expected)
            for kind, label, h, checked, expected in _nonlinear_specs(ctx.quick)]


def _nonlinear_specs(quick: bool) -> list[tuple[str, str, Harvester, bool, Status | None]]:
    """(solver, label, system, checked against the other solver, expected status) of every
    nonlinear stress case. A Monte Carlo case is checked against Fokker--Planck where that
    solver applies (a single unit) and a stationary state exists (no expected status)."""
    b = Harvester.build
    # Quick mode (CI): one case per kind of difficulty; the full run covers the whole list.
    # Every Fokker-Planck case is checked against Monte Carlo (an independent solver): in quick
    # mode only where the kink does not make both expensive.
    cases: list[tuple[str, str, Harvester, bool, Status | None]] = [
        ("fpe", "large n = 12", b(a=0.5, n=12), True, None),
        ("fpe", "n = 1 kink, a = 2", b(a=2.0, n=1), not quick, None),
        ("fpe", "D = 100, n = 3", b(a=0.5, n=3, D=100.0), True, None),
        ("mc", "harmonic ring beyond k_di (k = 1.2 k_di)", b(a=0.5, n=2, N=3, k=1.2 * k_di(3, 0.5)), False,
         Status.UNSTABLE),
        ("mc", "n = 1 kink, a = 2", b(a=2.0, n=1), True, None),
    ]
    if not quick:
        cases += [("fpe", label, h, True, None) for label, h in (
            ("tiny a = 1e-3, n = 3", b(a=1e-3, n=3)),
            ("large n = 8", b(a=0.5, n=8)),
            ("large n = 16", b(a=0.5, n=16)),
            ("tau = 1e-4, n = 3", b(a=0.5, n=3, tau=1e-4)),
            ("tau = 100, n = 3", b(a=0.5, n=3, tau=100.0)),
            ("tau_p = 1e3, n = 3", b(a=0.5, n=3, tau_p=1e3)),
            ("m = 1e-3 (stiff), n = 3", b(a=0.5, n=3, m=1e-3)),
            ("D = 100, n = 1", b(a=0.5, n=1, D=100.0)),
        )]
        cases += [("mc", label, h, True, None) for label, h in (
            ("m = 1e-3 (stiff), n = 3", b(a=0.5, n=3, m=1e-3)),
            ("large n = 12", b(a=0.5, n=12)),
            ("large n = 16", b(a=0.5, n=16)),
            ("tau = 1e-4, n = 3", b(a=0.5, n=3, tau=1e-4)),
            ("tau = 100, n = 3", b(a=0.5, n=3, tau=100.0)),
            ("D = 100, n = 3", b(a=0.5, n=3, D=100.0)),
            ("D = 100, n = 1", b(a=0.5, n=1, D=100.0)),
            ("tiny a = 1e-3, n = 3", b(a=1e-3, n=3)),
        )]
    return cases


def prefetch(ctx: Context) -> None:
    """Announce the Fokker--Planck solves of the nonlinear cases, results and references
    (:meth:`Context.prefetch`)."""
    for kind, _, h, checked, _ in _nonlinear_specs(ctx.quick):
        if (kind == "fpe" or checked) and declines(h) is None:
            ctx.prefetch(h, "fpe")


def run_exact(ctx: Context) -> Section:
    """The harmonic stress cases (exact solver; about a second in all)."""
    return _run(ctx, "stress_exact", f"{_SECTION}: exact solver", _harmonic_cases(ctx))


def run_solvers(ctx: Context) -> Section:
    """The nonlinear stress cases (Fokker--Planck and Monte Carlo)."""
    return _run(ctx, "stress_solvers", f"{_SECTION}: Fokker-Planck and Monte Carlo", _nonlinear_cases(ctx))


def _run(ctx: Context, key: str, title: str, cases: list[tuple[str, Callable[[], list[CheckResult]]]]) -> Section:
    """Each case under a wall-time budget (a hang fails)."""
    sec = Section(key, title)
    budget = 30.0 if ctx.quick else 900.0
    sec.text.append(
        "PASS means: the status is true for the problem (unstable only beyond a harmonic threshold, "
        "metastable only for an n < 2 ring with k < 0), and the numbers, converged or not, are accurate to "
        f"their stated errors (exact: stated error plus a relative round-off floor of {EXACT_FLOOR:g} "
        "against a 40-digit Lyapunov solve; Fokker-Planck and Monte Carlo: 4 combined error bars against "
        "the other, independent solver on the same problem, the tolerance at most "
        f"{MAX_REL_TOL[ctx.quick]:.0%} of the reference, and the stationary identities of docs/model.md §2). "
        "A refusal of these well-posed cases FAILS, except Fokker-Planck outside its declared domain (the strong "
        f"kink), which must decline within {DECLINE_SECONDS:g} s naming Monte Carlo (there the Monte Carlo case "
        "reuses the cross-checks' run, checked against a second Monte Carlo construction; here its status and "
        "identities); a result without numbers is a SKIP (nothing was "
        f"checked). Each case runs under a {budget:g} s wall-time budget; exceeding it is a hang (FAIL)."
    )
    table = Table("Stress cases", ("case", "outcome", "time [s]"))
    for label, case in cases:
        res = ctx.check(label, _SECTION, case, cap=budget)
        sec.checks += res
        worst = "FAIL" if any(c.outcome.value == "FAIL" for c in res) else (
            "SKIP" if all(c.outcome.value == "SKIP" for c in res) else "PASS")
        table.rows.append((label, worst, f"{sum(c.seconds for c in res):.2f}"))
    sec.tables.append(table)
    return sec
