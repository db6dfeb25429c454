"""The harmonic twin: a linear ring on the same noise, whose averages are known exactly.

The twin of a harvester ring is the harmonic ring with the same parameters and coupling
``k`` and an on-site stiffness :math:`\\kappa` (potential :math:`\\kappa x^2/2`), driven by the
same noise paths :math:`\\xi_j(t)`. Its moments fluctuate with the system's, and their
expectations are known exactly, so they serve as control variates
(:mod:`montecarlo.controls.regression`). Exact here means: for the integrator itself at the step ``h``,
not only in the limit h -> 0, so that subtracting the twin's fluctuation adds no time-step
bias. Mode ``q`` of the twin (:math:`s_q = \\sin^2(\\pi q/N)`) advances, one step of the
kernel's splitting, as

.. math::

    y' = E y + g\\,\\big(\\sigma\\xi + k(2 - 4 s_q)(x + \\tfrac h2 v)\\big),\\qquad
    \\xi' = e^{-h/\\tau}\\xi + \\sqrt{(D/\\tau)(1 - e^{-2h/\\tau})}\\,Z,

with :math:`y = (x, v, V)`, :math:`(E, g)` the exact flow of the linear part with stiffness
:math:`\\kappa + 2k` (:func:`montecarlo.coefficients.step_coefficients`). The moments are measured
after the y update, with :math:`v\\xi` times :math:`e^{-h/2\\tau}`. The stationary covariance
of this recursion solves a discrete Lyapunov equation per mode, and ring averages are means
over modes (Parseval). The paths start from that stationary law (:func:`initial_cholesky`),
so the twin is stationary from the first step and its expected time averages over any
window are the stationary values.

The stiffness comes from the statistical linearization of the ring
(:func:`linearized_stiffness`): :math:`\\kappa = \\langle xU'(x)\\rangle / \\langle x^2\\rangle`,
with the averages taken either over a Gaussian x of the twin's own variance (closure) or
measured in a pilot run.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from fpe_harvester.errors import ParameterError, check_real
from fpe_harvester.exact.moments import closure_mismatch, mode_moments
from fpe_harvester.model import Harvester, mode_sin2

from ..layout import CF_PVX, CF_XI_HALF, M_TWIN
from ..steps import STEPPERS

__all__ = [
    "TWIN_MOMENTS",
    "natural_amplitude",
    "twin_harvester",
    "twin_is_stable",
    "scheme_matrices",
    "stationary_covariances",
    "twin_expectations",
    "initial_cholesky",
    "linearized_stiffness",
    "poisson_controls",
]

#: The twin's measured moments (the ``t_`` entries of :data:`montecarlo.layout.MOMENTS`):
#: second moments, then fourth moments and :math:`|x|^n` (n the system's exponent).
TWIN_MOMENTS = ("V2", "vV", "v2", "x2", "vxi", "x4", "x2V2", "x2v2", "absxn", "V2v2", "vxiV2")


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


def scheme_matrices(lin: Harvester, dt: float, step: str = "frozen"
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
        raise ParameterError(f"scheme_matrices needs a harmonic ring (n = 2), got n = {lin.n!r}")
    dt = check_real("dt", dt, low=0.0, low_open=True)
    stepper = STEPPERS.get(step)
    if stepper is None or not stepper.twin:
        raise ParameterError(f"step must be one of {tuple(k for k, s in STEPPERS.items() if s.twin)} (a step "
                             f"with a harmonic twin), got {step!r}")
    return stepper.twin_matrices(lin, dt)


def stationary_covariances(lin: Harvester, dt: float, step: str = "frozen") -> np.ndarray:
    """Stationary covariance (N, 4, 4) of each mode's state before a step (discrete Lyapunov).

    Raises :class:`ParameterError` when some mode of the discrete scheme is not stable
    (spectral radius >= 1).
    """
    import scipy.linalg

    M, _, Q, _ = scheme_matrices(lin, dt, step)
    out = np.empty_like(M)
    for q in range(lin.N):
        rho = float(np.max(np.abs(np.linalg.eigvals(M[q]))))
        if not rho < 1.0:
            raise ParameterError(
                f"the harmonic twin (stiffness {2 * lin.a:g}, k = {lin.k:g}) has no stationary "
                f"law at dt = {dt:g}: mode {q} has spectral radius {rho:.6g} >= 1")
        out[q] = scipy.linalg.solve_discrete_lyapunov(M[q], Q)
    return out


def twin_expectations(lin: Harvester, dt: float, n: float = 2.0, step: str = "frozen") -> dict[str, float]:
    """Exact expected values of the twin's measured moments (:data:`TWIN_MOMENTS`) at step dt.

    The second moments differ from the continuous-time values of
    :func:`fpe_harvester.exact.mode_moments` by the scheme's O(dt^2) bias, which is what the
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
        The stepper the twin runs (:func:`scheme_matrices`). The joint step's transition is exact
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
    _, T, _, half = scheme_matrices(lin, dt, step)
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
    """Lower Cholesky factor (4N x 4N) of the twin ring's stationary law before a step.

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
    return np.linalg.cholesky(C)


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


def poisson_controls(lin: Harvester, dt: float, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Weights over the martingale sums that make the Poisson-solution controls of V2 and Pin.

    For the harmonic ring ``lin`` at the frozen-xi step dt, the measured state
    :math:`Y_t` (x, v, V after the step's flow, xi before its update, unit by unit) is the linear
    chain :math:`Y_{t+1} = A Y_t + \\sum_j b_j Z_j` with :math:`A = T D_\\xi` (T of
    :func:`scheme_matrices` in unit space, :math:`D_\\xi` the xi decay :math:`e^{-h/\\tau}`) and
    :math:`b_j = s\\,T e_{\\xi_j}`. For a quadratic observable :math:`f = Y^TFY` (the ring mean of
    :math:`V^2`, or of :math:`\\sigma e^{-h/2\\tau} v\\xi`) the Poisson equation
    :math:`g - E[g(Y')|Y] = f - \\pi(f)` has the quadratic solution :math:`g = Y^TGY`,
    :math:`G - A^TGA = F` (one discrete Lyapunov solve), and its martingale increment is

    .. math::

        g(Y') - E[g(Y')|Y] = \\sum_j 2\\,e_{\\xi_j}^T T^T G A Y\\; sZ_j
        + s^2 \\sum_{j,l} (T^TGT)_{\\xi_j\\xi_l}(Z_jZ_l - \\delta_{jl}),

    linear in the state times the noise plus Hermite terms: a fixed combination of the ``lin`` and
    ``he`` sums of :mod:`montecarlo.controls.martingale` (the ring's symmetry makes the weights depend on
    the lag only; lags beyond :data:`montecarlo.controls.martingale.MG_DIST` are not in the basis, so the
    weights are exact for N <= 9). With a sample at every step the time average's fluctuation is
    this martingale up to the boundary term :math:`g(Y_{t_0}) - g(Y_{t_1})`.

    Parameters
    ----------
    lin : Harvester
        A stable harmonic ring (the system itself, or a nonlinear system's twin: the weights then
        define a control evaluated on the real state, still of mean 0).
    dt : float
        The fine step of the ensemble, > 0 (frozen-xi step).
    names : tuple of str
        :attr:`montecarlo.Ensemble.mart_names` of the ensemble.

    Returns
    -------
    dict
        ``{"V2": w, "Pin": w}``, weight vectors over ``names``.
    """
    import scipy.linalg

    M, T, _, _ = scheme_matrices(lin, dt)
    N = lin.N
    p = lin.params
    lag = np.arange(N)
    cosw = np.cos(2.0 * math.pi * np.outer(lag, np.arange(N)) / N) / N
    Tb = np.einsum("lq,qab->lab", cosw, T)
    Tu = np.zeros((4 * N, 4 * N))
    for j in range(N):
        for l in range(N):
            Tu[4 * j:4 * j + 4, 4 * l:4 * l + 4] = Tb[(j - l) % N]
    Dxi = np.eye(4 * N)
    Dxi[3::4, 3::4] *= math.exp(-dt / p.tau)
    A = Tu @ Dxi
    s = math.sqrt(p.noise_variance * -math.expm1(-2.0 * dt / p.tau))
    half = math.exp(-0.5 * dt / p.tau)
    out = {}
    for key in ("V2", "Pin"):
        F = np.zeros((4 * N, 4 * N))
        for j in range(N):
            if key == "V2":
                F[4 * j + 2, 4 * j + 2] = 1.0 / N
            else:
                F[4 * j + 1, 4 * j + 3] = F[4 * j + 3, 4 * j + 1] = 0.5 * p.sigma * half / N
        G = scipy.linalg.solve_discrete_lyapunov(A.T, F)
        lin_w = 2.0 * Tu[:, 3].T @ G @ A  # unit 0's phi = lin_w . Y
        K = s * s * Tu.T @ G @ Tu
        w = np.zeros(len(names))
        for i, name in enumerate(names):
            kind, *rest = name.split("_")
            if kind == "lin":
                var, d = "x v V xi".split().index(rest[0]), int(rest[1])
                if d == 0:
                    w[i] = lin_w[var]
                else:
                    # the basis holds y_{j-d} + y_{j+d}: equal weights on a reflection-symmetric ring
                    w[i] = lin_w[4 * d + var] if 2 * d != N else 0.5 * lin_w[4 * d + var]
            elif kind == "he":
                d = int(rest[0])
                w[i] = K[3, 3] if d == 0 else (K[3, 4 * d + 3] * (1.0 if 2 * d == N else 2.0))
        out[key] = w
    return out


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


