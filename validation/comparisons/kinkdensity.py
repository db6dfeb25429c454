"""The kink's density near its trap, Fokker--Planck against Monte Carlo (a report figure).

At n = 1 the force :math:`-a\\,\\mathrm{sign}(x)` traps slow units near (x, v) = (0, 0): their
swings shrink exponentially and never stop, and the stationary law concentrates there like
:math:`P(E < \\varepsilon) \\sim \\varepsilon^\\beta` (:math:`E = m v^2/2 + a|x|`), β ~ 2.4,
1.9, 0.5 for a = 0.5, 1, 2. The figure compares the density of the (x, v) marginal averaged
over energy shells,

.. math::

    \\bar p(\\varepsilon_1, \\varepsilon_2) = \\frac{P(\\varepsilon_1 < E < \\varepsilon_2)}
    {A(\\varepsilon_2) - A(\\varepsilon_1)},\\qquad A(\\varepsilon) = \\frac{8}{3}
    \\sqrt{\\frac{2}{m}}\\,\\frac{\\varepsilon^{3/2}}{a},

(A the area of :math:`E < \\varepsilon`), from the Fokker--Planck level
(:meth:`fpe_harvester.fpe.schemes.xv.kink.KinkLevel.energy_cdf`) and from Monte Carlo states
(:func:`montecarlo.sample.sample_states`, error bars from the spread between paths). Where
Fokker--Planck declines the unit (the strong kink), the second Monte Carlo construction's time
in each shell (:mod:`validation.references.exactflow`) stands in its place: two Monte Carlo
constructions, each with its error bars.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fpe_harvester.errors import NotConvergedError
from fpe_harvester.fpe import stationary
from fpe_harvester.fpe.schemes.xv.kinkdisc import KinkDG, KinkSettings
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats
from montecarlo.sample import sample_states

from ..harness.report import Figure, new_figure, save_figure

__all__ = ["ShellDensity", "shell_density_fpe", "shell_density_mc", "kink_density_figure", "EDGES",
           "v_concentration"]

#: Fokker--Planck tolerance on eta of the figure's levels.
FPE_TOL = 1e-3

#: Energy shells' edges [energy units] (log-spaced).
EDGES = np.logspace(-3.5, 0.25, 16)


@dataclass(frozen=True)
class ShellDensity:
    """Shell-averaged density on the shells ``edges[i] < E < edges[i+1]`` and its error
    (``None``: no error estimate)."""

    edges: np.ndarray
    density: np.ndarray
    error: np.ndarray | None
    label: str

    @property
    def centres(self) -> np.ndarray:
        return np.sqrt(self.edges[1:] * self.edges[:-1])


def shell_area(eps: np.ndarray, a: float, m: float = 1.0) -> np.ndarray:
    """Area of the region :math:`m v^2/2 + a|x| < \\varepsilon` of the (x, v) plane."""
    return (8.0 / 3.0) * math.sqrt(2.0 / m) * np.asarray(eps) ** 1.5 / a


def shell_density_fpe(level, edges: np.ndarray, label: str) -> ShellDensity:
    """Shell densities of a Fokker--Planck kink level (:class:`~fpe_harvester.fpe.schemes.xv.kink.KinkLevel`)."""
    P = level.energy_cdf(edges, nodes=48)
    A = shell_area(edges, level.mesh.a, level.mass)
    return ShellDensity(edges, np.diff(P) / np.diff(A), None, label)


def shell_density_mc(h: Harvester, edges: np.ndarray, *, samples: int, paths: int, seed: int = 7,
                     dt: float = 0.01) -> ShellDensity:
    """Shell densities from Monte Carlo states (one sample per time unit per path); the error
    is the standard error of the per-path shell fractions."""
    s = sample_states(h, samples=samples, paths=paths, every=1.0, dt=dt, seed=seed)
    E = 0.5 * h.params.m * s[..., 0, 1] ** 2 + h.a * np.abs(s[..., 0, 0])        # (samples, paths)
    counts = np.stack([np.mean((E > lo) & (E <= hi), axis=0) for lo, hi in zip(edges[:-1], edges[1:])])
    frac = counts.mean(axis=1)
    err = counts.std(axis=1, ddof=1) / math.sqrt(paths)
    dA = np.diff(shell_area(edges, h.a, h.params.m))
    return ShellDensity(edges, frac / dA, err / dA, f"Monte Carlo, dt = {dt:g}, {samples * paths:.0e} states")


def v_concentration(h: Harvester, deltas: tuple[float, ...] = (1e-3, 1e-2, 1e-1), *, samples: int = 400,
                    paths: int = 512, dt: float = 0.01, seed: int = 3) -> dict[str, list[float]]:
    """How strongly the law of the voltage V concentrates at V = 0 (Monte Carlo states).

    Trapped units of the kink relax toward rest and their voltage decays like
    :math:`e^{-t/\\tau_p}`; when trapped spells are long against :math:`\\tau_p`, the marginal
    of V has an integrable spike at 0, :math:`P(|V| < \\delta) \\sim \\delta^{\\beta_V}` with
    :math:`\\beta_V < 1` (a smooth density has :math:`\\beta_V = 1`), which no Hermite
    series in V resolves. Returns, for :math:`\\delta` in ``deltas`` (units of the standard
    deviation of V), the fractions :math:`P(|V| < \\delta\\,\\mathrm{sd}(V))` with their standard
    errors (spread between paths, one state every 2 time units after a burn-in of 30), and the
    local exponents :math:`\\beta_V` between successive deltas.
    """
    s = sample_states(h, samples=samples, paths=paths, every=2.0, t_burn=30.0, dt=dt, seed=seed)
    V = s[..., 0, 2]                                                     # (samples, paths)
    sd = float(V.std())
    fr = np.stack([np.mean(np.abs(V) < d * sd, axis=0) for d in deltas])  # (deltas, paths)
    p = fr.mean(axis=1)
    with np.errstate(divide="ignore"):
        beta = np.diff(np.log(p)) / np.diff(np.log(np.asarray(deltas)))
    return {"delta_sd": list(deltas), "fraction": p.tolist(),
            "fraction_err": (fr.std(axis=1, ddof=1) / math.sqrt(paths)).tolist(),
            "exponent": beta.tolist(), "sd_V": sd}


def _fpe_levels(h: Harvester, solved: Callable[[Harvester], Stats] | None = None
                ) -> tuple[bool, list[ShellDensity]]:
    """Whether the solver converged, and the certified level, else its first levels labelled so.

    ``solved`` (optional) gives the Fokker--Planck result of ``h`` at :data:`FPE_TOL` if it is known
    already (the validation run's cache): when it did not converge, the levels are shown
    without solving it again (at a = 2 the failed solve costs ~50 s)."""
    known = None if solved is None else solved(h)
    if known is None or known.ok:
        sol = stationary(h, tol=FPE_TOL, max_seconds=60.0)
        st = sol.stats
        if sol.level is not None and st.ok:
            lv = sol.level
            return True, [shell_density_fpe(lv, EDGES, f"Fokker-Planck, M = {lv.M}, degree {lv.order}: "
                                                       f"eta {st.eta:.5f} +- {st.eta_err:.1e}")]
    disc = KinkDG.build(h, KinkSettings(), FPE_TOL)
    out = []
    for M in (4, 6):
        try:
            lv = disc.solve(M, 1)
        except NotConvergedError:
            break  # a level the solver cannot solve is not drawn; the check fails on the unconverged solver
        out.append(shell_density_fpe(lv, EDGES, f"Fokker-Planck level M = {M} (not converged): "
                                                f"eta {lv.moments['eta']:.4f}"))
    return False, out


#: Largest |FP - MC| / error_MC over the shells for the densities to agree.
SIGMAS = 4.0


def kink_density_figure(out: Path, quick: bool, a_values: tuple[float, ...] = (0.5, 2.0),
                        solved: Callable[[Harvester], Stats] | None = None,
                        second: Callable[[Harvester], ShellDensity | None] | None = None,
                        ) -> tuple[Figure, list[tuple[str, bool, str]]]:
    """The figure, and per a one comparison (label, passed, detail): on every shell with a Monte
    Carlo count, the certified Fokker--Planck level's shell densities within :data:`SIGMAS` Monte
    Carlo standard errors (fails when the solver does not converge) or, where ``second(h)`` gives the
    second Monte Carlo construction's shells (Fokker--Planck declines the unit), those within
    :data:`SIGMAS` combined standard errors. ``solved``: the Fokker--Planck result at
    :data:`FPE_TOL` where already known (see :func:`_fpe_levels`)."""
    fig, axes = new_figure((5.5 * len(a_values), 4.2), ncols=len(a_values))
    lines = []
    # full: 4x the quick run's states (2e6 took two minutes per a; the shells' Monte Carlo errors
    # grow by ~2.2x, still well below the levels' differences at a = 2)
    samples, paths = (300, 400) if quick else (600, 800)
    for ax, a in zip(np.atleast_1d(axes), a_values):
        h = Harvester.build(a=a, n=1)
        mc = shell_density_mc(h, EDGES, samples=samples, paths=paths)
        ok = mc.density > 0
        ax.errorbar(mc.centres[ok], mc.density[ok], yerr=mc.error[ok], fmt="o", ms=4, color="k", label=mc.label)
        other = second(h) if second is not None else None
        if other is not None:
            lines.append(_mc_vs_mc(ax, a, mc, other, ok))
        else:
            lines.append(_fpe_vs_mc(ax, a, h, mc, ok, solved))
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("E = m v^2/2 + a|x|")
        ax.set_ylabel("density of (x, v), averaged on the shell")
        ax.set_title(f"n = 1, a = {a:g}")
        ax.legend(fontsize=7)
    caption = ("The kink's (x, v) density near its trap (0, 0), averaged on energy shells E = m v^2/2 + a|x| "
               "(log axes): Monte Carlo states (black points, standard errors from the spread between paths) "
               "against Fokker-Planck levels (lines; below the innermost mesh layer a level is a polynomial) or, "
               "where Fokker-Planck declines the unit (the strong kink), against the exact-flow Monte Carlo "
               "(open points), a second construction.")
    return save_figure(fig, out / "kink_density.png", caption), lines


def _fpe_vs_mc(ax, a: float, h: Harvester, mc: ShellDensity, ok: np.ndarray,
               solved: Callable[[Harvester], Stats] | None) -> tuple[str, bool, str]:
    converged, fps = _fpe_levels(h, solved)
    detail = []
    z = np.array([np.inf])
    for i, fp in enumerate(fps):
        ax.loglog(fp.centres, np.abs(fp.density), "-" if i == 0 else "--", label=fp.label)
        z = np.abs(fp.density - mc.density)[ok] / mc.error[ok]
        detail.append(f"{fp.label}: |FP - MC| / error_MC over {int(ok.sum())} shells median "
                      f"{np.median(z):.2g}, max {np.max(z):.2g}")
    passed = converged and bool(np.max(z) <= SIGMAS)
    return (f"kink density near the trap: fpe vs mc, a = {a:g}", passed,
            "; ".join(detail) + ("" if converged else "; the Fokker-Planck solver did not converge"))


def _mc_vs_mc(ax, a: float, mc: ShellDensity, other: ShellDensity, ok: np.ndarray) -> tuple[str, bool, str]:
    both = ok & (other.density > 0)
    ax.errorbar(other.centres[both], other.density[both], yerr=other.error[both], fmt="o", mfc="none", ms=5,
                color="C1", label=other.label)
    z = np.abs(other.density - mc.density)[both] / np.hypot(mc.error, other.error)[both]
    passed = bool(both.sum() >= 3 and np.max(z) <= SIGMAS)
    return (f"kink density near the trap: mc vs exact-flow mc, a = {a:g}", passed,
            f"|MC - exact-flow MC| / combined error over {int(both.sum())} shells with both counts: median "
            f"{np.median(z):.2g}, max {np.max(z):.2g} (pass: max <= {SIGMAS:g}); {other.label}")
