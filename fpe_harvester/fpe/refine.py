"""Error estimates from refinement and the tolerance-driven choice of M and the mesh.

The discretization has two knobs: the Hermite degree M (steps of 2) and the number of
elements (doubling). For a sequence :math:`f_0, f_1, f_2` of one observable on three
successive levels of one knob (the other fixed), with differences
:math:`e_1 = f_1 - f_0`, :math:`e_2 = f_2 - f_1` and ratio :math:`r = |e_2/e_1|`, the
error of :math:`f_2` is estimated by the tail of a geometric series,

.. math::

    \\varepsilon = |e_2|\\,\\max\\Big(1, \\frac{r}{1 - r}\\Big),

never less than the last difference (conservative when convergence is fast). In M the
convergence may be algebraic (the kink of n = 1 makes the density non-smooth), where the
geometric tail underestimates: with :math:`f(M) = f_\\infty + C M^{-q}` and steps of 2,
:math:`r = ((M-2)/M)^{q+1}` gives q and the tail :math:`|e_2| M / (2q)`; the larger of the
two estimates is used, and never less than :math:`\\sqrt{|e_1 e_2|}` when the two steps
have opposite signs (steep potentials converge irregularly in M). When the sequence is not
yet contracting (:math:`r \\ge 0.9`) the estimate is :math:`10|e_2|` and the level is
flagged as pre-asymptotic. The mesh error is a Richardson estimate from three meshes
(:func:`mesh_error`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import Harvester
from .discretize import Level, Whitening, solve_level
from .mesh import XMesh

__all__ = ["tail_error", "mesh_error", "reported_eta_error", "Plan", "RefinementResult", "refine",
           "level_gigabytes", "default_memory_gb"]

#: Largest relative spread of eta over the good levels for which a broken-down refinement
#: still returns its finest level (with the spread as error); beyond it, no estimate.
BROKEN_SPREAD = 0.1

#: The mesh error is first estimated once the Hermite part is below this share of tol.
HERMITE_SHARE = 0.5

#: Observables carried through the refinement (each gets its own estimate).
OBSERVABLES = ("eta", "V2", "Pin", "v2", "vV", "x2")


def tail_error(values: Sequence[float], degrees: Sequence[int] | None = None) -> tuple[float, bool]:
    """Error estimate of the last of up to three successive refinements.

    Parameters
    ----------
    values : sequence of float
        The observable on successive levels (coarse to fine).
    degrees : sequence of int, optional
        The Hermite degrees of the levels (steps of 2); enables the algebraic tail.

    Returns
    -------
    (error, asymptotic)
        With two values the last difference and ``False``; with one value ``inf``.

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
    err = e2 * max(1.0, r / (1.0 - r))
    if degrees is not None and (values[-1] - values[-2]) * (values[-2] - values[-3]) < 0.0:
        # Hermite sequences of steep potentials (n = 8) converge irregularly, with steps of
        # alternating sign: a small last step can follow a large one by chance, so there the
        # geometric mean of the two steps is a floor.
        err = max(err, math.sqrt(e1 * e2))
    if degrees is not None and r > 0.0:
        M = degrees[-1]
        q = math.log(r) / math.log((M - 2.0) / M) - 1.0
        if q > 0.0:
            err = max(err, e2 * M / (2.0 * q))
        else:
            err = max(err, 10.0 * e2)
    return err, True


def mesh_error(values: Sequence[float], order: int) -> float:
    """Error of the finest of up to three meshes, each twice as fine as the previous.

    With two meshes the last difference :math:`e_2 = |f_N - f_{N/2}|` (a bound for any
    convergence order >= 1). With three, the observed order
    :math:`q_{obs} = \\log_2(e_1/e_2)` (:math:`e_1 = |f_{N/2} - f_{N/4}|`) is used in the
    Richardson estimate :math:`e_2/(2^q - 1)` with :math:`q = \\min(q_{obs}, p + 1)`: never
    faster than the L2 order p + 1 of the DG discretization (functionals often converge
    faster; the cap keeps the estimate conservative). If the sequence is not contracting at
    least at first order (:math:`q_{obs} < 1`) the estimate stays :math:`e_2`.

    Examples
    --------
    >>> round(mesh_error([1.1, 1.01], 3), 6)
    0.09
    >>> round(mesh_error([1.0017, 1.0001, 1.0], 3), 8)  # observed order 4 = p + 1
    6.67e-06
    """
    if len(values) < 2:
        return math.inf
    e2 = abs(values[-1] - values[-2])
    if len(values) < 3 or e2 == 0.0:
        return e2
    e1 = abs(values[-2] - values[-3])
    if e1 == 0.0 or e2 > 0.5 * e1:
        return e2
    q = min(math.log2(e1 / e2), order + 1.0)
    return e2 / (2.0**q - 1.0)


