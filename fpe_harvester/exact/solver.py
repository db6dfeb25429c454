"""The exact solver for harmonic harvesters (n = 2): Fourier modes + closed-form moments."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import MethodNotAvailableError, ParameterError, check_int
from ..model import Harvester, Params, mode_sin2
from ..result import Stats, Status
from .moments import ring_moments
from .stability import MARGINAL_RTOL, k_di, mode_growth_rate

__all__ = ["Exact", "exact_stats", "exact_sweep"]


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
        return exact_stats([h])[0]


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
        ``V2``, ``Vrms``, ``Pin``, ``eta``, ``v2``, ``vV``, ``x2`` and the round-off errors
        ``V2_err``, ``Pin_err``, ``eta_err``, ``v2_err``, ``vV_err``, ``x2_err``; points with no
        stationary state (``k < k_di``) are masked, never NaN, and so is ``x2`` at marginal
        points (``k = k_di``), where it diverges. Also plain arrays ``"stable"`` (bool,
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
    for key in ("V2", "Pin", "v2", "vV", "x2"):
        mask = ~stable | marginal if key == "x2" else ~stable
        out[key] = np.ma.masked_array(mom[key], mask=mask)
        out[key + "_err"] = np.ma.masked_array(err[key], mask=mask)
    out["eta"] = out["V2"] / (params.R * out["Pin"])
    out["eta_err"] = out["eta"] * np.ma.hypot(out["V2_err"] / out["V2"], out["Pin_err"] / out["Pin"])
    out["Vrms"] = np.ma.sqrt(out["V2"])
    out["kappa_min"] = kmin
    out["marginal"] = marginal
    out["stable"] = stable
    return out


def exact_stats(hs: Sequence[Harvester]) -> list[Stats]:
    """Exact results of harmonic harvesters, one :func:`exact_sweep` per ring size and parameters.

    The single path from the closed form to :class:`Stats`: :meth:`Exact.solve` calls it with one
    harvester, a scene with all its harmonic points. Marginal points (``k = k_di``) get their
    finite limits and ``x2 = None``; unstable ones no numbers, a message and the growth rate.

    Raises
    ------
    MethodNotAvailableError
        A harvester is not harmonic (n != 2).
    """
    groups: dict[tuple[int, Params], list[int]] = {}
    for i, h in enumerate(hs):
        reason = Exact().unsupported_reason(h)
        if reason:
            raise MethodNotAvailableError(reason + "; use method='fpe' (N = 1) or 'mc'")
        groups.setdefault((h.N, h.params), []).append(i)
    results: dict[int, Stats] = {}
    for (N, params), idx in groups.items():
        sweep = exact_sweep(np.array([hs[i].a for i in idx]), np.array([hs[i].k for i in idx]), N, params)
        for j, i in enumerate(idx):
            results[i] = _point_stats(hs[i], {key: val[j] for key, val in sweep.items()})
    return [results[i] for i in range(len(hs))]


def _point_stats(h: Harvester, point: dict[str, Any]) -> Stats:
    """:class:`Stats` of ``h`` from its entries of :func:`exact_sweep`."""
    kmin = float(point["kappa_min"])
    kd = k_di(h.N, h.a)
    rate = mode_growth_rate(kmin, h.params)
    info = {"N": h.N, "kappa_min": kmin, "k_di": kd}
    if not point["stable"]:
        q = int(np.argmin(h.mode_stiffness()))
        return Stats(
            status=Status.UNSTABLE,
            method=Exact.name,
            growth_rate=rate,
            info=info,
            message=(
                f"unstable: k = {h.k:g} is beyond k_di = {kd:.10g}; mode q = {q} has stiffness "
                f"{kmin:.4g} < 0 and grows like exp({rate:.4g} t). Choose k > k_di."
            ),
        )
    marginal = bool(point["marginal"])
    message = "stable"
    if marginal:
        message = (
            f"marginal: k = k_di = {kd:.10g}; the critical mode has zero stiffness, so its x "
            "diffuses (x2 is unbounded) while V2, Pin and eta are the finite limits"
        )
    return Stats.from_moments(
        V2=float(point["V2"]), V2_err=float(point["V2_err"]),
        Pin=float(point["Pin"]), Pin_err=float(point["Pin_err"]),
        R=h.params.R,
        v2=float(point["v2"]), v2_err=float(point["v2_err"]),
        vV=float(point["vV"]), vV_err=float(point["vV_err"]),
        x2=None if marginal else float(point["x2"]),
        x2_err=None if marginal else float(point["x2_err"]),
        status=Status.MARGINAL if marginal else Status.STABLE,
        message=message,
        method=Exact.name,
        growth_rate=rate,
        info=info,
    )
