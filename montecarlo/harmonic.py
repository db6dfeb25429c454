"""The harmonic twin: a linear ring on the same noise as the system, whose law is known exactly.

The twin of a harvester ring is the harmonic ring with the same parameters and coupling ``k``
(and ``k4``) and an on-site stiffness :math:`\\kappa` (potential :math:`\\kappa x^2/2`), driven by
the same noise paths :math:`\\xi_j(t)`. Its moments fluctuate with the system's and their
expectations are known exactly, so they serve as control variates
(:mod:`montecarlo.controls.twin`). Exact here means: for the integrator itself at the step ``h``,
not only in the limit h -> 0, so that subtracting the twin's fluctuation adds no time-step bias.
Each stepper gives its one-step matrices per Fourier mode
(:meth:`~montecarlo.steps.base.Stepper.twin_matrices`); the stationary covariance of that
recursion solves a discrete Lyapunov equation per mode, and ring averages are means over modes
(Parseval). The paths start from that stationary law (:func:`initial_cholesky`), so the twin is
stationary from the first step and its expected time averages over any window are the
stationary values.

The stiffness comes from the statistical linearization of the ring
(:func:`linearized_stiffness`): :math:`\\kappa = \\langle xU'(x)\\rangle / \\langle x^2\\rangle`,
with the averages taken either over a Gaussian x of the twin's own variance (closure) or
measured in a pilot run; the same stiffness gives the relaxation time behind the burn-in
(:mod:`montecarlo.plan`) and the scale of the paths (:func:`natural_amplitude`).
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np

from fpe_harvester.errors import ParameterError, check_real
from fpe_harvester.exact.moments import closure_mismatch, mode_moments
from fpe_harvester.model import Harvester, mode_sin2

from .steps import STEPPERS

__all__ = [
    "twin_harvester",
    "twin_is_stable",
    "step_matrices",
    "stationary_covariances",
    "twin_expectations",
    "initial_cholesky",
    "linearized_stiffness",
    "natural_amplitude",
    "double_range_error",
]


def twin_harvester(h: Harvester, kappa: float) -> Harvester:
    """The harmonic ring with on-site stiffness ``kappa`` (``a = kappa/2``) and ``h``'s k, k4, N,
    params.

    The bi-Laplacian coupling ``k4`` is linear and enters exactly; the cubic bonds ``k3`` are
    dropped (``k3 = 0``): the twin must stay linear for its exact means, and a control variate
    adds no bias whatever its coupling, so only its correlation with the system is at stake
    (where dropping k3 leaves the twin unstable, the ring runs without it).

    Parameters
    ----------
    h : Harvester
        The system.
    kappa : float
        On-site stiffness of the twin, > 0 (its potential is :math:`\\kappa x^2/2`).
    """
    kappa = check_real("kappa", kappa, low=0.0, low_open=True)
    return h.replace(a=0.5 * kappa, n=2.0, k3=0.0)


def twin_is_stable(h: Harvester, kappa: float) -> bool:
    """Whether every mode stiffness :math:`\\kappa + 4k s_q` of the twin is positive."""
    return bool(np.all(twin_harvester(h, kappa).mode_stiffness() > 0.0)) if kappa > 0 else False


def step_matrices(lin: Harvester, dt: float, step: str = "frozen"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Per-mode one-step matrices of the stepper ``step`` on the harmonic ring ``lin``
    (:meth:`~montecarlo.steps.base.Stepper.twin_matrices`: M, T, Q and the factor on the measured
    v xi).

    Parameters
    ----------
    lin : Harvester
        A harmonic ring (n = 2).
    dt : float
        Time step, > 0.
    step : str
        A stepper that can run the twin (a name of :data:`montecarlo.steps.STEPPERS`).
    """
    if not lin.is_linear:
        raise ParameterError(f"step_matrices needs a harmonic ring (n = 2), got n = {lin.n!r}")
    dt = check_real("dt", dt, low=0.0, low_open=True)
    stepper = STEPPERS.get(step)
    if stepper is None or not stepper.twin:
        raise ParameterError(f"step must be one of {tuple(k for k, s in STEPPERS.items() if s.twin)} (a step "
                             f"with a harmonic twin), got {step!r}")
    return stepper.twin_matrices(lin, dt)


def double_range_error(h: Harvester, what: str) -> ParameterError:
    """The error for a system whose parameters' scales put ``what`` outside double precision
    (every parameter listed, so that the user sees which one to rescale)."""
    given = ", ".join(f"{k} = {v:g}" for k, v in h.params.to_dict().items())
    return ParameterError(f"{what}: the parameters' scales (a = {h.a:g}, {given}) put it outside double "
                          f"precision; rescale the problem (docs/model.md §5)")


