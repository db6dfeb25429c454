"""Cross-checks between the three solvers.

* exact vs Monte Carlo on harmonic rings (N = 1, 2, 3, 5);
* Fokker--Planck vs Monte Carlo on single nonlinear units (n x a grid), except where Fokker--Planck
  declines (its domain rule): there, and at the strong kink (n = 1 and 1.25, a = 2) in any case,
  the product's Monte Carlo vs the exact-flow construction (:mod:`validation.comparisons.strongkink`);
* Fokker--Planck vs exact on the harmonic unit (n = 2);
* the Fourier-mode exact solution vs a dense 4N x 4N Lyapunov solve (scipy) for small N.

The stationary identities of every result computed in the run are the closing section's
(:mod:`validation.sections.identities`).

Each comparison of a quantity ``q`` passes when
:math:`|q_1 - q_2| \\le 4\\sqrt{\\delta_1^2 + \\delta_2^2} + \\text{floor}` (see
:func:`validation.harness.checks.agree`).
"""

from __future__ import annotations

import math

import numpy as np

from fpe_harvester.exact import dense_covariance, k_di
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats, Status

from ..harness.checks import CheckResult, Context, agree, expect
from ..harness.report import Section
from ..comparisons.strongkink import STRONG_CAP, STRONG_KINK, declines, mc_vs_flow

__all__ = ["run", "HARMONIC_RINGS", "NONLINEAR_GRID", "QUICK_NONLINEAR", "MAX_REL_TOL"]

#: (N, k) of the harmonic rings compared with Monte Carlo (a = 0.5; all inside the stable range).
HARMONIC_RINGS = ((1, 0.0), (2, -0.15), (3, -0.25), (5, -0.2))
#: (n, a) grid of single nonlinear units compared between Fokker--Planck and Monte Carlo.
NONLINEAR_GRID = tuple((n, a) for n in (1.0, 1.5, 3.0, 4.0, 8.0) for a in (0.5, 1.0, 2.0))
#: The subset used in quick mode: the kink, a non-integer n and a steep potential.
QUICK_NONLINEAR = ((1.0, 0.5), (1.5, 1.0), (4.0, 2.0))
#: a of the harmonic units solved by Fokker--Planck against the exact solver, and the
#: tolerance asked for (keyed by quick mode).
_FPE_VS_EXACT_A = {True: (0.5, 2.0), False: (0.5, 1.0, 2.0)}
_FPE_VS_EXACT_TOL = {True: 1e-4, False: 1e-8}

_SECTION = "Cross-checks"
_COMPARED = ("eta", "V2", "Pin")


#: Largest tolerance of a cross-check relative to the reference value (quick, full): error bars
#: wider than this cannot tell a right answer from a wrong one, so such a comparison fails.
MAX_REL_TOL = {True: 0.1, False: 0.03}


def _compare(label: str, r1: Stats, r2: Stats, *, quick: bool, floor: float = 0.0, rel_floor: float = 0.0,
             names: tuple[str, ...] = _COMPARED) -> list[CheckResult]:
    """Compare two results quantity by quantity within their error bars, the tolerance capped
    (:data:`MAX_REL_TOL`). Both must describe the stationary state: stable or marginal, or not
    converged with a best estimate and its error (then the comparison tests that error bar);
    any other status, or no number, fails."""
    note = f"{r1.method}: {r1.status.value}; {r2.method}: {r2.status.value}"
    bad = [r for r in (r1, r2) if not (r.ok or (r.status is Status.NOT_CONVERGED and r.eta is not None))]
    if bad:
        return [expect(f"{label}: {q}", _SECTION, False,
                       "; ".join(f"{r.method} is {r.status.value} ({r.message})" for r in bad)
                       + ": no stationary number to cross-check") for q in names]
    return [agree(f"{label}: {q}", _SECTION, *r1.value(q), *r2.value(q), floor=floor,
                  rel_floor=rel_floor, max_rel_tol=MAX_REL_TOL[quick], note=note) for q in names]


#: Share of the cap that 4 error bars of a Monte Carlo run may take before it is solved again tighter.
CAP_SHARE = 0.8


def mc_within_cap(ctx: Context, h: Harvester, names: tuple[str, ...] = _COMPARED) -> Stats:
    """Monte Carlo run whose error bars on every compared quantity fit the cap of the check
    (4 errors <= :data:`MAX_REL_TOL`). The run's ``tol`` bounds only eta's error; V2's and
    Pin's are often 2-3 times larger (slow noise: V2 ~4x), so a run whose widest band of 4
    errors exceeds :data:`CAP_SHARE` of the cap is solved again with ``tol`` scaled down by the
    excess (at most 4x, with 4x the time budget; same seed, cached), so that a good result is
    not failed for the width of its bars. Used for results and references alike."""
    mc = ctx.solve(h, "mc")
    if not mc.ok or mc.eta is None:
        return mc
    widths = [4.0 * abs(e / v) for q in names for v, e in [mc.value(q)] if v and e is not None and math.isfinite(e)]
    limit = CAP_SHARE * MAX_REL_TOL[ctx.quick]
    if not widths or max(widths) <= limit:
        return mc
    opts = ctx.options("mc")
    tol = max(opts["tol"] * limit / max(widths), opts["tol"] / 4.0)
    return ctx.solve(h, "mc", tol=tol, max_time=4.0 * opts["max_time"])


