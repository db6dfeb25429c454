"""Time-dependent Fokker--Planck runs of the Hermite-DG hierarchy, driven by py-pde.

The semi-discrete hierarchy (see :mod:`.assemble`) is the linear ODE system

.. math::

    (M_x \\otimes I)\\,\\dot c = -A c \\quad\\Longrightarrow\\quad \\dot c = G c,
    \\qquad G = -(M_x^{-1} \\otimes I) A,

with the block-diagonal DG mass matrix :math:`M_x` inverted element by element. It is
wrapped as a py-pde :class:`~pde.PDEBase` whose state is a :class:`~pde.ScalarField` on a
one-dimensional index grid holding the coefficient vector, so py-pde's solvers (``"scipy"``:
:func:`scipy.integrate.solve_ivp`, BDF with the sparse Jacobian G by default; ``"explicit"``,
``"implicit"``, ...) and trackers drive it. A :class:`~pde.CallbackTracker` records
:math:`\\langle V^2\\rangle(t)`, :math:`P_{in}(t)`, :math:`\\eta(t) = V^2(t)/(R P_{in}(t))`
and the x-marginal density at each interrupt.

The start is a Gaussian in (x, v, V, xi): by default the harvester near rest (x, v, V with
standard deviation ``rest_width`` times the equivalent harmonic :math:`\\sqrt{\\langle x^2\\rangle}`,
:math:`\\xi` in its stationary state :math:`N(0, D/\\tau)`), or any covariance ``P0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg.spsolve)

from ..errors import MethodNotAvailableError, NotConvergedError, ParameterError, check_int, check_real
from ..model import Harvester
from .hermite import HermiteBasis
from .schemes.x.discretize import Level, Whitening, assemble_level, level_moments
from .schemes.x.scheme import XMeshRule

__all__ = ["TransientSolution", "transient", "initial_coefficients", "lyapunov_transient"]


@dataclass(frozen=True)
class TransientSolution:
    """Observables of a time-dependent run at the tracker's interrupts.

    Attributes
    ----------
    t : ndarray
        Times (units of the model).
    V2, Pin, eta, v2, vV, x2 : ndarray
        Moments at each time of the density renormalized to the mass still in the domain
        (what leaves through :math:`\\pm L` is a truncation artefact; see ``mass``); ``eta``
        is the instantaneous ratio :math:`V^2/(R P_{in})`
        (undefined while :math:`P_{in} \\le 0`: masked there).
    mass : ndarray
        :math:`\\int p\\,dx` (1 up to the outflow at :math:`\\pm L`).
    x : ndarray
        Grid of the x-marginal snapshots.
    density : ndarray (len(t), len(x))
        x-marginal density at each time.
    info : dict
        M, elements, order, L, dofs, solver and py-pde's run information.
    """

    t: np.ndarray
    V2: np.ndarray
    Pin: np.ndarray
    eta: np.ma.MaskedArray
    v2: np.ndarray
    vV: np.ndarray
    x2: np.ndarray
    mass: np.ndarray
    x: np.ndarray
    density: np.ndarray
    info: dict[str, Any]


def _hermite_values(hb: HermiteBasis, z: np.ndarray) -> np.ndarray:
    """:math:`h_\\alpha(z)` for all alpha at points ``z`` of shape (3, npts) -> (n_alpha, npts)."""
    M = hb.M
    one = np.empty((3, M + 1, z.shape[1]))
    one[:, 0] = 1.0
    if M >= 1:
        one[:, 1] = z
    for k in range(1, M):
        one[:, k + 1] = (z * one[:, k] - math.sqrt(k) * one[:, k - 1]) / math.sqrt(k + 1)
    a = hb.alphas
    return one[0, a[:, 0]] * one[1, a[:, 1]] * one[2, a[:, 2]]


def initial_coefficients(lv_parts: tuple[Any, HermiteBasis, Whitening], P0: np.ndarray,
                         nodes: int = 6) -> np.ndarray:
    """DG projection of a centred Gaussian density :math:`N(0, P_0)` in (x, v, V, xi).

    :math:`c_\\alpha(x) = p_0(x)\\,E[h_\\alpha(z)\\,|\\,x]`, the conditional expectation by a
    tensor Gauss--Hermite rule (``nodes + M/2`` points per direction), then an element-wise
    L2 projection in x.
    """
    X, hb, w = lv_parts
    Li = np.linalg.inv(w.chol)
    sxx = P0[0, 0]
    gain = P0[1:, 0] / sxx
    cond = P0[1:, 1:] - np.outer(P0[1:, 0], P0[1:, 0]) / sxx
    # Conditional law of z = L^{-1} (y - b x) given x: mean Li (gain - b) x, covariance Li cond Li^T.
    Cz = Li @ cond @ Li.T
    Lz = np.linalg.cholesky(Cz + 1e-300 * np.eye(3)) if np.all(np.linalg.eigvalsh(Cz) > 0) else None
    if Lz is None:
        raise ParameterError("P0 must be a positive definite 4x4 covariance of (x, v, V, xi)")
    nq = nodes + hb.M // 2
    g, gw = np.polynomial.hermite_e.hermegauss(nq)
    gw = gw / math.sqrt(2.0 * math.pi)
    Z = np.stack(np.meshgrid(g, g, g, indexing="ij")).reshape(3, -1)
    W = np.einsum("i,j,k->ijk", gw, gw, gw).ravel()
    Hz0 = Lz @ Z  # fluctuation part, the same at every x
    basis = X.basis
    xq = np.asarray(basis.global_coordinates())[0]  # (nelems, nqp)
    dx = basis.dx
    mu = np.multiply.outer(xq, Li @ (gain - w.shift))  # (nelems, nqp, 3)
    px = np.exp(-(xq**2) / (2 * sxx)) / math.sqrt(2 * math.pi * sxx)
    b = np.zeros((basis.N, hb.size))
    phi = np.stack([np.asarray(basis.basis[i][0]) for i in range(basis.element_dofs.shape[0])])
    ne, nqp = xq.shape
    for e in range(ne):
        for q in range(nqp):
            f = px[e, q] * dx[e, q] * (_hermite_values(hb, Hz0 + mu[e, q][:, None]) @ W)
            b[basis.element_dofs[:, e]] += np.outer(phi[:, e, q], f)
    b = b[X.perm]
    return np.asarray(sp.linalg.spsolve(X.mass.tocsc(), b)).ravel()


def _mass_inverse(X: Any, block: int) -> sp.csr_matrix:
    Md = X.mass.toarray()
    inv = np.zeros_like(Md)
    for k in range(0, Md.shape[0], block):
        s = slice(k, k + block)
        inv[s, s] = np.linalg.inv(Md[s, s])
    return sp.csr_matrix(inv)


def lyapunov_transient(h: Harvester, P0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Exact covariance :math:`P(t)` of a harmonic unit: :math:`\\dot P = AP + PA^T + Q`, P(0) = P0.

    Integrated with :func:`scipy.integrate.solve_ivp` (the reference for n = 2).
    """
    from scipy.integrate import solve_ivp

    from ..exact import drift_matrix, noise_matrix

    if not h.is_linear:
        raise MethodNotAvailableError("the Lyapunov reference needs a harmonic potential (n = 2)")
    A = drift_matrix(2.0 * h.a, h.params)
    Q = noise_matrix(h.params)

    def rhs(_: float, p: np.ndarray) -> np.ndarray:
        P = p.reshape(4, 4)
        return (A @ P + P @ A.T + Q).ravel()

    sol = solve_ivp(rhs, (0.0, float(t[-1])), np.asarray(P0, float).ravel(), t_eval=t, rtol=1e-11, atol=1e-13)
    return sol.y.T.reshape(-1, 4, 4)


