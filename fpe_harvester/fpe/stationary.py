"""Stationary Fokker--Planck solution of a single nonlinear harvester.

:func:`stationary` refines the discretization of a scheme (see :mod:`.schemes`, :mod:`.refine`)
until the requested relative error on :math:`\\eta` is met and returns an :class:`FPESolution`:
the statistics (a :class:`~fpe_harvester.result.Stats`), the x-marginal density
:math:`p(x) = c_0(x)`, the conditional means

.. math::

    \\langle y_i | x\\rangle = \\frac{\\sum_\\alpha w_{i\\alpha}\\,c_\\alpha(x)}{c_0(x)},
    \\qquad y = (v, V, \\xi),

on a grid, and the residuals of the exact stationary identities (docs/model.md §2)

.. math::

    r_V = \\frac{\\langle V^2\\rangle - K_c\\tau_p\\langle vV\\rangle}{\\langle V^2\\rangle},\\qquad
    r_P = \\frac{\\sigma\\langle v\\xi\\rangle - m\\gamma\\langle v^2\\rangle - K_v\\langle vV\\rangle}
    {\\sigma\\langle v\\xi\\rangle}.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import MethodNotAvailableError, NotConvergedError, ParameterError, check_int
from ..model import Harvester
from ..result import Stats, Status
from .estimate import reported_eta_error
from .protocol import Level
from .refine import RefinementResult, refine
from .schemes import check_settings, resolve_scheme
from .settings import Settings

if TYPE_CHECKING:
    from .schemes.x.discretize import Whitening

__all__ = ["FPESolution", "stationary", "solve_settings", "ring_reason"]


@dataclass(frozen=True)
class FPESolution:
    """Stationary solution: statistics, fields on a grid, identity residuals.

    Attributes
    ----------
    stats : Stats
        Values, error estimates, status and solver details (``info``).
    x : ndarray
        Grid on :math:`[-L, L]` where the fields are evaluated.
    density : ndarray
        x-marginal density :math:`p(x)` (integrates to 1).
    v_mean, V_mean, xi_mean : numpy.ma.MaskedArray
        Conditional means :math:`\\langle v|x\\rangle`, :math:`\\langle V|x\\rangle`,
        :math:`\\langle\\xi|x\\rangle`; masked where :math:`p(x) < 10^{-9}\\max p`.
    residuals : dict
        ``V2`` and ``power``: the relative residuals :math:`r_V, r_P` of the exact identities.
    level : Level or None
        The discretization level the numbers come from; None (and empty fields) when no
        level could be solved (status NOT_CONVERGED, see the message).
    """

    stats: Stats
    x: np.ndarray
    density: np.ndarray
    v_mean: np.ma.MaskedArray
    V_mean: np.ma.MaskedArray
    xi_mean: np.ma.MaskedArray
    residuals: dict[str, float]
    level: Level | None = field(repr=False)

    def evaluate(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Density and conditional means at arbitrary points ``x`` (inside [-L, L])."""
        if self.level is None:
            raise NotConvergedError(f"no solved level to evaluate: {self.stats.message}")
        return self.level.fields(np.asarray(x, dtype=float))


def _stats(h: Harvester, ref: RefinementResult, tol: float) -> Stats:
    est = ref.best
    if est is None:
        return Stats(status=Status.NOT_CONVERGED, message=ref.reason, method="fpe",
                     info={"tol": tol, "seconds": ref.seconds, "history": ref.history})
    lv = est.level
    mo, er = est.moments, est.errors
    V2, Pin = mo["V2"], mo["Pin"]
    eta_err, cov = reported_eta_error(mo, er)
    status = Status.STABLE if ref.converged else Status.NOT_CONVERGED
    message = (f"converged: estimated relative error on eta {eta_err / abs(mo['eta']):.2g} <= tol = {tol:.2g}"
               if ref.converged else ref.reason + "; the numbers are the best estimate with its error")
    info = {
        **lv.info(),
        "tol": tol, "error_eta_hermite": est.error_M, "error_eta_mesh": est.error_x,
        "mesh_checked": est.mesh_checked,
        "residual_V2": lv.moments["res_V2"], "residual_power": lv.moments["res_power"],
        "seconds": ref.seconds, "history": ref.history,
    }
    # eta_err: eta's own refinement estimate, not the bound propagated from V2 and Pin.
    return Stats.from_moments(
        V2=V2, Pin=Pin, R=h.params.R, V2_err=er["V2"], Pin_err=er["Pin"], cov_V2_Pin=cov, eta_err=eta_err,
        v2=mo["v2"], v2_err=er["v2"], vV=mo["vV"], vV_err=er["vV"], x2=mo["x2"], x2_err=er["x2"],
        status=status, message=message, method="fpe", info=info,
    )


