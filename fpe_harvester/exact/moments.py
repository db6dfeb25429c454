"""Exact stationary moments of harmonic harvesters (n = 2), single units and rings.

The state of one unit is :math:`z = (x, v, V, \\xi)` and its SDE is linear,
:math:`dz = A z\\,dt + b\\,dW`, with

.. math::

    A = \\begin{pmatrix} 0 & 1 & 0 & 0 \\\\ -\\kappa/m & -\\gamma & -K_v/m & \\sigma/m \\\\
        0 & K_c & -1/\\tau_p & 0 \\\\ 0 & 0 & 0 & -1/\\tau \\end{pmatrix},\\qquad
    b b^T = \\mathrm{diag}(0, 0, 0, 2D/\\tau^2).

The stationary covariance :math:`P` solves the Lyapunov equation
:math:`A P + P A^T + b b^T = 0`. Its solution is rational in the parameters
(derived once symbolically and checked against the numerical Lyapunov solve in the tests):

.. math::

    P_{in} = \\sigma\\langle v\\xi\\rangle = \\frac{D\\sigma^2(\\tau+\\tau_p)}{d_1},\\qquad
    \\langle V^2\\rangle = \\frac{D K_c^2\\sigma^2\\tau_p^2(\\gamma\\tau\\tau_p+\\tau+\\tau_p)}{d_1 d_2},

    d_1 = m\\tau + m\\tau_p + \\gamma m\\tau^2 + \\gamma m\\tau\\tau_p + K_cK_v\\tau^2\\tau_p
          + \\kappa\\tau^2(\\tau + \\tau_p),

    d_2 = \\gamma m + \\gamma^2 m\\tau_p + K_cK_v\\tau_p + K_cK_v\\gamma\\tau_p^2 + \\gamma\\kappa\\tau_p^2.

A ring's drift is circulant, so its Fourier modes decouple: mode ``q`` is a single unit
with stiffness :math:`\\kappa_q = 2a + k\\mu_q + k_4\\mu_q^2`, :math:`\\mu_q = 4\\sin^2(\\pi q/N)`
(the eigenvalues of minus the ring Laplacian), and its own independent noise,
and ring averages are the means over modes of the single-unit moments.
"""

from __future__ import annotations

import math

import numpy as np

from ..model import Harvester, Params
from ..wide import Float, Wide

__all__ = [
    "drift_matrix",
    "noise_matrix",
    "mode_moments",
    "wide_mode_moments",
    "lyapunov_covariance",
    "ring_drift_matrix",
    "dense_covariance",
    "ring_moments",
    "closure_mismatch",
]


def drift_matrix(kappa: float, params: Params) -> np.ndarray:
    """4x4 drift matrix :math:`A` of one unit (or one ring mode) of stiffness ``kappa``."""
    p = params
    return np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [-kappa / p.m, -p.gamma, -p.Kv / p.m, p.sigma / p.m],
            [0.0, p.Kc, -1.0 / p.tau_p, 0.0],
            [0.0, 0.0, 0.0, -1.0 / p.tau],
        ]
    )


def noise_matrix(params: Params) -> np.ndarray:
    """4x4 diffusion matrix :math:`b b^T = \\mathrm{diag}(0, 0, 0, 2D/\\tau^2)`."""
    Q = np.zeros((4, 4))
    Q[3, 3] = 2.0 * params.D / params.tau**2
    return Q


