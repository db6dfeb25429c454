"""The exact solver for harmonic harvesters (n = 2): Fourier modes + closed-form moments."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import MethodNotAvailableError, ParameterError, check_int
from ..model import Harvester, Params, mode_sin2
from ..result import Stats, Status
from .moments import ring_moments
from .stability import MARGINAL_RTOL, classify, growth_rate, k_di

__all__ = ["Exact", "exact_sweep"]


@dataclass(frozen=True)
class Exact:
    """Exact stationary moments of a harmonic ring (any N) from its Fourier modes.

    Cost is O(N) closed-form evaluations. The reported errors are floating-point round-off
    bounds (~1e-16 relative, larger only for ``x2`` next to the threshold, where it diverges).
    Handles only ``n = 2``.

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5, n=2), "exact")
    >>> round(r.eta * 39, 12)
    20.0
    """

    name: ClassVar[str] = "exact"

    def unsupported_reason(self, h: Harvester) -> str | None:
        """``None`` if this solver handles ``h``, else why not."""
        if not h.is_linear:
            return f"the exact solver needs a harmonic potential (n = 2), got n = {h.n:g}"
        return None

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics of ``h``; unstable rings come back with status and growth rate."""
        reason = self.unsupported_reason(h)
        if reason:
            raise MethodNotAvailableError(reason + "; use method='fpe' (N = 1) or 'mc'")
        kap = h.mode_stiffness()
        scale = 2.0 * h.a + 4.0 * abs(h.k)
        status, kmin = classify(h, kappa=kap)
        rate = growth_rate(h, kappa=kap)
        kd = k_di(h.N, h.a)
        info = {"N": h.N, "kappa_min": kmin, "k_di": kd}
        if status == "unstable":
            q = int(np.argmin(kap))
            return Stats(
                status=Status.UNSTABLE,
                method=self.name,
                growth_rate=rate,
                info=info,
                message=(
                    f"unstable: k = {h.k:g} is beyond k_di = {kd:.10g}; mode q = {q} has stiffness "
                    f"{kmin:.4g} < 0 and grows like exp({rate:.4g} t). Choose k > k_di."
                ),
            )
        message = "stable"
        if status == "marginal":
            kap = _clip_marginal(kap, scale)
            message = (
                f"marginal: k = k_di = {kd:.10g}; the critical mode has zero stiffness, so its x "
                "diffuses (x2 is unbounded) while V2, Pin and eta are the finite limits"
            )
        mom, err = _moments_with_roundoff(kap, scale, h.params)
        marginal = status == "marginal"
        return Stats.from_moments(
            V2=float(mom["V2"]), V2_err=float(err["V2"]),
            Pin=float(mom["Pin"]), Pin_err=float(err["Pin"]),
            R=h.params.R,
            v2=float(mom["v2"]), v2_err=float(err["v2"]),
            vV=float(mom["vV"]), vV_err=float(err["vV"]),
            x2=None if marginal else float(mom["x2"]),
            x2_err=None if marginal else float(err["x2"]),
            status=Status(status),
            message=message,
            method=self.name,
            growth_rate=rate,
            info=info,
        )


def _clip_marginal(kap: np.ndarray, scale: np.ndarray | float) -> np.ndarray:
    """Set stiffnesses within round-off of zero (``MARGINAL_RTOL * scale``) to exactly 0."""
    return np.where(np.abs(kap) <= MARGINAL_RTOL * np.asarray(scale)[..., None], 0.0, kap)


#: Round-off of a computed stiffness 2a + 4k sin^2(pi q/N), relative to 2a + 4|k|.
_KAPPA_ROUNDOFF = 4.0 * np.finfo(float).eps


def _moments_with_roundoff(
    kap: np.ndarray, scale: np.ndarray | float, params: Params
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Ring moments (means over the last axis) and their floating-point error.

    The error is the change of each moment when every stiffness moves by its own round-off
    :math:`\\delta = 4\\epsilon(2a + 4|k|)`, plus a few ulps of the result. It is ~1e-16
    relative for well-conditioned rings and grows like :math:`\\delta/\\kappa_{min}` for
    ``x2`` close to the threshold, where ``x2`` diverges.
    """
    mom = ring_moments(kap, params)
    shifted = ring_moments(kap + _KAPPA_ROUNDOFF * np.asarray(scale)[..., None], params)
    err = {key: np.abs(shifted[key] - mom[key]) + _KAPPA_ROUNDOFF * np.abs(mom[key]) for key in mom}
    return mom, err


def exact_sweep(
    a: np.ndarray | float,
    k: np.ndarray | float,
    N: int = 3,
    params: Params | None = None,
) -> dict[str, np.ma.MaskedArray]:
    """Vectorized exact statistics of harmonic rings over arrays of ``a`` and ``k``.

    Parameters
    ----------
    a, k : array_like
        Potential strengths (> 0) and couplings; broadcast against each other.
    N : int
        Ring size, >= 1 (for N = 1, ``k`` must be 0).
    params : Params, optional
        Physical parameters (paper's defaults).

    Returns
    -------
    dict of numpy.ma.MaskedArray
        ``V2``, ``Vrms``, ``Pin``, ``eta``, ``v2``, ``vV`` and the round-off errors
        ``V2_err``, ``Pin_err``, ``eta_err``, ``v2_err``, ``vV_err``; points with no stationary
        state (``k < k_di``) are masked, never NaN. Also plain arrays ``"stable"`` (bool,
        marginal included), ``"marginal"`` (bool) and ``"kappa_min"`` (smallest mode stiffness).

    Notes
    -----
    Cost: N closed-form evaluations per point; 10,000 points of an N = 3 ring take about a
    millisecond.
    """
    params = params or Params()
    N = check_int("N", N, low=1)
    a_arr, k_arr = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(k, dtype=float))
    if not (np.all(np.isfinite(a_arr)) and np.all(a_arr > 0)):
        raise ParameterError("a must be finite and > 0 everywhere in the sweep, valid range (0, inf)")
    if not np.all(np.isfinite(k_arr)):
        raise ParameterError("k must be finite everywhere in the sweep")
    if N == 1 and np.any(k_arr != 0):
        raise ParameterError("k must be 0 for a single unit (N = 1)")
    kap = 2.0 * a_arr[..., None] + 4.0 * k_arr[..., None] * mode_sin2(N)
    kmin = kap.min(axis=-1)
    scale = 2.0 * a_arr + 4.0 * np.abs(k_arr)
    marginal = np.abs(kmin) <= MARGINAL_RTOL * scale
    kap = _clip_marginal(kap, scale)
    stable = (kmin > 0) | marginal
    mom, err = _moments_with_roundoff(np.where(stable[..., None], kap, 1.0), scale, params)
    out: dict[str, np.ma.MaskedArray] = {}
    for key in ("V2", "Pin", "v2", "vV"):
        out[key] = np.ma.masked_array(mom[key], mask=~stable)
        out[key + "_err"] = np.ma.masked_array(err[key], mask=~stable)
    out["eta"] = out["V2"] / (params.R * out["Pin"])
    out["eta_err"] = out["eta"] * np.ma.hypot(out["V2_err"] / out["V2"], out["Pin_err"] / out["Pin"])
    out["Vrms"] = np.ma.sqrt(out["V2"])
    out["kappa_min"] = kmin
    out["marginal"] = marginal
    out["stable"] = stable
    return out
