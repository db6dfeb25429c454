"""Independent references for the exact solver, free of its closed form and of its round-off.

* :func:`mp_mode_moments`, :func:`mp_ring_moments`: a 40-digit Lyapunov solve (mpmath) of each
  mode, built from the exact binary values of the inputs;
* :func:`rational_eta`: the closed form evaluated in exact rational arithmetic
  (:class:`fractions.Fraction`) where the mode stiffnesses are rational;
* :func:`mp_closed_form`: the closed form in mpmath (many digits, no exponent limit), the
  reference for the exact solver over the whole double range (the formula itself is checked
  against :func:`mp_mode_moments` at moderate parameters: an identity between rational
  functions that holds there holds everywhere).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import mpmath

from fpe_harvester.model import Harvester, Params

__all__ = ["mp_closed_form", "mp_mode_moments", "mp_ring_moments", "rational_eta"]


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


def mp_closed_form(h: Harvester, dps: int = 60, marginal: float = 0.0) -> dict[str, Any]:
    """Ring averages of a harmonic ring from the closed form in mpmath (``dps`` digits).

    Parameters
    ----------
    h : Harvester
        A harmonic ring; its float inputs are taken at their exact binary values.
    dps : int
        Decimal digits of the evaluation (mpmath exponents are unbounded, so nothing
        overflows: the values are the true ones, however far beyond double precision).
    marginal : float
        Mode stiffnesses with :math:`|\\kappa_q| \\le` ``marginal`` times
        :math:`2a + 4|k|\\sin^2(\\pi q/N)` are taken as 0 (the limit at ``k = k_di``).

    Returns
    -------
    dict
        ``V2``, ``Pin``, ``eta``, ``v2``, ``vV``, ``x2`` (``inf`` when a mode has zero
        stiffness) as mpf, ``kappa`` and ``scale``: the exact mode stiffnesses and
        :math:`2a + 4|k|\\sin^2(\\pi q/N)`, lists of mpf. Meaningful only when every
        ``kappa`` is >= 0.
    """
    p = h.params
    with mpmath.workdps(dps):
        m, g, Kv, Kc, s, tau, D, tp, R = (mpmath.mpf(x) for x in (p.m, p.gamma, p.Kv, p.Kc, p.sigma, p.tau,
                                                                    p.D, p.tau_p, p.R))
        a, k = mpmath.mpf(h.a), mpmath.mpf(h.k)
        s2 = [mpmath.sin(mpmath.pi * min(q, h.N - q) / h.N) ** 2 for q in range(h.N)]
        kappa = [2 * a + 4 * k * x for x in s2]
        scale = [2 * a + 4 * abs(k) * x for x in s2]
        KK = Kc * Kv
        acc = {key: mpmath.mpf(0) for key in ("V2", "Pin", "v2", "vV", "x2")}
        for kap, sc in zip(kappa, scale):
            if abs(kap) <= marginal * sc:
                kap = mpmath.mpf(0)
            d1 = (tau + tp) * (m + g * m * tau + kap * tau**2) + KK * tau**2 * tp
            d2 = (1 + g * tp) * (g * m + KK * tp) + g * kap * tp**2
            vV = D * Kc * s**2 * tp * (g * tau * tp + tau + tp) / (d1 * d2)
            acc["vV"] += vV
            acc["V2"] += Kc * tp * vV
            acc["Pin"] += D * s**2 * (tau + tp) / d1
            acc["v2"] += D * s**2 * (KK * tp**3 + m * (tau + tp) * (1 + g * tp) + kap * tp**2 * (tau + tp)) / (
                m * d1 * d2)
            x2_num = (KK * g * tau**2 * tp**2 + KK * tau**2 * tp + g**2 * m * tau**2 * tp + g**2 * m * tau * tp**2
                      + g * m * (tau + tp) ** 2 + m * (tau + tp) + (g * tau + 1) * kap * tp**2 * (tau + tp))
            acc["x2"] += D * s**2 * x2_num / (kap * d1 * d2) if kap != 0 else mpmath.inf
        out: dict[str, Any] = {key: val / h.N for key, val in acc.items()}
        out["eta"] = out["V2"] / (R * out["Pin"])
        out["kappa"], out["scale"] = kappa, scale
        return out