def wide_mode_moments(kappa: Wide | Float, params: Params) -> dict[str, Wide | Float]:
    """The closed form of :func:`mode_moments` in :class:`~fpe_harvester.wide.Wide` arithmetic
    (or, given a :class:`~fpe_harvester.wide.Float` ``kappa``, in plain floats, the fast path).

    Bit-for-bit the float result wherever that stays in the normal range, and the correctly
    scaled value where a float intermediate would overflow or underflow, so only the moments
    themselves decide whether they are representable. ``kappa`` must be >= 0; ``x2`` is
    returned as 0 where ``kappa == 0`` (it is infinite there: the caller masks it).
    """
    p = params
    num = type(kappa) if isinstance(kappa, (Wide, Float)) else Wide
    m, g, Kv, Kc, s, tau, D, tp = (num.of(x) for x in (p.m, p.gamma, p.Kv, p.Kc, p.sigma, p.tau, p.D, p.tau_p))
    kap = num.of(kappa)
    KK = Kc * Kv
    d1 = m * tau + m * tp + g * m * tau**2 + g * m * tau * tp + KK * tau**2 * tp
    d1 = d1 + kap * tau**2 * (tau + tp)
    d2 = g * m + g**2 * m * tp + KK * tp + KK * g * tp**2 + g * kap * tp**2
    c = g * tau * tp + tau + tp
    vxi = D * s * (tau + tp) / d1
    vV = D * Kc * s**2 * tp * c / (d1 * d2)
    V2 = Kc * tp * vV
    v2_num = KK * tp**3 + g * m * tau * tp + g * m * tp**2 + m * tau + m * tp + kap * tp**2 * (tau + tp)
    v2 = D * s**2 * v2_num / (m * d1 * d2)
    x2_num = (
        KK * g * tau**2 * tp**2 + KK * tau**2 * tp + g**2 * m * tau**2 * tp + g**2 * m * tau * tp**2
        + g * m * (tau + tp) ** 2 + m * (tau + tp) + (g * tau + 1.0) * kap * tp**2 * (tau + tp)
    )
    soft = kap.sign() == 0
    x2 = num.where(soft, 0.0, D * s**2 * x2_num / (num.where(soft, 1.0, kap) * d1 * d2))
    return {"V2": V2, "vV": vV, "v2": v2, "vxi": vxi, "x2": x2, "Pin": s * vxi}


def mode_moments(kappa: np.ndarray | float, params: Params) -> dict[str, np.ndarray]:
    """Closed-form stationary second moments of a unit with stiffness ``kappa``.

    Parameters
    ----------
    kappa : array_like
        Stiffness :math:`\\kappa \\ge 0` (``2a`` for a single unit, :math:`\\kappa_q` for a ring
        mode). Broadcasts. At ``kappa = 0`` every moment but ``x2`` has a finite limit and
        ``x2`` is ``inf``. Values < 0 have no stationary state: the caller must check.
    params : Params
        Physical parameters.

    Returns
    -------
    dict of ndarray
        ``V2``, ``vV``, ``v2``, ``vxi``, ``x2`` and ``Pin`` (:math:`=\\sigma\\langle v\\xi\\rangle`).
        Evaluated without intermediate overflow (:func:`wide_mode_moments`); a moment beyond the
        double range comes back as ``inf`` or below the smallest normal double (0 or subnormal).

    Examples
    --------
    >>> mom = mode_moments(1.0, Params())
    >>> round(float(mom["V2"]) * 143, 12), round(float(mom["Pin"]) * 11, 12)
    (20.0, 3.0)
    """
    kap = np.asarray(kappa, dtype=float)
    mom = {key: val.to_float() for key, val in wide_mode_moments(Wide.of(kap), params).items()}
    mom["x2"] = np.where(kap > 0, mom["x2"], np.inf)
    return mom


