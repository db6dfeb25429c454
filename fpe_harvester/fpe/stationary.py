"""Stationary Fokker--Planck solution of a single nonlinear harvester.

:func:`stationary` refines the Hermite-DG discretization (see :mod:`.refine`) until the
requested relative error on :math:`\\eta` is met and returns an :class:`FPESolution`:
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

import numpy as np
from skfem import Basis

from ..errors import MethodNotAvailableError, NotConvergedError, ParameterError, check_int, check_real
from ..model import Harvester
from ..result import Stats, Status
from .adapt import AdaptiveHermiteDG
from .assemble import _element
from .discretize import HermiteDG, Level, Whitening
from .estimate import reported_eta_error
from .kink import KinkLevel
from .kinkdisc import KinkDG, KinkSettings
from .refine import Discretization, Plan, RefinementResult, refine

__all__ = ["FPESolution", "stationary", "default_plan", "resolve_scheme", "resolve_mesh", "SCHEMES", "MESHES"]


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
        if isinstance(self.level, KinkLevel):
            return self.level.fields(np.asarray(x, dtype=float))
        return _fields(self.level, np.asarray(x, dtype=float))


#: Unknowns allowed to a level of the kink scheme (GMRES in the mode basis holds about 200
#: vectors of the half plane's unknowns; the memory bound max_gb applies too).
KINK_MAX_DOFS = 6_000_000

#: The Fokker--Planck schemes (see :func:`stationary`).
SCHEMES = ("auto", "x", "xv")

#: The x meshes of scheme ``"x"`` for n < 2 (see :func:`default_plan`).
MESHES = ("auto", "algebraic", "geometric", "adaptive")

#: Geometric layers toward x = 0 of the ``"geometric"`` mesh and their ratio. Measured for
#: n = 1.5, a = 1 at M = 8 on 8 bulk elements per half: 2 layers are within 3e-8 (relative
#: eta) of 10 layers; 4 keep a margin for higher M.
GEOMETRIC_LAYERS = 4
GEOMETRIC_RATIO = 0.15


def resolve_mesh(h: Harvester, mesh: str) -> str:
    """The x mesh ``"algebraic"`` or ``"geometric"`` that ``mesh`` means for ``h``.

    ``"auto"`` is ``"algebraic"``: for 1 < n < 2 it measured at least as accurate per
    unknown as the geometric one (see :func:`default_plan`), and the element-wise
    refinement (``"adaptive"``, any n) did not measure faster overall (see
    :mod:`validation.bench.fpe`). For n >= 2 the mesh is graded toward the walls only and
    ``"algebraic"`` names that mesh; ``"geometric"`` is refused.
    """
    if mesh not in MESHES:
        raise ParameterError(f"mesh must be one of {', '.join(map(repr, MESHES))}, got {mesh!r} "
                             f"(type {type(mesh).__name__})")
    if mesh == "adaptive":
        return mesh
    if mesh == "geometric" and h.n >= 2.0:
        raise ParameterError(f"mesh='geometric' grades toward the non-smooth force at x = 0 of n < 2, "
                             f"got n = {h.n!r}; use mesh='auto'")
    return "algebraic" if mesh == "auto" else mesh


def resolve_scheme(h: Harvester, scheme: str, x_settings: bool = False) -> str:
    """The scheme ``"x"`` or ``"xv"`` that ``scheme`` means for ``h`` (ParameterError if invalid).

    ``"auto"`` is ``"xv"`` for 1 <= n < 2 and ``"x"`` otherwise; for 1 < n < 2 it is ``"x"``
    when the caller set something only scheme ``"x"`` has (``x_settings``: a mesh, a
    number of elements, a weight). Measured for 1 < n < 2 at tol = 1e-4 (one run,
    ``python -m validation.bench.fpe --schemes``, 45 s budget): ``"xv"`` converges in 7 of
    the 9 cases n in {1.25, 1.5, 1.75} x a in {0.5, 1, 2} (4.7-10.5 s), ``"x"`` in 4
    (1.1-12.7 s; n = 1.25 at every a and n = 1.5 at a = 1, 2 not in 25-30 s); where both
    converge ``"x"`` is faster at n = 1.75, a <= 1 (1.1 and 2.9 s against 4.7 and 5.7 s).
    The two agree within their error bars in all 9.
    """
    if scheme not in SCHEMES:
        raise ParameterError(f"scheme must be one of {', '.join(map(repr, SCHEMES))}, got {scheme!r} "
                             f"(type {type(scheme).__name__})")
    if scheme == "auto":
        return "xv" if h.n == 1.0 or (1.0 < h.n < 2.0 and not x_settings) else "x"
    if scheme == "xv" and not 1.0 <= h.n < 2.0:
        raise ParameterError(f"scheme='xv' (DG in x and v) is built for the kink n = 1 and for 1 < n < 2, "
                             f"got n = {h.n!r}; "
                             "use scheme='x' or 'auto'")
    return scheme


def default_plan(h: Harvester, M: int | None = None, half_elements: int | None = None,
                 order: int | None = None, theta: float = 30.0, scheme: str = "x", mesh: str = "auto"
                 ) -> Plan:
    """Discretization settings for ``h``: smooth potentials (n >= 2) on a mesh graded toward
    the walls, n < 2 (kink or non-smooth force at 0) graded toward 0; DG order P3; the
    refinement starts at M = 4 on 8 elements per half.

    P4 was measured as an alternative at tol = 1e-4 and is not a robust gain: n = 8 took
    21 s (16 P4 elements) against 37 s (32 P3) at a = 0.5 but 51 s against 16 s at a = 2;
    for n = 1.5, 3, 4 (a = 0.5) P4 is 30-50 % slower (timings of the earlier one-sweep
    block solver). P2 is no gain for the kink either: n = 1, a = 0.5, tol = 1e-3 took 50 s
    (M = 16, 32 elements) against 22 s with P3 (twisted solver).

    The kink scheme (``scheme="xv"``) starts at M = 4 on its base mesh (size 1), DG degree 3.

    ``mesh`` (n < 2 only, :func:`resolve_mesh`): ``"algebraic"`` grades the nodes like
    :math:`t^{2.5}` toward 0; ``"geometric"`` keeps the bulk uniform (:math:`\\beta = 1`)
    and splits the element at 0 into :data:`GEOMETRIC_LAYERS` layers of ratio
    :data:`GEOMETRIC_RATIO`, with Gauss--Jacobi quadrature of the force there. Measured for
    n = 1.5, a = 1 (relative eta change to a mesh twice as fine, fixed M): the algebraic
    mesh with 16 elements per half is within 3e-9 at M = 8 to 14; the geometric one with
    16 bulk elements and 4-8 layers 1.5e-6 (the uniform bulk dominates once 2 layers are
    there). The Hermite sequence in M is the same on both meshes: what limits 1 < n < 2 is
    the Hermite expansion in (v, V, xi), not the mesh.
    """
    if scheme == "xv":
        return Plan(M=4 if M is None else M, half_elements=1 if half_elements is None else half_elements,
                    order=3 if order is None else order, theta=theta, grading=1.0, wall=0.0,
                    fixed=M is not None, max_half_elements=8)
    kink = h.n < 2.0
    geometric = resolve_mesh(h, mesh) == "geometric"
    return Plan(
        M=4 if M is None else M,
        half_elements=8 if half_elements is None else half_elements,
        order=3 if order is None else order,
        theta=theta,
        grading=2.5 if kink and not geometric else 1.0,
        wall=0.1,
        fixed=M is not None and half_elements is not None,
        layers=GEOMETRIC_LAYERS if geometric else 0,
        ratio=GEOMETRIC_RATIO,
    )


def _fields(lv: Level, x: np.ndarray) -> dict[str, np.ndarray]:
    X = lv.xmat
    x = np.clip(x, -lv.mesh.L, lv.mesh.L)
    # A fresh element: ElementLinePp caches reference values by array shape only.
    basis = Basis(X.basis.mesh, _element(lv.order), intorder=2 * lv.order + 6)
    probe = basis.probes(np.atleast_2d(np.abs(x) if lv.half else x))
    u = np.zeros((basis.N, lv.coef.shape[1]))
    u[X.perm] = lv.coef
    vals = probe @ u
    if lv.half:
        # Mirror image on x < 0: c_alpha(-x) = (-1)^|alpha| c_alpha(x).
        vals = np.where((x < 0.0)[:, None], vals * lv.hermite.parity(), vals)
    w1 = lv.hermite.first_moment_weights(lv.whitening.chol)
    dens = vals[:, 0]
    num = vals @ w1.T
    mask = dens < 1e-9 * max(float(dens.max()), 1e-300)
    safe = np.where(mask, 1.0, dens)
    out = {"density": dens}
    w = lv.whitening
    centre = np.multiply.outer(np.asarray(x, dtype=float), w.shift) + np.multiply.outer(w.psi(x), w.curve)
    for i, name in enumerate(("v_mean", "V_mean", "xi_mean")):
        # <y|x> = <y'|x> + b x + c psi(x) (the weight's centre)
        mean = num[:, i] / safe + centre[:, i]
        out[name] = np.ma.masked_array(np.where(mask, 0.0, mean), mask=mask)
    return out


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
    half_elements: int | None = None,
    order: int | None = None,
    theta: float = 30.0,
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
        Hermite total degree to start from (>= 2); with ``half_elements`` too, the level
        is fixed and the error is estimated from one refinement step of each knob.
    half_elements : int, optional
        Elements per half-domain to start from (>= 1; default 8).
    order : int, optional
        DG polynomial order in 2..5 (default 3).
    theta : float
        Domain factor :math:`U(L)/T_{eff}` in [5, 200]. Default 30.
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
        ``"x"``: DG in x, Hermite functions of (v, V, xi) (:mod:`.discretize`); ``"xv"``:
        DG in (x, v), Hermite functions of (V, xi) (:mod:`.kink`, only n = 1; there
        ``order`` is the DG degree on its base mesh, ``half_elements`` the refinement's
        mesh knob, which raises the degree by log2 of it, default 1; a given ``M`` alone
        fixes the level); ``"auto"`` (default): ``"xv"`` for 1 <= n < 2 (for n > 1 the force
        :math:`a n |x|^{n-1}` in the v transport, one core element per axis instead of the
        kink's layers toward the trap; ``"x"`` when ``mesh``, ``half_elements`` or
        ``weight`` is given), else ``"x"`` (see :func:`resolve_scheme`).
    weight : Whitening, optional
        Gaussian weight of the Hermite expansion of scheme ``"x"`` (default
        :meth:`Whitening.of`, the equivalent harmonic unit's). Another weight changes how fast
        the expansion converges, not its limit: the validation uses a deliberately wrong one
        to test the error estimate where the default would be exact (n = 2).
    mesh : str
        x mesh of scheme ``"x"`` for n < 2: ``"algebraic"`` (nodes graded like
        :math:`t^{2.5}` toward 0), ``"geometric"`` (geometric layers toward 0, Gauss--Jacobi
        quadrature of the force on the element at 0), or ``"auto"`` (default, the
        algebraic one; see :func:`default_plan`). For n >= 2 ``"auto"`` and
        ``"algebraic"`` are the same wall-graded mesh. ``"adaptive"`` (any n) starts from
        the algebraic mesh and bisects at each mesh step only the elements that the error
        indicator of :mod:`.adapt` marks (the others bisect all of them).

    Returns
    -------
    FPESolution

    Examples
    --------
    >>> from fpe_harvester import Harvester
    >>> sol = stationary(Harvester.build(a=0.5, n=2), tol=1e-4, M=4, half_elements=8)
    >>> abs(sol.stats.eta - 20 / 39) < 1e-6
    True
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    if h.N != 1:
        raise MethodNotAvailableError(_ring_reason(h))
    tol = check_real("tol", tol, low=0.0, high=0.1, low_open=True)
    if M is not None:
        M = check_int("M", M, low=2, high=max_M)
    if half_elements is not None:
        half_elements = check_int("half_elements", half_elements, low=1, high=1024)
    if order is not None:
        order = check_int("order", order, low=2, high=5)
    theta = check_real("theta", theta, low=5.0, high=200.0)
    max_M = check_int("max_M", max_M, low=4, high=60)
    max_dofs = check_int("max_dofs", max_dofs, low=1000)
    if max_seconds is not None:
        max_seconds = check_real("max_seconds", max_seconds, low=0.0, low_open=True)
    if max_gb is not None:
        max_gb = check_real("max_gb", max_gb, low=0.0, low_open=True)
    grid = check_int("grid", grid, low=3)
    scheme = resolve_scheme(h, scheme, x_settings=mesh != "auto" or half_elements is not None or weight is not None)
    if weight is not None and scheme != "x":
        raise ParameterError(f"weight is the Gaussian weight of scheme 'x'; got scheme {scheme!r} (n = {h.n:g})")
    resolve_mesh(h, mesh)
    if mesh != "auto" and scheme != "x":
        raise ParameterError(f"mesh is the x mesh of scheme 'x'; got scheme {scheme!r} (n = {h.n:g})")
    plan = default_plan(h, M, half_elements, order, theta, scheme, mesh)
    plan = Plan(**{**plan.__dict__, "max_M": max_M, "max_seconds": max_seconds, "max_gb": max_gb,
                    "max_dofs": max_dofs if scheme == "x" else max(max_dofs, KINK_MAX_DOFS)})
    if scheme == "xv":
        t0 = time.perf_counter()
        deadline = None if max_seconds is None else t0 + max_seconds
        try:
            # 1 < n < 2 has no trap at the origin: one core element per axis (measured at
            # a = 1, tol 1e-4: n = 1.5 eta 0.3878655 in 22 s against 0.3878575 +- 1.4e-5 in
            # 47 s with the kink's four layers; n = 1.25 0.3919145 in 31 s against 0.3919087 in 90 s)
            settings = KinkSettings(order=plan.order, layers=1 if h.n > 1.0 else KinkSettings.layers)
            disc: Discretization = KinkDG.build(h, settings, tol, deadline)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError, NotConvergedError) as exc:
            ref = RefinementResult(None, False, f"the kink solver's pilot level failed ({exc}); use method='mc'",
                                   seconds=time.perf_counter() - t0)
        else:
            if max_seconds is not None:  # the pilot's time counts
                plan = dataclasses.replace(plan, max_seconds=max(max_seconds - disc.pilot_seconds, 1e-3))
            ref = refine(disc, tol, plan, progress)
            ref = dataclasses.replace(ref, seconds=ref.seconds + disc.pilot_seconds)
    else:
        if weight is not None and not isinstance(weight, Whitening):
            raise ParameterError(f"weight must be a Whitening or None, got {type(weight).__name__}")
        w = Whitening.of(h) if weight is None else weight
        xdisc = (AdaptiveHermiteDG(h, plan.mesh(h, w), plan.order, w) if resolve_mesh(h, mesh) == "adaptive"
                 else HermiteDG(h, plan.mesh(h, w), plan.order, w))
        ref = refine(xdisc, tol, plan, progress)
    stats = _stats(h, ref, tol)
    lv = None if ref.best is None else ref.best.level
    if lv is None:
        empty = np.ma.masked_array(np.zeros(0))
        return FPESolution(stats=stats, x=np.zeros(0), density=np.zeros(0), v_mean=empty,
                           V_mean=empty, xi_mean=empty, residuals={}, level=None)
    half_width = lv.mesh.Lx if isinstance(lv, KinkLevel) else lv.mesh.L
    x = np.linspace(-half_width, half_width, grid)
    f = lv.fields(x) if isinstance(lv, KinkLevel) else _fields(lv, x)
    return FPESolution(
        stats=stats, x=x, density=f["density"], v_mean=f["v_mean"], V_mean=f["V_mean"],
        xi_mean=f["xi_mean"], residuals={"V2": lv.moments["res_V2"], "power": lv.moments["res_power"]},
        level=lv,
    )


def _ring_reason(h: Harvester) -> str:
    hint = "method='exact'" if h.is_linear else "method='mc'"
    return (f"the Fokker-Planck solver handles a single oscillator (N = 1), got a ring of N = {h.N} "
            f"units: its state is {4 * h.N}-dimensional; use {hint}"
            + (" (harmonic rings are solved exactly for any N)" if h.is_linear else ""))