def reported_eta_error(moments: dict[str, float], errors: dict[str, float]) -> tuple[float, float]:
    """Error on eta to report, and the covariance of the V2 and Pin errors to go with it.

    The error of eta is estimated directly from its own refinement sequence: the
    truncation errors of V2 and Pin are strongly correlated and partly cancel in the
    ratio. The returned covariance (:math:`|\\rho| \\le 1`) makes first-order propagation
    from V2 and Pin as close to that estimate as it can be.
    """
    V2, Pin, eta = moments["V2"], moments["Pin"], abs(moments["eta"])
    a, b = errors["V2"] / V2, errors["Pin"] / Pin
    rel = errors["eta"] / eta
    rel_cov = min(max(rel, abs(a - b)), a + b)
    cov = (a * a + b * b - rel_cov**2) / 2.0 * V2 * Pin
    return errors["eta"], cov


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
        Limits; the solve reports NOT_CONVERGED when tol needs more. ``max_dofs`` counts
        the unknowns of the whole mesh, twice those of the half mesh that is solved (a
        level's ``dofs``).
    max_seconds : float or None
        Wall-time budget for the adaptation (s); no step starts whose predicted cost
        would exceed it.
    max_gb : float or None
        Memory bound of one level's factorization in GB (:func:`level_gigabytes`); no
        level beyond it is attempted. Default (None): half the physical memory.
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
    max_gb: float | None = None

    @property
    def memory_limit(self) -> float:
        """The memory bound in GB (``max_gb`` or half the physical memory)."""
        return default_memory_gb() if self.max_gb is None else self.max_gb

    def mesh(self, h: Harvester, w: Whitening, half_elements: int | None = None) -> XMesh:
        """The x mesh of this plan for ``h``: domain :math:`U(L) = \\Theta T_{eff}` of the
        weight ``w``, ``half_elements`` (default the plan's) elements per half."""
        nh = self.half_elements if half_elements is None else half_elements
        return XMesh(w.domain(h, self.theta), nh, n=h.n, scale=math.sqrt(w.x2), theta=self.theta,
                     wall=self.wall, grading=self.grading)


@dataclass(frozen=True)
class RefinementResult:
    """Best level, its error estimates and the history of levels computed."""

    best: Level | None
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

    M grows in steps of 2 on the current mesh until its error estimate (levels M - 4,
    M - 2, M, :func:`tail_error`) is below ``tol * |eta| / 2``; then the mesh error
    (last doubling) is computed at that M, and the larger part is refined (M + 2 or twice
    the elements) until the sum is below ``tol * |eta|`` or a limit of ``plan`` is hit.

    The time budget is checked before each step against the elapsed time plus the
    predicted cost of the levels the step needs (:func:`_predicted_seconds`). A level that
    fails or gives unphysical moments (V2, Pin, v2, x2 <= 0) ends the refinement with
    ``converged=False``, the finest good level and the spread of the good levels as error
    (``best`` is None if no level worked); a failed lower degree that only feeds the tail
    estimate is dropped instead.
    """
    t0 = time.perf_counter()
    w = Whitening.of(h)
    base = plan.mesh(h, w)
    cache: dict[tuple[int, int], Level] = {}
    failed: dict[tuple[int, int], str] = {}

    def level(M: int, nh: int) -> Level:
        key = (M, nh)
        if key in failed:
            raise _LevelFailed(failed[key])
        if key not in cache:
            gb = level_gigabytes(M, nh, plan.order)
            if gb > plan.memory_limit:
                failed[key] = (f"level M = {M}, {2 * nh} elements would need about {gb:.3g} GB, "
                               f"more than max_gb = {plan.memory_limit:.3g} GB")
                raise _LevelFailed(failed[key])
            try:
                lv = solve_level(h, M, base.with_elements(nh), plan.order, w)
            except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
                failed[key] = f"level M = {M}, {2 * nh} elements failed ({exc})"
                raise _LevelFailed(failed[key]) from exc
            bad = _unphysical(lv)
            if bad:
                failed[key] = f"level M = {M}, {2 * nh} elements is unphysical ({bad})"
                raise _LevelFailed(failed[key])
            cache[key] = lv
            if progress is not None:
                progress(f"M={M} elements={2 * nh} dofs={lv.dofs} eta={lv.moments['eta']:.10g} "
                         f"({lv.seconds:.2f} s)")
        return cache[key]

    def usable(ms: Sequence[int], nh: int) -> list[Level]:
        # Lower degrees only feed the tail estimate: one that fails (a low-order Hermite
        # truncation can lose positivity) is dropped from the sequence, not fatal.
        out = []
        for m in ms:
            try:
                out.append(level(m, nh))
            except _LevelFailed:
                if m == ms[-1]:
                    raise
        return out

    def estimates(M: int, nh: int, fixed: bool = False, enough: float | None = None
                  ) -> tuple[dict[str, float], float, float]:
        # Mesh: Richardson from the meshes nh/4, nh/2, nh with the observed order capped at
        # p + 1 (:func:`mesh_error`); the last difference alone if the sequence is not
        # contracting. A coarsest mesh of one element per half is still used; below that the
        # next finer mesh serves as the comparison. With ``enough`` (an error on eta), the
        # coarsest mesh is solved only if the two-mesh estimate (never smaller than the
        # Richardson one) is above it: it can only sharpen the estimate.
        # Hermite: tail estimate from M - 4, M - 2, M; a fixed level M is instead compared
        # with M + 2, whose own tail is added (the error of f(M) is |f(M) - f(M+2)| + tail).
        meshes = [level(M, nh // 2) if nh >= 2 else level(M, 2 * nh)]
        if nh >= 4 and enough is not None:
            errs, eM, ex = combine(M, nh, fixed, meshes)
            if reported_eta_error(level(M, nh).moments, errs)[0] <= enough:
                return errs, eM, ex
        if nh >= 4:
            try:  # the coarsest mesh only sharpens the estimate; it may fail to solve
                meshes.insert(0, level(M, nh // 4))
            except _LevelFailed:
                pass
        return combine(M, nh, fixed, meshes)

    def combine(M: int, nh: int, fixed: bool, meshes: list[Level]) -> tuple[dict[str, float], float, float]:
        degs = [m for m in ((M - 2, M, M + 2) if fixed else (M - 4, M - 2, M)) if m >= 2]
        seq_M = usable(degs, nh)
        degs = [lv.M for lv in seq_M]
        errs: dict[str, float] = {}
        eM = ex = 0.0
        for name in OBSERVABLES:
            vals = [lv.moments[name] for lv in seq_M]
            em, _ = tail_error(vals, degs)
            if fixed:
                em += abs(vals[-1] - level(M, nh).moments[name])
            if meshes[-1].mesh.half_elements > nh:
                ey = abs(level(M, nh).moments[name] - meshes[-1].moments[name])
            else:
                seq = [lv.moments[name] for lv in meshes] + [level(M, nh).moments[name]]
                ey = mesh_error(seq, plan.order)
            errs[name] = em + ey
            if name == "eta":
                eM, ex = em, ey
        return errs, eM, ex

    try:
        if plan.fixed:
            M, nh = plan.M, plan.half_elements
            errs, eM, ex = estimates(M, nh, fixed=True)
            best = level(M, nh)
            rel = reported_eta_error(best.moments, errs)[0] / abs(best.moments["eta"])
            ok = rel <= tol
            reason = "" if ok else (f"fixed M = {M}, {2 * nh} elements: estimated relative error "
                                    f"{rel:.2g} > tol = {tol:.2g}")
            return RefinementResult(best, errs, eM, ex, ok, reason, _history(cache), time.perf_counter() - t0)

        M, nh = plan.M, plan.half_elements
        while True:
            best = level(M, nh)
            eta = abs(best.moments["eta"])
            # Refine M first on the current mesh (lower degrees are cheap and cached); the mesh
            # sequence at the current M is computed only once the Hermite part is small.
            seq_M = usable([m for m in (M - 4, M - 2, M) if m >= 2], nh)
            vals = [lv.moments["eta"] for lv in seq_M]
            eM, _ = tail_error(vals, [lv.M for lv in seq_M])
            # A Hermite sequence that stops contracting usually means the mesh no longer
            # resolves the higher modes (n = 8 at M >= 16 on 16 elements wanders by 1e-5
            # around a value 1e-5 off): then the mesh error is checked too, and the larger
            # part refined.
            if eM <= HERMITE_SHARE * tol * eta or _stalled(vals):
                errs, eM, ex = estimates(M, nh, enough=tol * eta)
                if reported_eta_error(best.moments, errs)[0] <= tol * eta:
                    return RefinementResult(best, errs, eM, ex, True, "", _history(cache),
                                            time.perf_counter() - t0)
                grow_M = eM >= ex
            else:
                grow_M = True
            nxt_M, nxt_nh = (M + 2, nh) if grow_M else (M, 2 * nh)
            dofs = 2 * nxt_nh * _block_size(nxt_M, plan.order)
            elapsed = time.perf_counter() - t0
            limit = None
            if nxt_M > plan.max_M:
                limit = f"Hermite degree M would exceed max_M = {plan.max_M}"
            elif nxt_nh > plan.max_half_elements:
                limit = f"elements would exceed {2 * plan.max_half_elements}"
            elif dofs > plan.max_dofs:
                limit = f"unknowns would exceed max_dofs = {plan.max_dofs}"
            elif (gb := level_gigabytes(nxt_M, nxt_nh, plan.order)) > plan.memory_limit:
                limit = (f"memory: the next level would need about {gb:.3g} GB, more than "
                         f"max_gb = {plan.memory_limit:.3g} GB")
            elif plan.max_seconds is not None:
                # The next step may also need the coarse-mesh level of its error estimate.
                need = [(m, k) for m, k in ((nxt_M - 4, nxt_nh), (nxt_M - 2, nxt_nh),
                                            (nxt_M, nxt_nh), (nxt_M, max(nxt_nh // 2, 1)),
                                            (nxt_M, max(nxt_nh // 4, 1)))
                        if m >= 2 and (m, k) not in cache]
                predicted = sum(_predicted_seconds(cache, m, k, plan.order) for m, k in need)
                if elapsed + predicted > plan.max_seconds:
                    limit = (f"time budget max_seconds = {plan.max_seconds:g} s: {elapsed:.3g} s used, "
                             f"the next level would need about {predicted:.3g} s more")
            if limit is not None:
                errs, eM, ex = estimates(M, nh)
                rel = reported_eta_error(best.moments, errs)[0] / eta
                reason = (f"tol = {tol:.2g} not reached: estimated relative error on eta {rel:.2g} "
                          f"(Hermite part {eM / eta:.2g}, mesh part {ex / eta:.2g}) at M = {M}, "
                          f"{2 * nh} elements; {limit}")
                return RefinementResult(best, errs, eM, ex, False, reason, _history(cache),
                                        time.perf_counter() - t0)
            M, nh = nxt_M, nxt_nh
    except _LevelFailed as exc:
        return _broken(str(exc), cache, tol, time.perf_counter() - t0)


def _stalled(values: Sequence[float]) -> bool:
    """True if the last step of a refinement sequence is not smaller than the one before,
    or at least half of it with the opposite sign (not a converging sequence)."""
    if len(values) < 3:
        return False
    e1, e2 = values[-2] - values[-3], values[-1] - values[-2]
    return abs(e2) >= abs(e1) or (e1 * e2 < 0.0 and abs(e2) >= 0.5 * abs(e1))


def _history(cache: dict[tuple[int, int], Level]) -> list[dict[str, Any]]:
    return [lv.summary() for _, lv in sorted(cache.items())]


class _LevelFailed(Exception):
    """A level could not be solved or gave unphysical moments (refinement breaks down)."""


def _unphysical(lv: Level) -> str:
    """Why the moments of ``lv`` cannot be a density's (empty if they can)."""
    mo = lv.moments
    for name in ("V2", "Pin", "v2", "x2", "eta"):
        if not math.isfinite(mo[name]) or mo[name] <= 0.0:
            return f"{name} = {mo[name]:.3g}"
    return ""


def level_gigabytes(M: int, half_elements: int, order: int) -> float:
    """Memory (GB) of one level's factorization: the dense LU of every element block of the
    half mesh (:math:`N_h n_b^2` doubles) plus half as much again for the coupling solves,
    the sparse operator and temporaries, plus 0.2 GB (measured peaks: 0.45 GB at M = 12 and
    1.58 GB at M = 16 with 8 elements per half, predicted 0.62 and 1.64)."""
    nb = _block_size(M, order)
    return 1.5 * half_elements * nb * nb * 8 / 1e9 + 0.2


def default_memory_gb() -> float:
    """Half the physical memory in GB (8 GB if the platform does not tell)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 8.0
    return max(0.5 * total / 1e9, 1.0)


def _block_size(M: int, order: int) -> int:
    """Unknowns per element, :math:`n_b = (p + 1)\\binom{M+3}{3}`."""
    return (order + 1) * math.comb(M + 3, 3)


def _cost_unit(M: int, order: int) -> float:
    # Dense LU per element: n_b^3.
    return float(_block_size(M, order)) ** 3


def _predicted_seconds(cache: dict[tuple[int, int], Level], M: int, nh: int, order: int) -> float:
    """Predicted wall time (s) of level (M, nh) from the costliest measured level.

    Cost = elements x :math:`n_b^q`, :math:`n_b = (p+1)\\binom{M+3}{3}`. The dense block LU
    gives q = 3 asymptotically; at moderate M assembly and O(n_b^2) work dominate, so q is
    measured from the two costliest levels on one mesh and clipped to [2, 3] (timings are
    noisy on a busy machine; 3 when only one level is known).
    """
    if not cache:
        return 0.0
    unit = lambda m: float(_block_size(m, order))  # noqa: E731  n_b
    ranked = sorted(cache.items(), key=lambda kv: kv[0][1] * unit(kv[0][0]) ** 3)
    (m0, k0), lv0 = ranked[-1]
    q = 3.0
    same = [(m, lv) for (m, k), lv in ranked[:-1] if k == k0 and m < m0]
    if same and lv0.seconds > 0.0:
        m1, lv1 = same[-1]
        if lv1.seconds > 0.0:
            q = min(max(math.log(lv0.seconds / lv1.seconds) / math.log(unit(m0) / unit(m1)), 2.0), 3.0)
    return lv0.seconds * (nh / k0) * (unit(M) / unit(m0)) ** q


def _broken(why: str, cache: dict[tuple[int, int], Level], tol: float, seconds: float
            ) -> RefinementResult:
    """NOT_CONVERGED result when a level fails: the finest good level, errors from the spread.

    With the refinement broken there is no asymptotic estimate: the error of each observable
    is the largest difference between the kept level and the other good levels (its own
    magnitude if there is only one). ``best`` is None when no level worked, or when the
    levels disagree in eta by more than ``BROKEN_SPREAD`` (a wild sequence, e.g. the kink
    with a = 2: 0.008, 0.020, 0.019, 0.076 at M = 2..8 while Monte Carlo gives 0.15, whose
    spread would be a false error bar).
    """
    advice = ("the Hermite expansion around the equivalent harmonic unit does not resolve this "
              "density (strongly non-Gaussian, e.g. a quasi-static drive or a kink force larger "
              "than the drive); use method='mc', or fix M and elements to inspect the levels")
    if not cache:
        return RefinementResult(None, {}, math.inf, math.inf, False, f"{why}; {advice}", [], seconds)
    key = max(cache, key=lambda k: (k[1] * _cost_unit(k[0], 3), k))
    best = cache[key]
    errs = {}
    for name in OBSERVABLES:
        others = [abs(lv.moments[name] - best.moments[name]) for k, lv in cache.items() if k != key]
        errs[name] = max(others) if others else abs(best.moments[name])
    spread = errs["eta"] / abs(best.moments["eta"])
    if spread > BROKEN_SPREAD:
        # Levels this far apart are not a converging sequence: their spread is no error bar.
        why = (f"{why}; " + (f"the good levels disagree by {spread:.0%} in eta (more than "
                             f"{BROKEN_SPREAD:.0%})" if len(cache) > 1 else "only one level worked")
               + ", so no estimate is given")
        return RefinementResult(None, {}, math.inf, math.inf, False, f"tol = {tol:.2g} not reached: "
                                f"refinement broke down, {why}; {advice}", _history(cache), seconds)
    reason = (f"tol = {tol:.2g} not reached: refinement broke down, {why}; kept M = {best.M}, "
              f"{best.mesh.elements} elements, error = spread over the good levels; {advice}")
    return RefinementResult(best, errs, errs["eta"], 0.0, False, reason, _history(cache), seconds)
