"""Independent references for the exact solver, free of its closed form and of its round-off.

* :func:`mp_mode_moments`, :func:`mp_ring_moments`: a 40-digit Lyapunov solve (mpmath) of each
  mode, built from the exact binary values of the inputs;
* :func:`closed_form_mode`: the closed form of one mode, written once, in any arithmetic;
* :func:`rational_eta`: it in exact rational arithmetic (:class:`fractions.Fraction`) where
  the mode stiffnesses are rational;
* :func:`mp_closed_form`: it in mpmath (many digits, no exponent limit), the
  reference for the exact solver over the whole double range (the formula itself is checked
  against :func:`mp_mode_moments` at moderate parameters: an identity between rational
  functions that holds there holds everywhere).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import mpmath

from fpe_harvester.model import Harvester, Params

__all__ = ["closed_form_mode", "mp_closed_form", "mp_mode_moments", "mp_ring_moments", "rational_eta"]


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


def closed_form_mode(kap: Any, m: Any, g: Any, Kv: Any, Kc: Any, s: Any, tau: Any, D: Any, tp: Any) -> dict[str, Any]:
    """Stationary moments of one harmonic mode of stiffness ``kap`` from the closed form, in
    the arithmetic of its arguments (:class:`fractions.Fraction`, mpmath ``mpf``, float or
    numpy arrays: only +, -, *, / are used). ``x2`` is None at ``kap == 0`` (infinite).

    With :math:`d_1 = (\\tau + \\tau_p)(m + \\gamma m\\tau + \\kappa\\tau^2) + K_cK_v\\tau^2\\tau_p`
    and :math:`d_2 = (1 + \\gamma\\tau_p)(\\gamma m + K_cK_v\\tau_p) + \\gamma\\kappa\\tau_p^2`:
    :math:`P_{in} = D\\sigma^2(\\tau + \\tau_p)/d_1`, :math:`\\langle vV\\rangle = DK_c\\sigma^2
    \\tau_p(\\gamma\\tau\\tau_p + \\tau + \\tau_p)/(d_1d_2)`, :math:`V_2 = K_c\\tau_p\\langle vV\\rangle`.
    """
    KK = Kc * Kv
    d1 = (tau + tp) * (m + g * m * tau + kap * tau**2) + KK * tau**2 * tp
    d2 = (1 + g * tp) * (g * m + KK * tp) + g * kap * tp**2
    vV = D * Kc * s**2 * tp * (g * tau * tp + tau + tp) / (d1 * d2)
    x2_num = (KK * g * tau**2 * tp**2 + KK * tau**2 * tp + g**2 * m * tau**2 * tp + g**2 * m * tau * tp**2
              + g * m * (tau + tp) ** 2 + m * (tau + tp) + (g * tau + 1) * kap * tp**2 * (tau + tp))
    return {"vV": vV, "V2": Kc * tp * vV, "Pin": D * s**2 * (tau + tp) / d1,
            "v2": D * s**2 * (KK * tp**3 + m * (tau + tp) * (1 + g * tp) + kap * tp**2 * (tau + tp)) / (m * d1 * d2),
            "x2": D * s**2 * x2_num / (kap * d1 * d2) if not _is_zero(kap) else None}


def _is_zero(kap: Any) -> bool:
    try:
        return bool(kap == 0)
    except ValueError:                      # an array: no element may be zero for x2
        return bool((kap == 0).any())


def _physical(p: Params, convert: Any) -> tuple[Any, ...]:
    """``m, gamma, Kv, Kc, sigma, tau, D, tau_p`` converted (e.g. to Fraction or mpf)."""
    return tuple(convert(getattr(p, n)) for n in ("m", "gamma", "Kv", "Kc", "sigma", "tau", "D", "tau_p"))


def rational_eta(kappas: list[Fraction], p: Params | None = None) -> tuple[Fraction, Fraction]:
    """``(V2, eta)`` of a ring in exact rational arithmetic, from rational mode stiffnesses
    (:func:`closed_form_mode` with :class:`fractions.Fraction`: the default parameters are
    integers, so no rounding at all)."""
    p = p or Params()
    phys = _physical(p, Fraction)
    V2 = Pin = Fraction(0)
    for kap in kappas:
        mom = closed_form_mode(kap, *phys)
        V2 += mom["V2"]
        Pin += mom["Pin"]
    n = len(kappas)
    V2, Pin = V2 / n, Pin / n
    return V2, V2 / (Fraction(p.R) * Pin)


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
        phys = _physical(p, mpmath.mpf)
        a, k = mpmath.mpf(h.a), mpmath.mpf(h.k)
        s2 = [mpmath.sin(mpmath.pi * min(q, h.N - q) / h.N) ** 2 for q in range(h.N)]
        kappa = [2 * a + 4 * k * x for x in s2]
        scale = [2 * a + 4 * abs(k) * x for x in s2]
        acc = {key: mpmath.mpf(0) for key in ("V2", "Pin", "v2", "vV", "x2")}
        for kap, sc in zip(kappa, scale):
            if abs(kap) <= marginal * sc:
                kap = mpmath.mpf(0)
            mom = closed_form_mode(kap, *phys)
            for key in acc:
                acc[key] += mpmath.inf if mom[key] is None else mom[key]
        R = mpmath.mpf(p.R)
        out: dict[str, Any] = {key: val / h.N for key, val in acc.items()}
        out["eta"] = out["V2"] / (R * out["Pin"])
        out["kappa"], out["scale"] = kappa, scale
        return out
