"""Stress tests of numerical stability.

Each case passes only if the answer is accurate to its stated error, or the library
refuses or flags it clearly (a :class:`ParameterError`, an unsupported-case message, or a
status ``unstable`` / ``not_converged`` / ``metastable`` with a message). NaN or inf
cannot reach the user (:class:`Stats` rejects them); a hang is caught by a wall-time budget.

References: harmonic cases are compared with a 40-digit Lyapunov solve
(:func:`.references.mp_ring_moments`: mpmath, 16 x 16 vectorized system per mode, 3 x 3 for
a zero-stiffness mode), built from the exact binary
values of the inputs, so it is independent of the closed form and of its round-off. The
N = 10^6 ring is compared with the N -> inf integral over modes. Nonlinear cases are
compared with an exactly equivalent rescaled problem where one exists
(:math:`x, v, V, \\xi \\to s\\,(\\cdot)` maps :math:`(a, D)` to :math:`(a s^{n-2}, D/s^2)`,
multiplies V2 and Pin by :math:`s^2` and leaves η unchanged), otherwise checked against the
stationary identities (docs/model.md §2) within their stated errors.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

from fpe_harvester.errors import HarvesterError, MethodNotAvailableError
from fpe_harvester.exact import k_di
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status

from .checks import CheckResult, Context, agree, expect, skipped, solver_available
from .crosscheck import identity_checks
from .references import mp_ring_moments
from .report import Section, Table

__all__ = ["run_exact", "run_solvers"]

_SECTION = "Stress tests"
#: Relative round-off floor allowed on top of the exact solver's stated error of 0.
EXACT_FLOOR = 1e-9


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
           reference: Callable[[], tuple[Stats, float]] | None = None) -> list[CheckResult]:
    """Accurate to the stated error (vs ``reference`` or by the identities), or clearly refused/flagged."""
    name = f"stress: {label} [{method}]"
    why = solver_available(method)
    if why:
        return [skipped(name, _SECTION, f"solver not available ({why})")]
    try:
        r = run()
    except MethodNotAvailableError as exc:
        return [expect(name, _SECTION, bool(str(exc)), f"refused clearly: {exc}")]
    except HarvesterError as exc:
        return [expect(name, _SECTION, bool(str(exc)), f"refused clearly ({type(exc).__name__}): {exc}")]
    if r.status in (Status.UNSTABLE, Status.NOT_CONVERGED, Status.METASTABLE):
        return [expect(name, _SECTION, bool(r.message), f"flagged {r.status.value}: {r.message or '(no message)'}")]
    out: list[CheckResult] = []
    if r.eta is None:
        return [expect(name, _SECTION, False, f"status {r.status.value} but no eta: {r.message}")]
    ref = None
    if reference is not None:
        try:
            ref, scale = reference()
        except HarvesterError as exc:
            out.append(skipped(f"{name}: reference", _SECTION, f"reference not available ({exc}); "
                               "judged by the identities only"))
        if ref is not None and not (ref.ok and ref.eta is not None):
            out.append(skipped(f"{name}: reference", _SECTION, f"reference {ref.method} is {ref.status.value}; "
                               "judged by the identities only"))
            ref = None
    if ref is not None:
        for q, s in (("eta", 1.0), ("V2", scale), ("Pin", scale)):
            v, e = r.value(q)
            rv, re_ = ref.value(q)
            out.append(agree(f"{name}: {q}", _SECTION, v, e, None if rv is None else rv * s,
                             None if re_ is None else re_ * s,
                             note=f"status {r.status.value}; reference: {ref.method}" + (
                                 f" on the equivalent rescaled problem (scale {scale:g})" if scale != 1.0 else
                                 " on the same problem")))
    out += identity_checks(label, r, h, _SECTION)
    return out


def _nonlinear_cases(ctx: Context) -> list[tuple[str, Callable[[], list[CheckResult]]]]:
    def fpe(label: str, h: Harvester, reference: Callable[[], tuple[Stats, float]] | None = None) -> tuple:
        if reference is None and not ctx.quick:
            # The full run checks Fokker-Planck against the independent Monte Carlo solver.
            reference = lambda: (ctx.solve(h, "mc"), 1.0)  # noqa: E731
        return (f"{label} [fpe]", lambda: _judge(label, "fpe", lambda: ctx.solve(h, "fpe"), h, reference))

    def mc(label: str, h: Harvester) -> tuple:
        return (f"{label} [mc]", lambda: _judge(label, "mc", lambda: ctx.solve(h, "mc"), h))

    def rescaled(n: float, a: float, D: float, s: float) -> Callable[[], tuple[Stats, float]]:
        # x -> s x maps (a, D) to (a s^(n-2), D / s^2); V2 and Pin scale by s^2, eta is unchanged.
        return lambda: (ctx.solve(Harvester.build(a=a * s ** (n - 2), n=n, D=D / s**2), "fpe"), s**2)

    b = Harvester.build
    # Quick mode (CI): one case per kind of difficulty; the full run covers the whole list.
    cases = [
        fpe("large n = 12", b(a=0.5, n=12)),
        fpe("n = 1 kink, a = 2", b(a=2.0, n=1)),
        fpe("D = 100, n = 3", b(a=0.5, n=3, D=100.0), rescaled(3.0, 0.5, 100.0, 10.0)),
        mc("harmonic ring beyond k_di (k = 1.2 k_di)", b(a=0.5, n=2, N=3, k=1.2 * k_di(3, 0.5))),
        mc("n = 1 kink, a = 2", b(a=2.0, n=1)),
    ]
    if not ctx.quick:
        cases += [
            fpe("tiny a = 1e-3, n = 3", b(a=1e-3, n=3)),
            fpe("large n = 8", b(a=0.5, n=8)),
            fpe("tau = 1e-4, n = 3", b(a=0.5, n=3, tau=1e-4)),
            fpe("tau = 100, n = 3", b(a=0.5, n=3, tau=100.0)),
            fpe("tau_p = 1e3, n = 3", b(a=0.5, n=3, tau_p=1e3)),
            fpe("m = 1e-3 (stiff), n = 3", b(a=0.5, n=3, m=1e-3)),
            fpe("D = 100, n = 1", b(a=0.5, n=1, D=100.0), rescaled(1.0, 0.5, 100.0, 10.0)),
            mc("m = 1e-3 (stiff), n = 3", b(a=0.5, n=3, m=1e-3)),
            mc("large n = 12", b(a=0.5, n=12)),
            mc("tau = 1e-4, n = 3", b(a=0.5, n=3, tau=1e-4)),
            mc("D = 100, n = 3", b(a=0.5, n=3, D=100.0)),
            mc("tiny a = 1e-3, n = 3", b(a=1e-3, n=3)),
        ]
    return cases


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
        "PASS means: accurate to the stated error (exact: stated error 0 plus a relative round-off floor "
        f"of {EXACT_FLOOR:g} against a 40-digit Lyapunov solve; Fokker-Planck and Monte Carlo: 4 combined "
        "error bars against an equivalent rescaled problem where one exists (full run: against Monte Carlo "
        "otherwise), and the stationary identities of docs/model.md §2 within 4 error bars), or clearly "
        "refused or flagged (error naming the problem, or status unstable / not_converged / metastable "
        f"with a message). Each case runs under a {budget:g} s wall-time budget; exceeding it is a hang (FAIL)."
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
