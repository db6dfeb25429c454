"""Tolerance-driven choice of the Hermite degree M and the mesh, with error estimates.

The refinement raises M (steps of 2) on a mesh of knob ``size`` (scheme x: elements per half)
(:func:`_hermite`) until the Hermite error (:func:`~.estimate.tail_error` of the last three
levels; for n < 2 at least the relative tail of V2 and of Pin, see :mod:`.estimate`) is below
:math:`(1 - s)\\,tol` (s = :data:`MESH_SHARE`). Then the mesh is checked
(:func:`_mesh_check`) at the cheaper degree M - 4 against a mesh twice as fine; if the
mesh error is above the rest of tol, the elements double and the Hermite sequence is
redone on the finer mesh from the same M (its lower degrees are cheap). A Hermite sequence
that stops contracting triggers the mesh check early: unresolved high modes are a mesh
problem.

Why this order (and not a certificate from neighbouring levels, nor a mesh chosen at a low
degree first): the measurements are in the methods notes (docs/methods.md, Fokker-Planck design notes).

With the element-wise discretization (:class:`~.schemes.x.adapt.AdaptiveHermiteDG`, ``mesh="adaptive"``)
"twice the elements" is the mesh whose marked elements are bisected (all of them when M
outgrows the mesh), the first mesh check refines at once if it finds more than
:data:`EARLY_SHARE` of tol, and checks from M = 10 on are made at M >= 8.

A level that fails or gives unphysical moments (V2, Pin, v2, x2 <= 0) is dropped when it
only feeds an estimate; when the level that would carry the result fails, the refinement
stops. At a stop or a limit (max_M, elements, memory, max_seconds) the result is
NOT_CONVERGED with the best estimate computed so far, the one with the smallest estimated
error (not the finest), or none when no estimate is smaller than its value.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import NotConvergedError
from .estimate import mesh_error, tail_error
from .protocol import Discretization, Level, RefinementPlan

__all__ = ["Estimate", "RefinementResult", "refine", "MESH_SHARE", "Levels",
           "hermite_estimate", "predicted_seconds", "stalled"]

#: Observables carried through the refinement (each gets its own estimate).
OBSERVABLES = ("eta", "V2", "Pin", "v2", "vV", "x2")

#: Share of tol given to the mesh error; the Hermite error gets the rest.
MESH_SHARE = 0.25

#: A discretization that refines early (``refine_early``) does so when the first mesh check
#: finds more than this share of tol: with the Hermite part at most 1 - MESH_SHARE of tol, a
#: mesh part above half of it is likely to fail the final check (docs/methods.md, Fokker-Planck design notes).
EARLY_SHARE = 0.5


@dataclass(frozen=True)
class Estimate:
    """Values of the observables with their error estimates.

    ``moments`` are the level's; ``hermite`` and ``mesh`` the two parts of the error of each observable;
    ``level`` the level the fields (density, conditional means) come from;
    ``mesh_checked`` says whether the mesh part was measured for this estimate or carried
    over from the last check (infinite before any).
    """

    moments: dict[str, float]
    hermite: dict[str, float]
    mesh: dict[str, float]
    level: Level
    mesh_checked: bool = False

    @property
    def errors(self) -> dict[str, float]:
        """Total error estimate of each observable (Hermite part + mesh part)."""
        return {name: self.hermite[name] + self.mesh[name] for name in self.hermite}

    @property
    def error_M(self) -> float:
        """Hermite part of the error on eta."""
        return self.hermite["eta"]

    @property
    def error_x(self) -> float:
        """Mesh part of the error on eta."""
        return self.mesh["eta"]

    @property
    def relative(self) -> float:
        """Estimated relative error on eta."""
        return (self.hermite["eta"] + self.mesh["eta"]) / abs(self.moments["eta"])


@dataclass(frozen=True)
class RefinementResult:
    """Best estimate, whether it meets tol, why not, and the history of levels computed."""

    best: Estimate | None
    converged: bool
    reason: str
    history: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0


class _Stop(Exception):
    """A limit of the plan, or the failure of a level that would carry the result."""


class Levels:
    """Solved levels of one refinement, keyed by (M, size), with the plan's limits."""

    def __init__(self, disc: Discretization, plan: RefinementPlan, progress: Callable[[str], None] | None) -> None:
        self.disc, self.plan, self.progress = disc, plan, progress
        self.cache: dict[tuple[int, int], Level] = {}
        self.failed: dict[tuple[int, int], str] = {}
        self.t0 = time.perf_counter()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def limit(self, M: int, nh: int) -> str:
        """Why level (M, nh) may not be computed ('' if it may)."""
        plan, disc = self.plan, self.disc
        if M > plan.max_M:
            return f"Hermite degree M = {M} would exceed max_M = {plan.max_M}"
        if nh > plan.max_size:
            return f"{disc.describe(nh)} would exceed {disc.describe(plan.max_size)}"
        if disc.unknowns(M, nh) > plan.max_dofs:
            return f"unknowns would exceed max_dofs = {plan.max_dofs}"
        gb = disc.gigabytes(M, nh)
        if gb > plan.memory_limit:
            return (f"memory: level M = {M}, {disc.describe(nh)} would need about {gb:.3g} GB, more "
                    f"than max_gb = {plan.memory_limit:.3g} GB")
        if plan.max_seconds is not None:
            need = predicted_seconds(self.cache, M, nh, disc)
            if self.elapsed + need > plan.max_seconds:
                return (f"time budget max_seconds = {plan.max_seconds:g} s: {self.elapsed:.3g} s used, "
                        f"the next level (M = {M}, {disc.describe(nh)}) would need about {need:.3g} s more")
        return ""

    def get(self, M: int, nh: int) -> Level:
        """Level (M, nh); raises :class:`_Stop` at a limit or if it fails."""
        key = (M, nh)
        if key in self.cache:
            return self.cache[key]
        if key in self.failed:
            raise _Stop(self.failed[key])
        why = self.limit(M, nh)
        if why:
            raise _Stop(why)
        lower = max((m for (m, k) in self.cache if k == nh and m < M), default=None)
        try:
            lv = self.disc.solve(M, nh, None if lower is None else self.cache[(lower, nh)])
        except (ArithmeticError, ValueError, np.linalg.LinAlgError, NotConvergedError) as exc:
            self.failed[key] = f"level M = {M}, {self.disc.describe(nh)} failed ({exc})"
            raise _Stop(self.failed[key]) from exc
        bad = _unphysical(lv)
        if bad:
            self.failed[key] = f"level M = {M}, {self.disc.describe(nh)} is unphysical ({bad})"
            raise _Stop(self.failed[key])
        self.cache[key] = lv
        if self.progress is not None:
            self.progress(f"M={M} ({self.disc.describe(nh)}) dofs={lv.dofs} eta={lv.moments['eta']:.10g} "
                          f"({lv.seconds:.2f} s)")
        return lv

    def get_or_none(self, M: int, nh: int) -> Level | None:
        """Level (M, nh), or None if it fails (limits still raise)."""
        if (M, nh) not in self.cache and (M, nh) not in self.failed:
            why = self.limit(M, nh)
            if why:
                raise _Stop(why)
        try:
            return self.get(M, nh)
        except _Stop:
            if (M, nh) in self.failed:
                return None
            raise

    def history(self) -> list[dict[str, Any]]:
        return [lv.summary() for _, lv in sorted(self.cache.items())]