def _exact_vs_mc(ctx: Context, N: int, k: float) -> list[CheckResult]:
    ctx.require("mc")
    h = Harvester.build(a=0.5, n=2, N=N, k=k)
    ex = ctx.solve(h, "exact")
    mc = mc_within_cap(ctx, h)
    return _compare(f"exact vs mc: N = {N}, k = {k:g}", mc, ex, quick=ctx.quick)


def _fpe_vs_mc(ctx: Context, n: float, a: float) -> list[CheckResult]:
    ctx.require("fpe", "mc")
    h = Harvester.build(a=a, n=n)
    fp = ctx.solve(h, "fpe")
    if not fp.ok and fp.eta is None:
        # Nothing to compare with: the check fails on the Fokker-Planck side, and a Monte Carlo run
        # narrowed to the cap would buy nothing (the stress section solves it to judge its identities).
        return [expect(f"fpe vs mc: n = {n:g}, a = {a:g}: {q}", _SECTION, False,
                       f"fpe is {fp.status.value} ({fp.message}): no stationary number to cross-check "
                       "(Monte Carlo not run for this check)") for q in _COMPARED]
    mc = mc_within_cap(ctx, h)
    return _compare(f"fpe vs mc: n = {n:g}, a = {a:g}", fp, mc, quick=ctx.quick)


def _fpe_vs_exact(ctx: Context, a: float) -> list[CheckResult]:
    h = Harvester.build(a=a, n=2)
    fp = ctx.solve(h, "fpe", tol=_FPE_VS_EXACT_TOL[ctx.quick])
    ex = ctx.solve(h, "exact")
    return _compare(f"fpe vs exact: n = 2, a = {a:g}", fp, ex, names=("eta", "V2", "Pin", "v2", "vV"),
                    rel_floor=1e-12, quick=ctx.quick)


def table_checks(ctx: Context) -> list[CheckResult]:
    """Every stable result of this run so far whose system has entries in the project's
    reference table (:mod:`validation.references.reftable`), against each of them (a system
    may have a Fokker--Planck and a Monte Carlo entry) within 4 combined errors."""
    from ..references.reftable import CASES, compare

    by_system: dict[Harvester, list[str]] = {}
    for case in CASES:
        by_system.setdefault(case.h, []).append(case.label)
    out = []
    for h, method, r in ctx.cache.results():
        if method == "exact" or not r.ok:
            continue
        for label in by_system.get(h, ()):
            out += [expect(f"{name} [{method}]", _SECTION, ok, detail) for name, ok, detail in compare(label, r)]
    return out


def _kink_density(ctx: Context, sec: Section) -> list[CheckResult]:
    """The kink's (x, v) density near its trap (:mod:`validation.comparisons.kinkdensity`): Monte Carlo
    against Fokker-Planck, or, where Fokker-Planck declines the unit (a = 2), against the exact-flow
    Monte Carlo (:mod:`validation.comparisons.strongkink`); quick mode a = 0.5 only."""
    from ..comparisons.kinkdensity import FPE_TOL, ShellDensity, kink_density_figure, shell_area
    from ..comparisons.strongkink import flow, shells

    a_values = (0.5,) if ctx.quick else (0.5, 2.0)
    ctx.require("mc", *(("fpe",) if any(declines(Harvester.build(a=a, n=1.0)) is None for a in a_values) else ()))
    # the run's Fokker-Planck result of each kink (shared with "fpe vs mc" when the tolerances match)
    # tells whether the solver converges, so a failed solve is not repeated for the figure
    solved = lambda h: ctx.solve(h, "fpe", tol=FPE_TOL)  # noqa: E731

    def second(h: Harvester) -> ShellDensity | None:
        if declines(h) is None:
            return None
        r = flow(ctx, h)
        frac, err = shells(r)
        edges = np.asarray(r.info["edges"])
        dA = np.diff(shell_area(edges, h.a, h.params.m))
        return ShellDensity(edges, frac / dA, err / dA, f"exact-flow Monte Carlo, {r.info['settings']['paths']} "
                                                         f"paths x {r.info['t_run']:g}, h = {r.info['settings']['step']:g}")

    fig, lines = kink_density_figure(ctx.out, ctx.quick, a_values, solved, second)
    sec.figures.append(fig)
    return [expect(label, _SECTION, ok, detail) for label, ok, detail in lines]


