"""Independent references for the exact solver, free of its closed form and of its round-off.

* :func:`mp_mode_moments`, :func:`mp_ring_moments`: a 40-digit Lyapunov solve (mpmath) of each
  mode, built from the exact binary values of the inputs;
* :func:`rational_eta`: the closed form evaluated in exact rational arithmetic
  (:class:`fractions.Fraction`) where the mode stiffnesses are rational.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import mpmath

from fpe_harvester.model import Harvester, Params

__all__ = ["mp_mode_moments", "mp_ring_moments", "rational_eta"]


def mp_mode_moments(kappa: Any, p: Params, dps: int = 40) -> dict[str, Any]:
    """Stationary moments of one mode of stiffness ``kappa`` >= 0 by a high-precision Lyapunov solve.

    Solves :math:`(I\\otimes A + A\\otimes I)\\,\\mathrm{vec}\\,P = -\\mathrm{vec}\\,Q` with mpmath at ``dps``
    digits. For ``kappa == 0`` x decouples and the (v, V, xi) block is solved (x2 is infinite).
    """
    with mpmath.workdps(dps):
        m, g, Kv, Kc, s, tau, D, tp = (mpmath.mpf(getattr(p, n)) for n in
                                       ("m", "gamma", "Kv", "Kc", "sigma", "tau", "D", "tau_p"))
        kappa = mpmath.mpf(kappa)
        rows = [[-g, -Kv / m, s / m], [Kc, -1 / tp, 0], [0, 0, -1 / tau]]
        if kappa != 0:
            rows = [[0, 1, 0, 0]] + [[-kappa / m if i == 0 else 0] + r for i, r in enumerate(rows)]
        A = mpmath.matrix(rows)
        n = A.rows
        M = mpmath.zeros(n * n, n * n)
        for i in range(n):
            for j in range(n):
                for l in range(n):
                    M[i * n + j, l * n + j] += A[i, l]
                    M[i * n + j, i * n + l] += A[j, l]
        rhs = mpmath.zeros(n * n, 1)
        rhs[n * n - 1] = -2 * D / tau**2
        x = mpmath.lu_solve(M, rhs)
        o = n - 3
        P = lambda i, j: x[(o + i) * n + (o + j)]  # noqa: E731
        return {"v2": P(0, 0), "V2": P(1, 1), "vV": P(0, 1), "Pin": s * P(0, 2),
                "x2": x[0] if kappa != 0 else mpmath.inf}


def mp_ring_moments(h: Harvester, dps: int = 40, zero_below: float = 0.0) -> dict[str, Any]:
    """Ring averages over modes with :math:`\\kappa_q = 2a + 4k\\sin^2(\\pi q/N)` in high precision.

    Mode stiffnesses with :math:`|\\kappa_q| \\le` ``zero_below`` :math:`\\cdot 2a` are set to 0 (the
    marginal limit at k = k_di, whose float input is only within round-off of the threshold).
    """
    with mpmath.workdps(dps):
        a, k = mpmath.mpf(h.a), mpmath.mpf(h.k)
        cache: dict[int, dict[str, Any]] = {}
        acc = {key: mpmath.mpf(0) for key in ("v2", "V2", "vV", "Pin", "x2")}
        for q in range(h.N):
            qq = min(q, h.N - q)  # mirror modes are identical
            if qq not in cache:
                kap = 2 * a + 4 * k * mpmath.sin(mpmath.pi * qq / h.N) ** 2
                if abs(kap) <= zero_below * 2 * a:
                    kap = mpmath.mpf(0)
                cache[qq] = mp_mode_moments(kap, h.params, dps)
            for key in acc:
                acc[key] += cache[qq][key]
        out = {key: val / h.N for key, val in acc.items()}
        out["eta"] = out["V2"] / (h.params.R * out["Pin"])
        return out


def rational_eta(kappas: list[Fraction], p: Params | None = None) -> tuple[Fraction, Fraction]:
    """``(V2, eta)`` of a ring in exact rational arithmetic, from rational mode stiffnesses.

    Same closed form as :func:`fpe_harvester.exact.mode_moments`, evaluated with
    :class:`fractions.Fraction` (the default parameters are integers, so no rounding at all).
    """
    p = p or Params()
    m, g, Kv, Kc, s, tau, D, tp, R = (Fraction(x) for x in (p.m, p.gamma, p.Kv, p.Kc, p.sigma,
                                                               p.tau, p.D, p.tau_p, p.R))
    V2 = Pin = Fraction(0)
    for kap in kappas:
        d1 = m * tau + m * tp + g * m * tau**2 + g * m * tau * tp + Kc * Kv * tau**2 * tp
        d1 += kap * tau**2 * (tau + tp)
        d2 = g * m + g**2 * m * tp + Kc * Kv * tp + Kc * Kv * g * tp**2 + g * kap * tp**2
        c = g * tau * tp + tau + tp
        V2 += D * Kc**2 * s**2 * tp**2 * c / (d1 * d2)
        Pin += D * s**2 * (tau + tp) / d1
    n = len(kappas)
    V2, Pin = V2 / n, Pin / n
    return V2, V2 / (R * Pin)