def refine(disc: Discretization, tol: float, plan: RefinementPlan, progress: Callable[[str], None] | None = None
           ) -> RefinementResult:
    """Refine M and the mesh of ``disc`` until the estimated relative error on eta is below ``tol``.

    See the module docstring. ``plan`` gives the starting level (``M``, ``size``:
    the discretization's mesh knob) and the limits. Returns the best estimate (the one that
    meets tol, or at a limit the one with the smallest estimated error) and the history of
    the levels.
    """
    levels = Levels(disc, plan, progress)
    found: list[Estimate] = []
    try:
        if plan.fixed:
            est = _fixed(levels, plan.M, plan.size)
            ok = est.relative <= tol
            reason = "" if ok else (f"fixed M = {plan.M}, {disc.describe(plan.size)}: estimated "
                                    f"relative error {est.relative:.2g} > tol = {tol:.2g}")
            return RefinementResult(est, ok, reason, levels.history(), levels.elapsed)
        M, nh, mesh = plan.M, plan.size, math.inf
        while True:
            est, why = _hermite(levels, nh, M, tol, mesh, found)
            if why == "resolution":
                disc.outgrown(nh)  # an element-wise refinement bisects all elements this time
                nh *= 2  # M is at the most this mesh carries: twice the elements, same M
                M = est.level.M if est is not None else M
                continue
            if why == "mesh":
                nh *= 2  # the early mesh check failed and refining is cheap: refine now
                M, mesh = est.level.M, math.inf  # the new mesh gets its own early check
                continue
            M = est.level.M
            est = _mesh_check(levels, est, nh, enough=MESH_SHARE * tol)
            found.append(est)
            if est.relative <= tol:
                return RefinementResult(est, True, "", levels.history(), levels.elapsed)
            if est.error_x <= MESH_SHARE * tol * abs(est.moments["eta"]):
                M += 2  # the Hermite part is what is left (a stalled sequence came here early)
            else:
                nh *= 2
            mesh = est.error_x / abs(est.moments["eta"])
    except _Stop as stop:
        return _stopped(str(stop), found, levels, tol)


