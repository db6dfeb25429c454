"""Error estimates from refinement and the tolerance-driven choice of M and the mesh.

The discretization has two knobs: the Hermite degree M (steps of 2) and the number of
elements (doubling). For a sequence :math:`f_0, f_1, f_2` of one observable on three
successive levels of one knob (the other fixed), with differences
:math:`e_1 = f_1 - f_0`, :math:`e_2 = f_2 - f_1` and ratio :math:`r = |e_2/e_1|`, the
error of :math:`f_2` is estimated by the tail of a geometric series,

.. math::

    \\varepsilon = |e_2|\\,\\max\\Big(1, \\frac{r}{1 - r}\\Big),

never less than the last difference (conservative when convergence is fast), and growing
as the convergence slows (the algebraic convergence of the kink case n = 1). When the
sequence is not yet contracting (:math:`r \\ge 0.9`) the estimate is :math:`10|e_2|` and
the level is flagged as pre-asymptotic.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..model import Harvester
from .discretize import Level, Whitening, solve_level
from .mesh import XMesh

__all__ = ["tail_error", "Plan", "RefinementResult", "refine"]

#: Observables carried through the refinement (each gets its own estimate).
OBSERVABLES = ("eta", "V2", "Pin", "v2", "vV", "x2")


def tail_error(values: Sequence[float]) -> tuple[float, bool]:
    """Error estimate of the last of up to three successive refinements.

    Returns ``(error, asymptotic)``; with two values the last difference is returned and
    ``asymptotic`` is False; with one value the error is ``inf``.

    Examples
    --------
    >>> err, ok = tail_error([1.1, 1.01, 1.001])
    >>> round(err, 6), ok
    (0.009, True)
    """
    if len(values) < 2:
        return math.inf, False
    e2 = abs(values[-1] - values[-2])
    if len(values) < 3:
        return e2, False
    e1 = abs(values[-2] - values[-3])
    if e1 == 0.0:
        return e2, e2 == 0.0
    r = e2 / e1
    if r >= 0.9:
        return 10.0 * e2, False
    return e2 * max(1.0, r / (1.0 - r)), True


@dataclass(frozen=True)
class Plan:
    """Starting point and limits of the refinement.

    Attributes
    ----------
    M : int
        Starting (or fixed) Hermite degree, >= 2.
    half_elements : int
        Starting (or fixed) elements per half-domain.
    order : int
        DG polynomial order.
    theta : float
        Domain factor :math:`U(L)/T_{eff}`.
    grading : float
        Mesh grading toward x = 0.
    wall : float
        Wall weight of the mesh monitor.
    fixed : bool
        If True, solve at (M, half_elements) and estimate the error from one refinement
        step of each knob (M + 2, 2 x elements); no adaptation.
    max_M, max_half_elements, max_dofs : int
        Limits; the solve reports NOT_CONVERGED when tol needs more.
    max_seconds : float or None
        Wall-time budget for the adaptation.
    """

    M: int
    half_elements: int
    order: int
    theta: float
    grading: float
    wall: float
    fixed: bool = False
    max_M: int = 24
    max_half_elements: int = 256
    max_dofs: int = 600_000
    max_seconds: float | None = None


@dataclass(frozen=True)
class RefinementResult:
    """Best level, its error estimates and the history of levels computed."""

    best: Level
    errors: dict[str, float]
    error_M: float
    error_x: float
    converged: bool
    reason: str
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0


def refine(h: Harvester, tol: float, plan: Plan, progress: Callable[[str], None] | None = None
           ) -> RefinementResult:
    """Refine M and the mesh until the estimated relative error on eta is below ``tol``.

    At each step the error in M (levels M - 4, M - 2, M on the current mesh) and in the
    mesh (N/4, N/2, N elements at the current M) are estimated with :func:`tail_error`;
    the larger one is refined (M + 2 or twice the elements) until their sum is below
    ``tol * |eta|`` or a limit of ``plan`` is hit.
    """
    t0 = time.perf_counter()
    w = Whitening.of(h)
    L = w.domain(h, plan.theta)
    base = XMesh(L, plan.half_elements, n=h.n, scale=math.sqrt(w.x2), theta=plan.theta,
                 wall=plan.wall, grading=plan.grading)
    cache: dict[tuple[int, int], Level] = {}

    def level(M: int, nh: int) -> Level:
        key = (M, nh)
        if key not in cache:
            cache[key] = solve_level(h, M, base.with_elements(nh), plan.order, w)
            if progress is not None:
                lv = cache[key]
                progress(f"M={M} elements={2 * nh} dofs={lv.dofs} eta={lv.moments['eta']:.10g} "
                         f"({lv.seconds:.2f} s)")
        return cache[key]

    def estimates(M: int, nh: int, fine_M: Level | None = None, fine_x: Level | None = None
                  ) -> tuple[dict[str, float], float, float, bool]:
        if fine_M is not None:
            seq_M = [level(M, nh), fine_M]
            seq_x = [level(M, nh), fine_x]
        else:
            seq_M = [level(m, nh) for m in (M - 4, M - 2, M) if m >= 2]
            seq_x = [level(M, n) for n in (nh // 4, nh // 2, nh) if n >= 1 and (n == nh or nh % n == 0)]
        errs: dict[str, float] = {}
        asym = True
        eM = ex = 0.0
        for name in OBSERVABLES:
            em, am = tail_error([lv.moments[name] for lv in seq_M])
            ey, ay = tail_error([lv.moments[name] for lv in seq_x])
            errs[name] = em + ey
            if name == "eta":
                eM, ex, asym = em, ey, am and ay
        return errs, eM, ex, asym

    if plan.fixed:
        M, nh = plan.M, plan.half_elements
        errs, eM, ex, _ = estimates(M, nh, level(M + 2, nh), level(M, 2 * nh))
        best = level(M, nh)
        ok = errs["eta"] <= tol * abs(best.moments["eta"])
        reason = "" if ok else (f"fixed M = {M}, {2 * nh} elements: estimated relative error "
                                f"{errs['eta'] / abs(best.moments['eta']):.2g} > tol = {tol:.2g}")
        return RefinementResult(best, errs, eM, ex, ok, reason, _history(cache), time.perf_counter() - t0)

    M, nh = plan.M, plan.half_elements
    while True:
        best = level(M, nh)
        errs, eM, ex, _ = estimates(M, nh)
        eta = abs(best.moments["eta"])
        if errs["eta"] <= tol * eta:
            return RefinementResult(best, errs, eM, ex, True, "", _history(cache), time.perf_counter() - t0)
        grow_M = eM >= ex
        nxt_M, nxt_nh = (M + 2, nh) if grow_M else (M, 2 * nh)
        na = (nxt_M + 1) * (nxt_M + 2) * (nxt_M + 3) // 6
        dofs = 2 * nxt_nh * (plan.order + 1) * na
        elapsed = time.perf_counter() - t0
        limit = None
        if nxt_M > plan.max_M:
            limit = f"Hermite degree M would exceed max_M = {plan.max_M}"
        elif nxt_nh > plan.max_half_elements:
            limit = f"elements would exceed {2 * plan.max_half_elements}"
        elif dofs > plan.max_dofs:
            limit = f"unknowns would exceed max_dofs = {plan.max_dofs}"
        elif plan.max_seconds is not None and elapsed > plan.max_seconds:
            limit = f"time budget max_seconds = {plan.max_seconds:g} s used up"
        if limit is not None:
            reason = (f"tol = {tol:.2g} not reached: estimated relative error on eta "
                      f"{errs['eta'] / eta:.2g} (Hermite part {eM / eta:.2g}, mesh part {ex / eta:.2g}) "
                      f"at M = {M}, {2 * nh} elements; {limit}")
            return RefinementResult(best, errs, eM, ex, False, reason, _history(cache),
                                    time.perf_counter() - t0)
        M, nh = nxt_M, nxt_nh


def _history(cache: dict[tuple[int, int], Level]) -> list[dict[str, Any]]:
    return [lv.summary() for _, lv in sorted(cache.items())]