def _fourier_vs_dense(ctx: Context, rng: np.random.Generator, N: int) -> list[CheckResult]:
    """Exact (Fourier modes) vs the dense 4N x 4N Lyapunov solve, random parameters and k."""
    out = []
    for _ in range(2):
        params = dict(m=rng.uniform(0.3, 3), gamma=rng.uniform(0.2, 3), Kv=rng.uniform(0.3, 3),
                      Kc=rng.uniform(0.3, 3), sigma=rng.uniform(0.3, 3), tau=rng.uniform(0.2, 5),
                      D=rng.uniform(0.2, 5), tau_p=rng.uniform(0.2, 5))
        a = float(rng.uniform(0.1, 2.0))
        h = Harvester.build(a=a, n=2, N=N, **params)
        if N > 1:
            h = h.replace(k=float(rng.uniform(0.9 * k_di(N, a), 1.0)))
        ex = ctx.solve(h, "exact")
        P = dense_covariance(h)
        p = h.params
        dense = {
            "V2": float(np.mean(np.diag(P)[2::4])),
            "v2": float(np.mean(np.diag(P)[1::4])),
            "vV": float(np.mean(np.diag(P[1::4, 2::4]))),
            "Pin": float(p.sigma * np.mean(np.diag(P[1::4, 3::4]))),
            "x2": float(np.mean(np.diag(P)[0::4])),
        }
        label = f"fourier vs dense Lyapunov: N = {N}, a = {a:.3g}, k = {h.k:.3g}, random params"
        rel = {q: abs(getattr(ex, q) - dense[q]) / abs(dense[q]) for q in dense}
        worst = max(rel, key=rel.__getitem__)
        out.append(agree(f"{label}: worst of V2, Pin, v2, vV, x2 ({worst})", _SECTION, getattr(ex, worst), 0.0,
                         dense[worst], 0.0, rel_floor=1e-10,
                         note="dense 4N x 4N scipy.linalg.solve_continuous_lyapunov; relative differences "
                              + ", ".join(f"{q} {v:.1e}" for q, v in rel.items())))
    return out


def run(ctx: Context) -> Section:
    """All cross-checks; quick mode runs a subset (listed in the section text)."""
    sec = Section("crosscheck", _SECTION)
    rings = HARMONIC_RINGS[::2] if ctx.quick else HARMONIC_RINGS
    grid = QUICK_NONLINEAR if ctx.quick else NONLINEAR_GRID
    dense_N = (1, 2, 3) if ctx.quick else (1, 2, 3, 4, 5, 6)
    fpe_a = _FPE_VS_EXACT_A[ctx.quick]
    sec.text.append(
        "Each comparison passes when both results describe the stationary state (stable, or not converged "
        "with a best estimate and its error, whose error bar is then what is tested) and |a - b| <= "
        "4 sqrt(err_a^2 + err_b^2) + floor, that tolerance being at most "
        f"{MAX_REL_TOL[ctx.quick]:.0%} of the reference value (wider error bars cannot tell right from wrong), "
        "with the errors the solvers report (Monte Carlo: standard error from replicas, time-step bias folded in; "
        "Fokker-Planck: truncation and mesh error; exact: 0, with a relative round-off floor of 1e-12, "
        "1e-10 for the dense Lyapunov solve). "
        f"Monte Carlo settings: {ctx.mc_options} (repeated with a smaller tol when 4 error bars of eta, V2 or Pin "
        f"exceed {CAP_SHARE:g} of the cap); Fokker-Planck settings: {ctx.fpe_options}."
    )
    sec.text.append(
        f"Harmonic rings (a = 0.5) compared with Monte Carlo: (N, k) = {list(rings)}. "
        f"Single nonlinear units (n, a): {list(grid)}. Fokker-Planck vs exact at n = 2, a in {list(fpe_a)}. "
        f"(Fokker-Planck asked for tol = {_FPE_VS_EXACT_TOL[ctx.quick]:g} there.) Dense Lyapunov cross-check for N in {list(dense_N)} with random parameters."
        + (" Quick mode: subsets; the full run covers N = 1, 2, 3, 5 and the whole 5 x 3 grid." if ctx.quick
           else "")
    )
    rng = np.random.default_rng(ctx.seed)
    for N in dense_N:
        sec.checks += ctx.check(f"fourier vs dense: N = {N}", _SECTION,
                                lambda N=N: _fourier_vs_dense(ctx, rng, N))
    for N, k in rings:
        sec.checks += ctx.check(f"exact vs mc: N = {N}, k = {k:g}", _SECTION,
                                lambda N=N, k=k: _exact_vs_mc(ctx, N, k))
    for a in fpe_a:
        sec.checks += ctx.check(f"fpe vs exact: a = {a:g}", _SECTION, lambda a=a: _fpe_vs_exact(ctx, a))
    declined = {(n, a): why for n, a in grid if (why := declines(Harvester.build(a=a, n=n)))}
    for n, a in grid:
        if (n, a) not in declined:
            sec.checks += ctx.check(f"fpe vs mc: n = {n:g}, a = {a:g}", _SECTION,
                                    lambda n=n, a=a: _fpe_vs_mc(ctx, n, a))
    sec.text.append(_strong_text(ctx, declined))
    if not ctx.quick:
        for n, a in dict.fromkeys([*declined, *STRONG_KINK]):
            why = f"Fokker-Planck declines this unit: {declined[(n, a)]}" if (n, a) in declined else ""
            sec.checks += ctx.check(f"mc vs exact-flow mc: n = {n:g}, a = {a:g}", _SECTION,
                                    lambda n=n, a=a, why=why: mc_vs_flow(ctx, n, a, _SECTION, why))
    sec.checks += ctx.check("kink density near the trap", _SECTION, lambda: _kink_density(ctx, sec))
    sec.checks += ctx.check("reference table", _SECTION, lambda: table_checks(ctx))
    for prefix in ("exact vs mc", "fpe vs mc"):
        note = systematic_offset([c for c in sec.checks if c.name.startswith(prefix) and c.name.endswith(": eta")])
        if note:
            sec.text.append(f"**Diagnostic ({prefix}, eta; not a pass/fail check).** {note}")
    return sec