def stationary_covariances(lin: Harvester, dt: float, step: str = "frozen") -> np.ndarray:
    """Stationary covariance (N, 4, 4) of each mode's state before a step (discrete Lyapunov).

    Raises :class:`ParameterError` when some mode of the discrete recursion is not stable
    (spectral radius >= 1), or when the covariance leaves the double range (sigma = 1e155 makes
    <v^2> ~ sigma^2 overflow).
    """
    M, _, Q, _ = step_matrices(lin, dt, step)
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(Q))):
        raise ParameterError(f"the harmonic twin (stiffness {2 * lin.a:g}, k = {lin.k:g}) has a step at dt = {dt:g} "
                             f"beyond double precision (its matrix exponential overflows): rescale the model so that "
                             f"a and |k| are of moderate size")
    out = np.empty_like(M)
    for q in range(lin.N):
        rho = float(np.max(np.abs(np.linalg.eigvals(M[q]))))
        if not rho < 1.0:
            raise ParameterError(
                f"the harmonic twin (stiffness {2 * lin.a:g}, k = {lin.k:g}) has no stationary "
                f"law at dt = {dt:g}: mode {q} has spectral radius {rho:.6g} >= 1")
        try:
            with np.errstate(over="raise", invalid="raise"):
                out[q] = _discrete_lyapunov(M[q], Q, q)
        except (FloatingPointError, ValueError) as exc:
            raise double_range_error(lin, f"the harmonic twin's stationary covariance (mode {q}) overflows "
                                          f"({exc})") from exc
    return out


def _discrete_lyapunov(M: np.ndarray, Q: np.ndarray, q: int) -> np.ndarray:
    """P = M P M^T + Q, checked by its residual in the scale of P's own diagonal.

    The state's variances span many decades for a stiff twin (a = 1e7: <x^2> ~ 5e-15 beside
    <xi^2> = 1), so LAPACK's condition estimate of the Kronecker system warns though the answer is
    accurate; the residual, scaled by sqrt(P_ii P_jj), says whether it is.
    """
    import scipy.linalg

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        P = scipy.linalg.solve_discrete_lyapunov(M, Q)
    if not np.all(np.isfinite(P)):
        raise FloatingPointError("the solution is not finite")
    d = np.sqrt(np.abs(np.diag(P)))
    scale = np.outer(d, d)
    resid = np.abs(M @ P @ M.T + Q - P)
    if not np.all(resid <= 1e-8 * scale + 1e-300):
        raise ParameterError(f"the harmonic twin's stationary covariance (mode {q}) could not be solved "
                             f"accurately (largest scaled residual {np.max(resid / (scale + 1e-300)):.3g})")
    return P


def twin_expectations(lin: Harvester, dt: float, n: float = 2.0, step: str = "frozen") -> dict[str, float]:
    """Exact expected values of the twin's measured moments (:data:`TWIN_MOMENTS`) at step dt.

    The second moments differ from the continuous-time values of
    :func:`fpe_harvester.exact.mode_moments` by the integrator's O(dt^2) bias, which is what the
    simulated twin carries. A unit's measured state (x, v, V, xi) is Gaussian with covariance
    S, the mean over modes of :math:`T P_q T^T`, so the higher moments follow from Isserlis'
    theorem, e.g. :math:`\\langle x^2V^2\\rangle = S_{xx}S_{VV} + 2S_{xV}^2`, and
    :math:`\\langle|x|^n\\rangle = S_{xx}^{n/2}\\,2^{n/2}\\Gamma(\\frac{n+1}2)/\\sqrt\\pi`.

    Parameters
    ----------
    lin : Harvester
        The twin (harmonic ring).
    dt : float
        Its time step, > 0.
    n : float
        Exponent of the ``absxn`` moment (the system's n), >= 1.
    step : str
        The stepper the twin runs (:func:`step_matrices`). The joint step's transition is exact
        for a single unit, so its second moments are the continuous-time ones; in a ring the
        neighbours' force at the predicted midpoint leaves an O(dt^2) bias.

    Examples
    --------
    >>> lin = Harvester.build(a=0.5)
    >>> e = twin_expectations(lin, 1e-3)
    >>> abs(e["V2"] * 143 / 20 - 1) < 1e-5
    True
    """
    P = stationary_covariances(lin, dt, step)
    _, T, _, half = step_matrices(lin, dt, step)
    S = np.einsum("qij,qjk,qlk->qil", T, P, T).mean(axis=0)
    n = check_real("n", n, low=1.0)
    absxn = S[0, 0] ** (0.5 * n) * 2.0 ** (0.5 * n) * math.gamma(0.5 * (n + 1)) / math.sqrt(math.pi)
    out = {
        "V2": S[2, 2], "vV": S[1, 2], "v2": S[1, 1], "x2": S[0, 0], "vxi": S[1, 3] * half,
        "x4": 3.0 * S[0, 0] ** 2,
        "x2V2": S[0, 0] * S[2, 2] + 2.0 * S[0, 2] ** 2,
        "x2v2": S[0, 0] * S[1, 1] + 2.0 * S[0, 1] ** 2,
        "absxn": absxn,
        "V2v2": S[2, 2] * S[1, 1] + 2.0 * S[1, 2] ** 2,
        "vxiV2": (S[1, 3] * S[2, 2] + 2.0 * S[1, 2] * S[2, 3]) * half,
    }
    return {key: float(val) for key, val in out.items()}