def _hermite(levels: Levels, nh: int, M: int, tol: float, mesh: float, found: list[Estimate]
             ) -> tuple[Estimate | None, str]:
    """Raise M (steps of 2) on ``nh`` elements per half until the Hermite error is below
    ``(1 - MESH_SHARE) * tol`` (returns ``"converged"``), the sequence stops contracting at
    M >= 10 (``"stalled"``: the mesh is suspect), or M would exceed what the mesh carries,
    the discretization's ``max_degree`` of the mesh (``"resolution"``). Every
    estimate on the way is appended to ``found``, its mesh part the last relative mesh
    error ``mesh``.

    The first estimate at M >= ``mesh_check_degree`` + 4 on a mesh not yet checked gets a mesh check at
    M - 2 while that is cheap, so that every later estimate (and a stop at a limit)
    carries a measured mesh error. A discretization whose refinement step is cheap
    (``refine_early``, the element-wise one) refines right away when that check fails
    (returns ``"mesh"``); the uniform one does not refine the mesh: for steep potentials the mesh error at a low
    degree overestimates that at high M (docs/methods.md, Fokker-Planck design notes), hence the check at M - 2 >= 8.
    """
    algebraic = levels.disc.algebraic
    est = None
    while True:
        if M > levels.disc.max_degree(nh):
            return est, "resolution"
        est = hermite_estimate(levels, nh, M, algebraic, mesh)
        m_check = levels.disc.mesh_check_degree
        if est is not None and M >= m_check + 4 and not math.isfinite(mesh):
            est = _mesh_check(levels, est, nh, M - 2, enough=MESH_SHARE * tol)
            mesh = est.error_x / abs(est.moments["eta"])
            if levels.disc.refine_early and mesh > EARLY_SHARE * tol:
                found.append(est)
                return est, "mesh"
        if est is not None:
            found.append(est)
            if est.error_M <= (1.0 - MESH_SHARE) * tol * abs(est.moments["eta"]):
                return est, "converged"
            if M >= 10 and stalled([lv.moments["eta"] for lv in _sequence(levels, nh, M)][-3:]):
                return est, "stalled"
        M += 2


def stalled(values: Sequence[float]) -> bool:
    """True if the last step of a refinement sequence is not smaller than the one before,
    or at least half of it with the opposite sign (not a converging sequence)."""
    if len(values) < 3:
        return False
    e1, e2 = values[-2] - values[-3], values[-1] - values[-2]
    return abs(e2) >= abs(e1) or (e1 * e2 < 0.0 and abs(e2) >= 0.5 * abs(e1))


def _sequence(levels: Levels, nh: int, M: int) -> list[Level]:
    """The levels M - 6, M - 4, M - 2, M on ``nh`` (lower ones solved as needed); a failed
    lower level ends the sequence (a low Hermite truncation may lose positivity)."""
    seq = [levels.get(M, nh)]
    for m in range(M - 2, max(M - 8, 1), -2):
        lv = levels.get_or_none(m, nh)
        if lv is None:
            break
        seq.insert(0, lv)
    return seq