def prefetch(ctx: Context) -> None:
    """Announce this step's Fokker--Planck solves (:meth:`Context.prefetch`): the harmonic units
    against the exact solver, then the grid of single units Fokker--Planck does not decline (the
    kink density figure reuses them)."""
    for a in _FPE_VS_EXACT_A[ctx.quick]:
        ctx.prefetch(Harvester.build(a=a, n=2.0), "fpe", tol=_FPE_VS_EXACT_TOL[ctx.quick])
    for n, a in QUICK_NONLINEAR if ctx.quick else NONLINEAR_GRID:
        h = Harvester.build(a=a, n=n)
        if declines(h) is None:
            ctx.prefetch(h, "fpe")


def _strong_text(ctx: Context, declined: dict[tuple[float, float], str]) -> str:
    """The strong-kink paragraph: where Fokker--Planck declines, and the Monte Carlo rows."""
    said = ("Fokker-Planck declines " + "; ".join(f"n = {n:g}, a = {a:g} ({why})" for (n, a), why in declined.items())
            + ": those units are checked by the two Monte Carlo constructions below, not by Fokker-Planck. "
            if declined else "Fokker-Planck declines none of the grid's units. ")
    if ctx.quick:
        return said + "The strong-kink rows (two Monte Carlo constructions) run in the full run only."
    return (said + "**The strong kink** (n, a) in "
            f"{sorted(set(STRONG_KINK) | set(declined))}: the product's Monte Carlo (settings above) against the "
            "exact-flow Monte Carlo of validation/references/exactflow.py, a second construction sharing no integrator "
            "code with it (exact Gaussian transitions of the linear flow; for n = 1 the kink's force exact on each side, "
            "crossings located on the conditional-mean path; for n > 1 the discrete-gradient force), whose errors add "
            "its step bias bound measured by python -m validation.studies.kink.exactflow_bias. Each row passes when "
            f"|a - b| <= 4 sqrt(err_a^2 + err_b^2), that tolerance at most {STRONG_CAP:.0%} of the value: below the "
            "~8 % bias of a scheme that steps over the kink's crossings at a = 2 (docs/model.md).")


def systematic_offset(checks: list[CheckResult]) -> str:
    """Sign test and mean normalized difference over a group of comparisons.

    Each check passing on its own can hide a common offset; if the errors were unbiased, the
    signs of (a - b) would be fair coin flips. Truncation errors are often one-sided, so this
    is a diagnostic, not a check.
    """
    import math

    pts = [(c.value - c.reference, c.tolerance / 4.0) for c in checks
           if c.value is not None and c.reference is not None and c.tolerance]
    if len(pts) < 3:
        return ""
    n = len(pts)
    pos = sum(d > 0 for d, _ in pts)
    k = max(pos, n - pos)
    p = min(1.0, 2.0 * sum(math.comb(n, j) for j in range(k, n + 1)) / 2.0**n)
    z = [d / s for d, s in pts if s > 0]
    zbar = sum(z) / len(z) if z else float("nan")
    return (f"{pos} of {n} differences are positive (two-sided sign-test p = {p:.2g}); mean normalized "
            f"difference {zbar:+.2f} (in units of the combined error), RMS {math.sqrt(sum(x * x for x in z) / len(z)):.2f}"
            + (". The signs suggest a common offset smaller than the stated errors." if p < 0.01 else "."))