@njit(cache=True, nogil=True)
def measure_twin(x, v, V, xi, w, cf, acc, nn, pvx) -> None:
    """Add the twin's moments (:data:`TWIN_MOMENTS`, ``nn`` the system's n) to their slots of
    ``acc`` (``t_*`` of :data:`montecarlo.layout.MOMENTS`).

    Second moments and a few fourth moments and :math:`|x|^n`: the twin is Gaussian, so
    each has an exactly known mean (:func:`montecarlo.controls.twin.twin_expectations`), and the
    higher ones follow the nonlinear system's amplitude-dependent response better.
    """
    N, P = x.shape
    half = cf[CF_XI_HALF]
    s = np.zeros(11)
    for j in range(N):
        for p in range(P):
            wp = w[p]
            xx, vv, VV = x[j, p] * x[j, p], v[j, p] * v[j, p], V[j, p] * V[j, p]
            vxi = v[j, p] * xi[j, p]
            ax = abs(x[j, p])
            s[0] += wp * VV
            s[1] += wp * v[j, p] * V[j, p]
            s[2] += wp * vv
            s[3] += wp * xx
            s[4] += wp * vxi
            s[5] += wp * xx * xx
            s[6] += wp * xx * VV
            s[7] += wp * xx * vv
            s[8] += wp * (ax if nn == 1.0 else ax**nn)
            s[9] += wp * VV * vv
            s[10] += wp * VV * vxi
    if cf[CF_PVX] == 1.0:
        s[4] = 0.0
        for j in range(N):
            for p in range(P):
                s[4] += w[p] * pvx[j, p]
    s[4] *= half
    s[10] *= half
    for i in range(11):
        acc[M_TWIN + i] += s[i]
