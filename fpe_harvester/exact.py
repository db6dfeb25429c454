"""The exact solver for harmonic harvesters (n = 2): Fourier modes + closed-form moments."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .errors import MethodNotAvailableError, ParameterError, check_int
from .linear import mode_moments, ring_moments
from .model import Harvester, Params
from .result import Stats, Status
from .stability import MARGINAL_RTOL, classify, growth_rate, k_di

__all__ = ["Exact", "exact_sweep"]


@dataclass(frozen=True)
class Exact:
    """Exact stationary moments of a harmonic ring (any N) from its Fourier modes.

    Cost is O(N) closed-form evaluations; errors are reported as 0 (round-off, ~1e-15
    relative). Handles only ``n = 2``.

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
        status, kmin = classify(h)
        kap = h.mode_stiffness()
        kd = k_di(h.N, h.a)
        info = {"N": h.N, "kappa_min": kmin, "k_di": kd}
        if status == "unstable":
            rate = growth_rate(h)
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
            kap = np.where(np.abs(kap) <= MARGINAL_RTOL * (2 * h.a + 4 * abs(h.k)), 0.0, kap)
            message = (
                f"marginal: k = k_di = {kd:.10g}; the critical mode has zero stiffness, so its x "
                "diffuses (x2 is unbounded) while V2, Pin and eta are the finite limits"
            )
        mom = ring_moments(kap, h.params)
        zero = 0.0
        x2 = None if status == "marginal" else float(mom["x2"])
        return Stats.from_moments(
            V2=float(mom["V2"]),
            Pin=float(mom["Pin"]),
            R=h.params.R,
            v2=float(mom["v2"]), v2_err=zero,
            vV=float(mom["vV"]), vV_err=zero,
            x2=x2, x2_err=None if x2 is None else zero,
            status=Status(status),
            message=message,
            method=self.name,
            growth_rate=growth_rate(h),
            info=info,
        )


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
        ``V2``, ``Vrms``, ``Pin``, ``eta``, ``v2``, ``vV``; points with no stationary state
        (``k < k_di``) are masked, never NaN. Also ``"stable"`` (bool array, marginal included).

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
    s2 = np.sin(np.pi * np.arange(N) / N) ** 2
    kap = 2.0 * a_arr[..., None] + 4.0 * k_arr[..., None] * s2
    kmin = kap.min(axis=-1)
    scale = 2.0 * a_arr + 4.0 * np.abs(k_arr)
    marginal = np.abs(kmin) <= MARGINAL_RTOL * scale
    kap = np.where(marginal[..., None] & (kap == kmin[..., None]), 0.0, kap)
    stable = (kmin > 0) | marginal
    mom = ring_moments(np.where(stable[..., None], kap, 1.0), params)
    out: dict[str, np.ma.MaskedArray] = {}
    for key in ("V2", "Pin", "v2", "vV"):
        out[key] = np.ma.masked_array(mom[key], mask=~stable)
    out["eta"] = out["V2"] / (params.R * out["Pin"])
    out["Vrms"] = np.ma.sqrt(out["V2"])
    out["stable"] = stable
    return out