def stationary(
    h: Harvester,
    tol: float = 1e-4,
    *,
    M: int | None = None,
    elements: int | None = None,
    order: int | None = None,
    domain: float = 30.0,
    max_M: int = 24,
    max_dofs: int = 600_000,
    max_seconds: float | None = None,
    max_gb: float | None = None,
    grid: int = 401,
    progress: Callable[[str], None] | None = None,
    scheme: str = "auto",
    weight: Whitening | None = None,
    mesh: str = "auto",
) -> FPESolution:
    """Stationary density and statistics of a single unit with :math:`U = a|x|^n`.

    Parameters
    ----------
    h : Harvester
        A single oscillator (``N = 1``), any :math:`n \\ge 1`.
    tol : float
        Requested relative error on :math:`\\eta`, in (0, 0.1]. Default 1e-4.
    M : int, optional
        Hermite total degree to start from (in [2, 60]; ``max_M`` is raised to it if
        smaller); with ``elements`` too (scheme ``"x"``), or alone (scheme ``"xv"``), the
        level is fixed and the error is estimated from one refinement step of each knob.
    elements : int, optional
        Elements of the whole x mesh of scheme ``"x"`` to start from (even, in [2, 2048];
        default 16); scheme ``"xv"`` does not use it.
    order : int, optional
        DG polynomial order in 2..5 (default 3).
    domain : float
        Domain factor :math:`\\Theta = U(L)/T_{eff}` in [5, 200] (the potential at the edge
        of the x domain in effective temperatures). Default 30.
    max_M, max_dofs : int
        Refinement limits; beyond them the result is NOT_CONVERGED.
    max_seconds : float, optional
        Wall-time budget of the refinement.
    max_gb : float, optional
        Memory bound (GB) of one level's factorization; default half the physical memory.
    grid : int
        Points of the output grid (>= 3).
    progress : callable, optional
        Called with a one-line message after each level.
    scheme : str
        ``"x"``: DG in x, Hermite functions of (v, V, xi) (:mod:`.schemes.x`); ``"xv"``:
        DG in (x, v), Hermite functions of (V, xi) (:mod:`.schemes.xv`, 1 <= n < 2; there
        ``order`` is the DG degree on its base mesh, which the refinement raises; a given
        ``M`` alone fixes the level); ``"auto"`` (default): ``"xv"`` for 1 <= n < 2 (for
        n > 1 the force :math:`a n |x|^{n-1}` in the v transport, one core element per axis
        instead of the kink's layers toward the trap; ``"x"`` when ``mesh``, ``elements`` or
        ``weight`` is given), else ``"x"`` (see :func:`~.schemes.resolve_scheme`).
    weight : Whitening, optional
        Gaussian weight of the Hermite expansion of scheme ``"x"`` (default
        :meth:`Whitening.of`, the equivalent harmonic unit's). Another weight changes how fast
        the expansion converges, not its limit: the validation uses a deliberately wrong one
        to test the error estimate where the default would be exact (n = 2).
    mesh : str
        x mesh of scheme ``"x"`` for n < 2: ``"algebraic"`` (nodes graded like
        :math:`t^{2.5}` toward 0), ``"geometric"`` (geometric layers toward 0, Gauss--Jacobi
        quadrature of the force on the element at 0), or ``"auto"`` (default, the
        algebraic one; see :class:`~.schemes.x.XMeshRule`). For n >= 2 ``"auto"`` and
        ``"algebraic"`` are the same wall-graded mesh. ``"adaptive"`` (any n) starts from
        the algebraic mesh and bisects at each mesh step only the elements that the error
        indicator of :mod:`.schemes.x.adapt` marks (the others bisect all of them).

    Returns
    -------
    FPESolution

    Notes
    -----
    This is the researcher's entry: it attempts any single unit. The solver object
    :class:`~.solver.FokkerPlanck` (``method="fpe"``) first consults the measured domain
    (:mod:`~fpe_harvester.fpe.domain`) and declines outside it.

    Examples
    --------
    >>> from fpe_harvester import Harvester
    >>> sol = stationary(Harvester.build(a=0.5, n=2), tol=1e-4, M=4, elements=16)
    >>> abs(sol.stats.eta - 20 / 39) < 1e-6
    True
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    if h.N != 1:
        raise MethodNotAvailableError(ring_reason(h))
    settings = check_settings(Settings(tol=tol, M=M, elements=elements, order=order, domain=domain,
                                       max_M=max_M, max_dofs=max_dofs, max_seconds=max_seconds, max_gb=max_gb,
                                       scheme=scheme, mesh=mesh, weight=weight))
    return solve_settings(h, settings, check_int("grid", grid, low=3), progress)


def solve_settings(h: Harvester, settings: Settings, grid: int = 401,
                   progress: Callable[[str], None] | None = None) -> FPESolution:
    """:func:`stationary` of a single unit ``h`` with validated ``settings``: resolve the
    scheme, build its discretization, refine it, and read off the result on ``grid`` points."""
    scheme = resolve_scheme(h, settings)
    plan = scheme.plan(h, settings)
    t0 = time.perf_counter()
    deadline = None if plan.max_seconds is None else t0 + plan.max_seconds
    try:
        disc = scheme.build(h, settings, plan, settings.tol, deadline)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError, NotConvergedError) as exc:
        ref = RefinementResult(None, False, f"{scheme.setup_failure} ({exc}); use method='mc'",
                               seconds=time.perf_counter() - t0)
    else:
        setup = time.perf_counter() - t0
        if plan.max_seconds is not None:  # the setup's time counts
            plan = dataclasses.replace(plan, max_seconds=max(plan.max_seconds - setup, 1e-3))
        ref = refine(disc, settings.tol, plan, progress)
        ref = dataclasses.replace(ref, seconds=ref.seconds + setup)
    return _solution(_stats(h, ref, settings.tol), None if ref.best is None else ref.best.level, grid)


def _solution(stats: Stats, lv: Level | None, grid: int) -> FPESolution:
    if lv is None:
        empty = np.ma.masked_array(np.zeros(0))
        return FPESolution(stats=stats, x=np.zeros(0), density=np.zeros(0), v_mean=empty,
                           V_mean=empty, xi_mean=empty, residuals={}, level=None)
    x = np.linspace(-lv.half_width, lv.half_width, grid)
    f = lv.fields(x)
    return FPESolution(
        stats=stats, x=x, density=f["density"], v_mean=f["v_mean"], V_mean=f["V_mean"],
        xi_mean=f["xi_mean"], residuals={"V2": lv.moments["res_V2"], "power": lv.moments["res_power"]},
        level=lv,
    )


def ring_reason(h: Harvester) -> str:
    """Why a ring of N > 1 units is not for the Fokker-Planck solver, and what to use."""
    hint = "method='exact'" if h.is_linear else "method='mc'"
    return (f"the Fokker-Planck solver handles a single oscillator (N = 1), got a ring of N = {h.N} "
            f"units: its state is {4 * h.N}-dimensional; use {hint}"
            + (" (harmonic rings are solved exactly for any N)" if h.is_linear else ""))