def balanced_lyapunov(A: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """X with :math:`A X + X A^T + Q = 0`, solved on the balanced :math:`T^{-1} A T` (T diagonal).

    Balancing keeps stiff units (a up to 1e12) well conditioned: unbalanced, scipy warns that
    an eigenvalue pair sums to nearly zero (relative to the norm of A), perturbs A, and for
    kappa = 1e-8 loses eight digits of x2 (balanced: the closed form to 1e-15).

    Raises
    ------
    numpy.linalg.LinAlgError
        Where even the balanced matrix has an eigenvalue pair summing to nearly zero (a unit
        whose stiffness is negligible against its damping: kappa = 2e-16 at the defaults), so
        that scipy would perturb it and return a covariance of unknown accuracy.
    """
    import warnings

    import scipy.linalg

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            # balancing itself fails on a stiffness near the smallest doubles (kappa = 1e-21)
            with np.errstate(all="raise"):
                B, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
            Xb = scipy.linalg.solve_continuous_lyapunov(B, -(Q / scale[:, None]) / scale[None, :])
        except (RuntimeWarning, FloatingPointError) as exc:
            raise np.linalg.LinAlgError(f"Lyapunov equation too ill-conditioned to solve: {exc}") from exc
    return Xb * scale[:, None] * scale[None, :]


def lyapunov_covariance(kappa: float, params: Params) -> np.ndarray:
    """Stationary covariance of one unit by a numerical Lyapunov solve (cross-check)."""
    return balanced_lyapunov(drift_matrix(kappa, params), noise_matrix(params))


def ring_drift_matrix(h: Harvester) -> np.ndarray:
    """Dense 4N x 4N drift matrix of the ring, state ordered unit by unit (x, v, V, xi).

    The coupling block is :math:`(kL - k_4L^2)/m`, L the ring Laplacian built entry by entry
    (independent of the Fourier modes it cross-checks).
    """
    p, N = h.params, h.N
    A = np.kron(np.eye(N), drift_matrix(2.0 * h.a, p))
    if N > 1:
        L = -2.0 * np.eye(N) + np.roll(np.eye(N), 1, axis=1) + np.roll(np.eye(N), -1, axis=1)
        A[1::4, 0::4] += (h.k * L - h.k4 * (L @ L)) / p.m
    return A


def dense_covariance(h: Harvester) -> np.ndarray:
    """Dense 4N x 4N stationary covariance (scipy Lyapunov solve); a cross-check for small N."""
    A = ring_drift_matrix(h)
    Q = np.kron(np.eye(h.N), noise_matrix(h.params))
    return balanced_lyapunov(A, Q)


def ring_moments(kappa: np.ndarray, params: Params) -> dict[str, np.ndarray]:
    """Ring averages from mode stiffnesses along the last axis (means over modes).

    ``x2`` is ``inf`` where some mode has zero stiffness; see :func:`mode_moments` for the range.
    """
    kap = np.asarray(kappa, dtype=float)
    mom = {key: val.mean(axis=-1).to_float() for key, val in wide_mode_moments(Wide.of(kap), params).items()}
    mom["x2"] = np.where(np.all(kap > 0, axis=-1), mom["x2"], np.inf)
    return mom


def closure_mismatch(h: Harvester, log_kappa: float) -> float:
    """Mismatch of the Gaussian closure (statistical linearization) at on-site stiffness
    :math:`\\kappa = e^{\\text{log\\_kappa}}`, for :math:`U = a|x|^n` and ``h``'s ring:

    .. math::

        \\mu(\\kappa) = \\ln\\frac{\\langle xU'(x)\\rangle}{\\kappa\\langle x^2\\rangle}
        = \\ln c_n + (\\tfrac n2 - 1)\\ln s^2(\\kappa) - \\ln\\kappa,\\qquad
        c_n = a n\\,2^{n/2}\\Gamma(\\tfrac{n+1}{2})/\\sqrt\\pi,

    with x Gaussian of the variance :math:`s^2` of the harmonic ring of on-site stiffness
    :math:`\\kappa` (mode stiffnesses :math:`\\kappa + k\\mu_q + k_4\\mu_q^2`, the mean over modes;
    one unit for N = 1), from the closed form (a numerical Lyapunov solve loses positivity at
    extreme :math:`\\kappa`). Its root is the equivalent stiffness; the Fokker--Planck frame
    (:func:`fpe_harvester.fpe.hermite.equivalent_harmonic`) and the Monte Carlo twin
    (:func:`montecarlo.harmonic.linearized_stiffness`) both solve it.
    """
    if log_kappa > 709.0:  # kappa beyond the largest double: x is at rest to double precision
        s2 = 0.0
    else:
        kappa = math.exp(log_kappa)
        kap = kappa + h.coupling_stiffness() if h.N > 1 else np.array([kappa])
        s2 = float(np.mean(mode_moments(kap, h.params)["x2"]))
    n, a = h.n, h.a
    c_n = a * n * 2.0 ** (n / 2) * math.gamma((n + 1) / 2) / math.sqrt(math.pi)
    e = 0.5 * n - 1.0
    if e != 0.0 and not 0.0 < s2 < math.inf:
        # s^2 under- or overflows at this kappa (a = 1e144): the mismatch's limit, by its sign
        return math.inf if (e < 0.0) == (s2 == 0.0) else -math.inf
    return math.log(c_n) + (e * math.log(s2) if e != 0.0 else 0.0) - log_kappa