def transient(
    h: Harvester,
    t_end: float,
    *,
    M: int = 6,
    elements: int | None = None,
    order: int = 3,
    domain: float = 12.0,
    P0: np.ndarray | None = None,
    rest_width: float = 0.3,
    solver: str = "runge-kutta",
    interval: float | None = None,
    grid: int = 201,
    trackers: list[Any] | None = None,
    **solver_options: Any,
) -> TransientSolution:
    """Evolve the density from a Gaussian start with py-pde and record the observables.

    Parameters
    ----------
    h : Harvester
        A single oscillator (N = 1).
    t_end : float
        Final time, > 0.
    M, elements, order, domain : int, int, int, float
        Discretization, named as in :func:`~.stationary.stationary`: Hermite degree (in
        [2, 40]), elements of the whole x mesh (even, in [2, 2048]; default 16 for n <= 7,
        32 for steeper walls; see Notes), DG order (2..5), domain factor
        :math:`\\Theta = U(L)/T_{eff}` (in [5, 200]; default 12, see Notes).
    P0 : ndarray (4, 4), optional
        Initial covariance of (x, v, V, xi). Default: near rest (see ``rest_width``).
    rest_width : float
        Initial standard deviation of x, v and V in units of the equivalent harmonic
        :math:`\\sqrt{\\langle x^2\\rangle}`, in (0, 1]; the mesh must resolve it.
    solver : str
        A py-pde solver name: ``"runge-kutta"`` (default; adaptive, ``tolerance=1e-7``),
        ``"scipy"`` (:func:`scipy.integrate.solve_ivp`, BDF with the sparse Jacobian unless
        ``method=`` is given; robust for stiff fine meshes but slower here), ``"euler"``,
        ``"implicit"``, ``"crank-nicolson"``, ...
    interval : float, optional
        Time between recorded points (default ``t_end / 100``).
    grid : int
        Points of the x grid of the density snapshots (>= 3).
    trackers : list, optional
        Extra py-pde trackers.
    **solver_options
        Passed to py-pde's solver (e.g. ``dt=1e-3`` for explicit schemes, ``rtol=`` for scipy).

    Returns
    -------
    TransientSolution

    Raises
    ------
    NotConvergedError
        If the run blows up: far in the tails, where the force is large compared with the
        width of the Gaussian weight, the truncated hierarchy can have spurious growing
        modes (harmless for the stationary solve, fatal for time stepping). The run is
        watched (mass drift, negative V2) and stopped with advice instead of returning
        garbage.

    Notes
    -----
    The default domain (:math:`\\Theta = 12`, density :math:`\\sim e^{-12}` at the edge) is
    smaller than the stationary solver's because the spurious modes live at the edge, and
    steep walls (n > 7) get twice the elements because an under-resolved wall carries a
    growing mode; the spectra behind both choices are in the methods notes (docs/methods.md).

    The start is centred, so the density stays mirror-symmetric and is evolved on the half
    mesh :math:`[0, L]` with the mirror condition at 0 (the restriction of the whole-mesh
    system to its symmetric subspace: the same solution and a subset of its spectrum);
    ``dofs`` counts those unknowns.
    """
    import pde

    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    if h.N != 1:
        raise MethodNotAvailableError(f"transient runs handle a single oscillator (N = 1), got N = {h.N}")
    t_end = check_real("t_end", t_end, low=0.0, low_open=True)
    M = check_int("M", M, low=2, high=40)
    elements = check_int("elements", (16 if h.n <= 7.0 else 32) if elements is None else elements,
                         low=2, high=2048)
    if elements % 2:
        raise ParameterError(f"elements must be even (a node at x = 0), got {elements}")
    order = check_int("order", order, low=2, high=5)
    domain = check_real("domain (the domain factor)", domain, low=5.0, high=200.0)
    rest_width = check_real("rest_width", rest_width, low=0.0, high=1.0, low_open=True)
    grid = check_int("grid", grid, low=3)
    interval = t_end / 100 if interval is None else check_real("interval", interval, low=0.0, low_open=True)

    w = Whitening.of(h, curved=False)
    mesh = XMeshRule.of(h, domain=domain).build(h, w, elements // 2)
    # The start is a centred Gaussian and the dynamics are mirror-symmetric, so the density
    # stays symmetric: the half mesh [0, L] with the mirror condition at 0 (see
    # :mod:`.schemes.x.discretize`) evolves the same discrete density with half the unknowns.
    hb, F, X, A, _ = assemble_level(h, M, mesh, order, w, half=True)
    G = (-(sp.kron(_mass_inverse(X, order + 1), sp.identity(hb.size)) @ A)).tocsr()
    c0 = initial_coefficients((X, hb, w), _start_covariance(h, w, P0, rest_width))
    state = pde.ScalarField(pde.CartesianGrid([[0.0, float(c0.size)]], c0.size), c0)

    class _Hierarchy(pde.PDEBase):
        def evolution_rate(self, state: pde.ScalarField, t: float = 0.0) -> pde.ScalarField:
            rate = state.copy()
            rate.data[...] = G @ state.data
            return rate

    _solver_defaults(solver, solver_options, G)
    xs = np.linspace(-mesh.L, mesh.L, grid)
    records: list[tuple[float, dict[str, float], np.ndarray, float]] = []
    mass0 = X.copies * float(c0.reshape(-1, hb.size)[:, 0] @ X.integral)  # both halves

    def record(st: pde.ScalarField, t: float) -> None:
        C = st.data.reshape(-1, hb.size)
        mass = X.copies * float(C[:, 0] @ X.integral)
        # Moments of the density still in the domain (the outflow at +-L is a truncation
        # artefact, recorded in ``mass``).
        mo = level_moments(h, X, hb, C / mass if mass > 0 else C, w)
        if not (np.all(np.isfinite(C)) and abs(mass - mass0) < 1e-3 and mo["V2"] > 0 and mo["x2"] > 0):
            raise NotConvergedError(
                f"transient run unstable at t = {t:.4g} (mass {mass:.6g}, V2 {mo['V2']:.4g}): the "
                f"truncated hierarchy has a spurious growing mode at M = {M}, {mesh.elements} elements, "
                f"domain = {domain:g}; use more elements, a smaller domain or a smaller M")
        lv = Level(M, order, mesh, C, mo, c0.size, 0.0, X, hb, w)
        records.append((t, mo, lv.fields(xs)["density"], mass))

    tracker = [pde.CallbackTracker(record, interrupts=interval), *(trackers or [])]
    dt = solver_options.pop("dt", None)
    if dt is None:
        # CFL estimate: largest speed times (p + 1)^2 over the smallest element.
        speed = float(np.abs(np.linalg.eigvalsh(F)).max())
        dt = 0.5 * float(np.diff(mesh.nodes()).min()) / (speed * (order + 1) ** 2)
    _, info = _Hierarchy().solve(state, t_range=t_end, dt=dt, tracker=tracker, solver=solver, backend="numpy",
                                 ret_info=True, **solver_options)
    return _solution(h, records, xs, {"M": M, "elements": mesh.elements, "order": order, "L": mesh.L,
                                      "dofs": c0.size, "solver": solver, "pde": _plain(info)})


def _start_covariance(h: Harvester, w: Whitening, P0: np.ndarray | None, rest_width: float) -> np.ndarray:
    """The start's covariance of (x, v, V, xi): ``P0`` checked, or the unit near rest."""
    if P0 is None:
        s = rest_width * math.sqrt(w.x2)
        return np.diag([s**2, s**2, s**2, h.params.noise_variance])
    P0 = np.asarray(P0, dtype=float)
    if P0.shape != (4, 4) or not np.all(np.isfinite(P0)) or not np.allclose(P0, P0.T):
        raise ParameterError(f"P0 must be a finite symmetric 4x4 covariance, got shape {P0.shape}")
    return P0


def _solver_defaults(solver: str, options: dict[str, Any], G: sp.csr_matrix) -> None:
    """Fill in the defaults of py-pde's ``solver`` in ``options`` (an adaptive step for
    Runge--Kutta; BDF with the sparse Jacobian ``G`` and tight tolerances for scipy)."""
    if solver in ("runge-kutta", "rk", "rk45"):
        options.setdefault("adaptive", True)
        options.setdefault("tolerance", 1e-7)
    if solver == "scipy":
        options.setdefault("method", "BDF")
        if options["method"] in ("BDF", "Radau", "LSODA"):
            options.setdefault("jac", G)
        options.setdefault("rtol", 1e-8)
        options.setdefault("atol", 1e-12)


def _solution(h: Harvester, records: list[tuple[float, dict[str, float], np.ndarray, float]], xs: np.ndarray,
              info: dict[str, Any]) -> TransientSolution:
    """The recorded points as a :class:`TransientSolution`."""
    t = np.array([r[0] for r in records])
    mom = {k: np.array([r[1][k] for r in records]) for k in ("V2", "Pin", "v2", "vV", "x2")}
    pin = mom["Pin"]
    eta = np.ma.masked_array(np.where(pin > 0, mom["V2"] / (h.params.R * np.where(pin > 0, pin, 1.0)), 0.0),
                             mask=pin <= 0)
    return TransientSolution(
        t=t, V2=mom["V2"], Pin=pin, eta=eta, v2=mom["v2"], vV=mom["vV"], x2=mom["x2"],
        mass=np.array([r[3] for r in records]), x=xs, density=np.array([r[2] for r in records]), info=info,
    )


def _plain(info: Any) -> Any:
    if isinstance(info, dict):
        return {str(k): _plain(v) for k, v in info.items()}
    if isinstance(info, (int, float, str, bool)) or info is None:
        return info
    return repr(info)
