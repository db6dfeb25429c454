"""The kink discretization as a refinement family: domain, base mesh, Gaussian frame, pilot.

:class:`KinkDG` is what :func:`~...refine.refine` refines for the kink potential (n = 1):
Hermite degree M in (V, xi) in steps of 2, and the DG degree p on a fixed (x, v) mesh
(``size`` s = 1, 2, 4, ...: :math:`p = p_0 + \\log_2 s`; one refinement step raises p by
one). The mesh is graded geometrically toward the trap, deep enough that the layers do not
limit the accuracy, so the error left to the mesh is that of the polynomials, which p
measures (docs/methods.md, Fokker-Planck design notes). It is built in three steps (:meth:`KinkDG.build`):

1. **First guess of the moments** from the equivalent harmonic unit
   (:func:`~...hermite.equivalent_harmonic`), which for a strong kink is poor (a = 2: it gives
   :math:`\\langle v^2\\rangle = 0.005` for 0.018).
2. **Pilot**: one level at M = 4 on the base mesh with the frame of the first guess; its
   moments give the frame of the refinement (:meth:`~.hierarchy.KinkFrame.from_moments`) and the
   domain. The Hermite weight matters at a = 2: widening it fourfold made the M = 8 level
   unphysical (V2 < 0), so the weight is the pilot's covariance, not a safe multiple of it.
3. **Domain** (:func:`kink_domain`): large enough that the outflow through its edge is
   negligible; the refinement reports the outflow rate (``leak``) of every level.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

from ....model import Harvester
from ...hermite import equivalent_harmonic
from ...plane import PlaneMesh
from ...protocol import Discretization
from .hierarchy import KinkFrame
from .kink import GMRES_GIGABYTES, GMRES_RESTART, CoarseCorrection, KinkLevel, solve_kink_level

__all__ = ["KinkDG", "kink_domain", "KinkSettings", "COARSE_DEGREE", "CHECK_CEILING"]

#: Hermite degree of the coarse correction (:class:`~.kink.CoarseCorrection`).
COARSE_DEGREE = 2

#: Weight of V widened WIDEN_V times when the kink is strong against the drive
#: (a / sd(F) > TRAPPING_WIDEN). Trapped units have V close to 0 while running ones reach
#: V ~ K_c tau_p v: the pilot's variance of V is too narrow for the running ones when many
#: are trapped; widening it keeps GMRES converging at a = 1 (a / sd(F) = 1.1), while at a = 0.5
#: (0.57) the pilot's variance converges faster in M (docs/methods.md, Fokker-Planck design notes).
TRAPPING_WIDEN, WIDEN_V = 0.8, 2.0

#: GMRES stops at a relative residual of GMRES_TOL times the tolerance on eta (eta does not
#: move at tighter residuals: docs/methods.md, Fokker-Planck design notes).
GMRES_TOL = 1e-2

#: GMRES iteration budget of a level: GMRES_GROWTH times the most any earlier level of the same
#: solve needed, at least GMRES_FLOOR and at most GMRES_MAXITER: a level that converges needs
#: tens to a few hundred iterations, growing slowly with M, one the expansion does not
#: resolve jumps past a thousand (docs/methods.md, Fokker-Planck design notes).
GMRES_FLOOR, GMRES_GROWTH, GMRES_MAXITER = 600, 4, 1500

#: Highest Hermite degree of a mesh check (:attr:`KinkDG.check_ceiling`).
CHECK_CEILING = 10

#: Degrees of the pilot level, tried in turn until one is physical. M = 2 suffices for
#: a <= 1 (defaults); at a = 2 the harmonic first guess makes it unphysical (V2 < 0) and
#: M = 4 is needed.
PILOT_DEGREES = (2, 4, 6)


@dataclass(frozen=True)
class KinkSettings:
    """Base mesh of the kink discretization (see :class:`~...plane.PlaneMesh`).

    Attributes
    ----------
    layers, ratio : int, float
        Geometric layers toward the trap and their ratio in v (ratio^2 in x).
    core : float
        Energy of the core box in units of :math:`m\\langle v^2\\rangle`.
    bulk_x, bulk_v : int
        Elements outside the core (v: per sign).
    grading : float
        Bulk spacing exponent.
    order : int
        DG degree in x and v.
    shifted, xshifted : bool
        Centre the (V, xi) weight on the regression on v, on x (:class:`~.hierarchy.KinkFrame`).
    """

    layers: int = 4
    ratio: float = 0.3
    core: float = 1.0
    bulk_x: int = 5
    bulk_v: int = 4
    grading: float = 2.5
    order: int = 3
    shifted: bool = False
    xshifted: float = 0.0


def kink_domain(h: Harvester, v2: float, sF: float) -> tuple[float, float]:
    """Half-widths :math:`(L_x, L_v)` of the (x, v) domain.

    The tails in v come from the drive: while :math:`F > a` the unit runs at up to
    :math:`(F - a)/(m\\gamma)`, so :math:`L_v = \\max(4.5\\,s_F/(m\\gamma), 8\\sqrt{\\langle v^2\\rangle})`
    with :math:`s_F` the standard deviation of F. A unit at speed :math:`L_v` climbs the
    potential by :math:`m L_v^2/2`, and a thermal tail reaches :math:`a L_x = 30\\,m\\langle v^2\\rangle`:
    :math:`L_x = \\max(m L_v^2/(2a), 30\\,m\\langle v^2\\rangle/a)`: a narrower domain loses mass
    through its edge, which the identity residuals show.
    """
    p = h.params
    Lv = max(4.5 * sF / (p.m * p.gamma), 8.0 * math.sqrt(v2))
    # U(Lx) = a Lx^n reaches that energy (n = 1: the kink; 1 < n < 2 the same way)
    Lx = (max(p.m * Lv**2 / 2.0, 30.0 * p.m * v2) / h.a) ** (1.0 / h.n)
    return Lx, Lv


def _drive_sd(h: Harvester, mo: dict[str, float]) -> float:
    """Standard deviation of the drive :math:`F = \\sigma\\xi - K_v V` from V2 and Pin
    (:math:`\\langle V\\xi\\rangle` by the identity of :meth:`~.hierarchy.KinkFrame.from_moments`)."""
    p = h.params
    vxi = mo["Pin"] / p.sigma
    Vxi = p.Kc * vxi / (1.0 / p.tau_p + 1.0 / p.tau)
    var = p.sigma**2 * p.D / p.tau + p.Kv**2 * mo["V2"] - 2.0 * p.sigma * p.Kv * Vxi
    return math.sqrt(max(var, 0.25 * p.sigma**2 * p.D / p.tau))


@dataclass(frozen=True)
class KinkDG(Discretization):
    """The kink discretization seen by the refinement (:class:`~fpe_harvester.fpe.protocol.Discretization`)."""

    h: Harvester
    base: PlaneMesh
    frame: KinkFrame
    order: int
    pilot: dict[str, float]
    pilot_seconds: float = 0.0
    rtol: float = 1e-9
    deadline: float | None = None
    algebraic: bool = True
    advice: str = ("the Hermite expansion in (V, xi) does not resolve this density (at a strong kink "
                   "the law of V is multi-scale: trapped units near V = 0, running ones far out); use "
                   "method='mc', or fix M to inspect the levels")
    work_exponents: tuple[float, float] = (1.0, 2.0)
    #: The mesh error hardly depends on M, so the mesh is checked at a low degree (at most
    #: CHECK_CEILING), and the first check, at M = 6, decides the refinement at once
    #: (``refine_early``; docs/methods.md, Fokker-Planck design notes).
    mesh_check_degree: int = 4
    refine_early: bool = True
    _coarse: dict[int, CoarseCorrection] = field(default_factory=dict, repr=False, compare=False)
    _iterations: list[int] = field(default_factory=list, repr=False, compare=False)

    @classmethod
    def build(cls, h: Harvester, settings: KinkSettings | None = None, tol: float = 1e-4,
              deadline: float | None = None) -> KinkDG:
        """Frame and domain from a pilot level (see the module docstring); GMRES solves the
        levels to a relative residual of ``1e-2 tol`` (within [1e-11, 1e-6]; :data:`GMRES_TOL`) and stops at
        the wall-clock ``deadline`` (a :func:`time.perf_counter` value) if given."""
        st = settings or KinkSettings()
        t0 = time.perf_counter()
        guess = _harmonic_guess(h)
        frame = KinkFrame.from_moments(h, guess, shifted=st.shifted)
        mesh = _base_mesh(h, st, guess)
        for M in PILOT_DEGREES:
            pilot = solve_kink_level(h, M, mesh, st.order, frame, rtol=1e-6, deadline=deadline)
            mo = pilot.moments
            if min(mo["V2"], mo["Pin"], mo["v2"], mo["x2"]) > 0.0:
                break
        else:
            raise FloatingPointError(f"the pilot levels of the kink solver (M = {PILOT_DEGREES}) are "
                                     f"unphysical (last: V2 = {mo['V2']:.3g}, Pin = {mo['Pin']:.3g})")
        trapping = h.a / _drive_sd(h, mo)
        if trapping > TRAPPING_WIDEN:
            mo = {**mo, "V2": WIDEN_V * mo["V2"]}
        frame = KinkFrame.from_moments(h, mo, shifted=st.shifted, xshifted=st.xshifted)
        mesh = _base_mesh(h, st, mo)
        return cls(h, mesh, frame, st.order, {k: mo[k] for k in ("eta", "V2", "Pin", "v2", "vV")},
                   time.perf_counter() - t0, min(max(GMRES_TOL * tol, 1e-11), 1e-6), deadline)

    @property
    def check_ceiling(self) -> int:
        return CHECK_CEILING

    def degree(self, size: int) -> int:
        """DG degree p of the mesh knob ``size`` (1, 2, 4, ...)."""
        return self.order + int(round(math.log2(size)))

    def solve(self, M: int, size: int, lower: Any = None) -> KinkLevel:
        guess = lower if isinstance(lower, KinkLevel) else None
        lv = solve_kink_level(self.h, M, self.base, self.degree(size), self.frame, guess=guess, rtol=self.rtol,
                              coarse=self.coarse(size), deadline=self.deadline, maxiter=self.maxiter())
        self._iterations.append(lv.iterations)
        return dataclasses.replace(lv, size=size)

    def maxiter(self) -> int:
        """GMRES budget of the next level: :data:`GMRES_GROWTH` times the most iterations an
        earlier level needed, within [:data:`GMRES_FLOOR`, :data:`GMRES_MAXITER`] (a level that
        needs far more than the others is one the expansion does not resolve)."""
        return min(GMRES_MAXITER, max(GMRES_FLOOR, GMRES_GROWTH * max(self._iterations, default=0)))

    def coarse(self, size: int) -> CoarseCorrection:
        """The coarse-degree correction of the mesh of ``size`` (made once, shared by every M)."""
        if size not in self._coarse:
            self._coarse[size] = CoarseCorrection(self.h, self.base, self.degree(size), self.frame, COARSE_DEGREE)
        return self._coarse[size]

    def unknowns(self, M: int, size: int) -> int:
        """Unknowns of the whole plane (twice those of the half plane that is solved)."""
        return 2 * self.base.elements * (self.degree(size) + 1) ** 2 * math.comb(M + 2, 2)

    def gigabytes(self, M: int, size: int) -> float:
        """The GMRES basis (at most :data:`~.kink.GMRES_GIGABYTES`) and the operator, the
        factors and the levels kept: about 100 doubles per unknown of the half plane
        (measured peak at n = 1, a = 1, M = 20, degree 4, 8.3e5 unknowns: 2.45 GB)."""
        half = self.unknowns(M, size) / 2
        return min(GMRES_GIGABYTES, 8 * half * (GMRES_RESTART + 1) / 1e9) + 100 * 8 * half / 1e9 + 0.2

    def max_degree(self, size: int) -> int:
        return 60  # M and the (x, v) mesh resolve different variables

    def work(self, M: int, size: int) -> tuple[float, float]:
        return float(self.base.elements * (self.degree(size) + 1) ** 2), float(math.comb(M + 2, 2))

    def describe(self, size: int) -> str:
        return f"{2 * self.base.elements} elements of degree {self.degree(size)}"


def _harmonic_guess(h: Harvester) -> dict[str, float]:
    """Moments of the equivalent harmonic unit: V2, Pin, v2, vV."""
    _, P = equivalent_harmonic(h)
    p = h.params
    v2, vV, vxi = float(P[1, 1]), float(P[1, 2]), float(P[1, 3])
    return {"V2": float(P[2, 2]), "Pin": p.sigma * vxi, "v2": v2, "vV": vV}


def _base_mesh(h: Harvester, st: KinkSettings, mo: dict[str, float]) -> PlaneMesh:
    Lx, Lv = kink_domain(h, mo["v2"], _drive_sd(h, mo))
    Ec = st.core * h.params.m * mo["v2"]
    # the core box reaches x_c with U(x_c) = Ec: x_c = Ec / a_eff
    a_eff = Ec / (Ec / h.a) ** (1.0 / h.n)
    return PlaneMesh(Lx=Lx, Lv=Lv, Ec=Ec, a=a_eff, layers=st.layers, ratio=st.ratio,
                     bulk_x=st.bulk_x, bulk_v=st.bulk_v, grading=st.grading)