def initial_cholesky(lin: Harvester, dt: float, step: str = "frozen") -> np.ndarray:
    """A factor L (4N x 4N, L L^T = C) of the twin ring's stationary covariance C before a step.

    The lower Cholesky factor; where C is singular to round-off, the factor of its positive
    semi-definite part (same law).

    State ordered unit by unit, (x_j, v_j, V_j, xi_j). The unit-space covariance is the
    block-circulant :math:`C_{jl} = N^{-1}\\sum_q P_q \\cos(2\\pi q (j - l)/N)`.
    """
    P = stationary_covariances(lin, dt, step)
    N = lin.N
    q = np.arange(N)
    lag = np.arange(N)
    w = np.cos(2.0 * math.pi * np.outer(lag, q) / N) / N
    blocks = np.einsum("lq,qab->lab", w, P)
    C = np.empty((4 * N, 4 * N))
    for j in range(N):
        for l in range(N):
            C[4 * j:4 * j + 4, 4 * l:4 * l + 4] = blocks[(j - l) % N]
    C = 0.5 * (C + C.T)
    try:
        return np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        # Singular to round-off (a subnormal K_c leaves <V^2> = 0): any L with L L^T = C samples
        # the same law, so take the factor of C's positive semi-definite part.
        w, U = np.linalg.eigh(C)
        return U * np.sqrt(np.clip(w, 0.0, None))


def linearized_stiffness(h: Harvester, xdU: float | None = None, x2: float | None = None) -> float | None:
    """Equivalent on-site stiffness :math:`\\kappa = \\langle xU'(x)\\rangle / \\langle x^2\\rangle`.

    Parameters
    ----------
    h : Harvester
        The system, any n >= 1 and ring.
    xdU, x2 : float, optional
        Measured :math:`\\langle xU'(x)\\rangle` and :math:`\\langle x^2\\rangle` (a pilot
        run). Without them, x is taken Gaussian with the twin's own stationary variance,
        :math:`\\langle xU'\\rangle = c_n s^n`,
        :math:`c_n = a n 2^{n/2}\\Gamma(\\frac{n+1}2)/\\sqrt\\pi`, and :math:`\\kappa` solves
        :math:`\\kappa = c_n s(\\kappa)^{n-2}` on the twin's stable range.

    Returns
    -------
    float or None
        The stiffness, or None when the twin with it would have no stationary state (some
        :math:`\\kappa + 4ks_q \\le 0`) or the closure has no root (n < 2 with k < 0, or the
        kink with a strong constant force).

    Examples
    --------
    >>> round(linearized_stiffness(Harvester.build(a=0.5, n=2, N=3, k=-0.2)), 12)
    1.0
    """
    if xdU is not None or x2 is not None:
        if xdU is None or x2 is None:
            raise ParameterError("linearized_stiffness needs both xdU and x2, or neither")
        xdU = check_real("xdU", xdU, low=0.0, low_open=True)
        x2 = check_real("x2", x2, low=0.0, low_open=True)
        kappa = xdU / x2
        return kappa if twin_is_stable(h, kappa) else None
    return _closure_stiffness(h)


@functools.lru_cache(maxsize=256)
def _closure_stiffness(h: Harvester) -> float | None:
    """The Gaussian-closure root of :func:`linearized_stiffness` (no pilot data), once per
    system: a grid of 321 closure evaluations (~0.5 s) that the plan, the escape threshold
    (:func:`natural_amplitude`) and every batch's threshold would otherwise repeat."""
    if h.is_linear:
        return 2.0 * h.a
    from scipy.optimize import brentq

    low = max(0.0, -4.0 * h.k * float(mode_sin2(h.N).max()))
    lo = math.log(low) + 1e-9 if low > 0 else math.log(2.0 * h.a) - 40.0
    hi = math.log(max(2.0 * h.a, low)) + 40.0
    grid = np.linspace(lo, hi, 321)
    vals = np.array([closure_mismatch(h, t) for t in grid])
    sign = np.nonzero(np.diff(np.sign(vals)) != 0)[0]
    if sign.size != 1:
        return None
    i = int(sign[0])
    kappa = math.exp(brentq(lambda t: closure_mismatch(h, t), grid[i], grid[i + 1], xtol=1e-13))
    return kappa if twin_is_stable(h, kappa) else None


def natural_amplitude(h: Harvester) -> float | None:
    """Root-mean-square displacement :math:`\\sqrt{\\langle x^2\\rangle}` of the equivalent
    harmonic ring (stiffness :func:`linearized_stiffness`, closed-form moments): the scale of the
    paths of a confined system, in units of x. None when the closure has no stable root.

    >>> round(natural_amplitude(Harvester.build(a=0.5, n=2)), 6) == round(
    ...     math.sqrt(mode_moments(np.array([1.0]), Harvester.build(a=0.5).params)["x2"][0]), 6)
    True
    """
    kappa = linearized_stiffness(h)
    if kappa is None:
        return None
    kap = kappa + 4.0 * h.k * mode_sin2(h.N) if h.N > 1 else np.array([kappa])
    x2 = float(np.mean(mode_moments(kap, h.params)["x2"]))
    return math.sqrt(x2) if math.isfinite(x2) and x2 > 0 else None