def hermite_estimate(levels: Levels, nh: int, M: int, algebraic: bool, mesh_guess: float
                     ) -> Estimate | None:
    """Estimate at degree M on ``nh``: the Hermite part from the levels M - 6 .. M (steps
    of 2; a failed lower level ends the sequence), the mesh part ``mesh_guess`` (relative,
    from the last mesh check; infinite before the first). None while fewer than three
    levels are available."""
    seq = _sequence(levels, nh, M)
    if len(seq) < 3:
        return None
    top = seq[-1]
    degs = [lv.M for lv in seq]
    values = {name: [lv.moments[name] for lv in seq] for name in OBSERVABLES}
    moments = dict(top.moments)
    hermite = {name: tail_error(v[-3:], degs[-3:])[0] for name, v in values.items()}
    if algebraic:
        # eta mixes a fast moment (V2 ~ <vV>) with a slow one (Pin ~ <v^2>, from the
        # concentration of the density at x = 0), so its own sequence shows a
        # pre-asymptotic exponent that underestimates its tail (see :mod:`.estimate`): its
        # error is at least the larger relative tail of V2 and Pin.
        rel = max(hermite["V2"] / abs(moments["V2"]), hermite["Pin"] / abs(moments["Pin"]))
        hermite["eta"] = max(hermite["eta"], rel * abs(moments["eta"]))
    mesh = {name: mesh_guess * abs(moments[name]) if math.isfinite(mesh_guess) else math.inf
            for name in OBSERVABLES}
    return Estimate(moments, hermite, mesh, top)


def _mesh_check(levels: Levels, est: Estimate, nh: int, Mc: int | None = None,
                enough: float = 0.0) -> Estimate:
    """The mesh error of ``nh`` elements per half, measured at M - 4 (at least its
    ``mesh_check_degree``, and at least the discretization's ``check_floor`` if that is
    below M - 2, at most its ``check_ceiling``; or at ``Mc``)
    against twice the elements (the next mesh of the discretization).

    With the difference d of the two meshes and an error :math:`\\propto N^{-q}`, the
    error of the coarser is :math:`d/(1 - 2^{-q})`, d plus the finer one's
    (:func:`~.estimate.mesh_error`); q is the observed order when a third mesh (half the
    elements, solved when the degree is low) contracts, capped to [1, p + 1], else 1 (the
    bound 2d for any order >= 1). The third mesh is solved only if 2d on eta is
    above ``enough`` (relative): it can only sharpen the estimate.

    The mesh error changes with M, in both directions, so a check at a lower degree is an
    estimate, not a bound; the benchmark checks the reported against the actual error.
    """
    M = est.level.M
    if Mc is None:
        floor = levels.disc.check_floor
        Mc = min(M, max(M - 4, min(floor, M - 2), levels.disc.mesh_check_degree))
        ceiling = levels.disc.check_ceiling
        Mc = Mc if ceiling is None else min(Mc, ceiling)
    a, b = levels.get(Mc, nh), levels.get(Mc, 2 * nh)
    # A third, coarser mesh gives the observed order, but only at a low degree: at high M
    # a coarse mesh is numerically meaningless for steep potentials.
    coarse = None
    d = abs(a.moments["eta"] - b.moments["eta"]) / abs(a.moments["eta"])
    if (2.0 * d > enough and Mc <= levels.disc.mesh_check_degree + 2 and nh % 2 == 0
            and Mc <= levels.disc.max_degree(nh // 2)):
        coarse = levels.get_or_none(Mc, nh // 2)
    meshes = ([coarse] if coarse is not None else []) + [a, b]
    sizes = [lv.size for lv in meshes]
    mesh = {}
    for name in OBSERVABLES:
        values = [lv.moments[name] for lv in meshes]
        # the error of nh elements is that of 2 nh plus their difference
        mesh[name] = abs(values[-2] - values[-1]) + mesh_error(sizes, values, levels.disc.order)
    return Estimate(est.moments, est.hermite, mesh, est.level, True)


def _fixed(levels: Levels, M: int, nh: int) -> Estimate:
    """A fixed level with the error of one refinement step of each knob: the Hermite part
    :math:`|f(M) - f(M+2)|` plus the tail of M - 2, M, M + 2, the mesh part the difference
    to twice the elements."""
    top = levels.get(M, nh)
    nxt = levels.get(M + 2, nh)
    seq = [lv for m in (M - 2, M) if m >= 2 and (lv := levels.get_or_none(m, nh)) is not None] + [nxt]
    fine = levels.get(M, 2 * nh)
    hermite, mesh = {}, {}
    for name in OBSERVABLES:
        vals = [lv.moments[name] for lv in seq]
        hermite[name] = abs(nxt.moments[name] - top.moments[name]) + tail_error(vals, [lv.M for lv in seq])[0]
        mesh[name] = abs(fine.moments[name] - top.moments[name])
    return Estimate(dict(top.moments), hermite, mesh, top, True)


def _stopped(why: str, found: list[Estimate], levels: Levels, tol: float) -> RefinementResult:
    """NOT_CONVERGED: the estimate with the smallest error found so far, if it means anything.

    If no estimate has a measured mesh error yet, the one with the smallest Hermite error
    gets a mesh check (unless that too hits a limit or fails). An estimate whose error is
    not smaller than its value (or none at all) is no estimate: then ``best`` is None and
    the reason says what to do.
    """
    good = [e for e in found if math.isfinite(e.relative) and e.relative < 1.0]
    hermite_only = [e for e in found if math.isfinite(e.error_M)]
    if not good and hermite_only:
        est = min(hermite_only, key=lambda e: e.error_M / abs(e.moments["eta"]))
        try:
            est = _mesh_check(levels, est, est.level.size)
        except _Stop:
            pass
        else:
            good = [est] if est.relative < 1.0 else []
    budget = levels.plan.max_seconds
    if budget is not None and ("time budget" in why or levels.elapsed >= 0.95 * budget):
        advice = f"the time budget stopped it: raise max_seconds (now {budget:g} s), or use method='mc'"
    else:
        advice = levels.disc.advice
    if not good:
        reason = f"tol = {tol:.2g} not reached and no error estimate: {why}; {advice}"
        return RefinementResult(None, False, reason, levels.history(), levels.elapsed)
    best = min(good, key=lambda e: e.relative)
    if best.relative <= tol and best.mesh_checked:
        # an estimate on the way met tol as a whole although its Hermite part alone was not
        # below its share when it was made (a limit stopped the search for a cheaper one)
        return RefinementResult(best, True, "", levels.history(), levels.elapsed)
    checked = "" if best.mesh_checked else " (mesh part from the last mesh check)"
    reason = (f"tol = {tol:.2g} not reached: estimated relative error on eta {best.relative:.2g} "
              f"(Hermite part {best.error_M / abs(best.moments['eta']):.2g}, mesh part "
              f"{best.error_x / abs(best.moments['eta']):.2g}{checked}) at M = {best.level.M}, "
              f"{best.level.elements} elements; stopped: {why}")
    return RefinementResult(best, False, reason, levels.history(), levels.elapsed)


def _unphysical(lv: Level) -> str:
    """Why the moments of ``lv`` cannot be a density's (empty if they can)."""
    mo = lv.moments
    for name in ("V2", "Pin", "v2", "x2", "eta"):
        if not math.isfinite(mo[name]) or mo[name] <= 0.0:
            return f"{name} = {mo[name]:.3g}"
    return ""


def predicted_seconds(cache: dict[tuple[int, int], Level], M: int, nh: int, disc: Discretization
                      ) -> float:
    """Predicted wall time (s) of level (M, nh) from the costliest measured level.

    Cost :math:`w\\,u^q` with ``(w, u) = disc.work(M, nh)`` (1-D: elements and the block
    size :math:`n_b`; the dense block LU gives q = 3 asymptotically, but at moderate M
    assembly and O(n_b^2) work dominate). q is measured from the two costliest levels on
    one mesh and clipped to ``disc.work_exponents`` (timings are noisy on a busy machine;
    the upper end when only one level is known).
    """
    if not cache:
        return 0.0
    lo, hi = disc.work_exponents
    cost = lambda key, q: disc.work(*key)[0] * disc.work(*key)[1] ** q  # noqa: E731
    ranked = sorted(cache.items(), key=lambda kv: cost(kv[0], hi))
    (m0, k0), lv0 = ranked[-1]
    q = hi
    same = [(m, lv) for (m, k), lv in ranked[:-1] if k == k0 and m < m0]
    if same and lv0.seconds > 0.0:
        m1, lv1 = same[-1]
        u0, u1 = disc.work(m0, k0)[1], disc.work(m1, k0)[1]
        if lv1.seconds > 0.0 and u0 > u1:
            q = min(max(math.log(lv0.seconds / lv1.seconds) / math.log(u0 / u1), lo), hi)
    return lv0.seconds * cost((M, nh), q) / cost((m0, k0), q)
