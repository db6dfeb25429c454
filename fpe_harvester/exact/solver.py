"""The exact solver for harmonic harvesters (n = 2): Fourier modes + closed-form moments."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import MethodNotAvailableError, ParameterError, check_int, check_real
from ..model import Harvester, Params
from ..result import Stats, Status
from ..solvers import Capabilities
from ..wide import LARGEST, SMALLEST_NORMAL, Float, Wide
from .moments import wide_mode_moments
from .stability import classify_modes, k_di, kappa_min, softest_mode, wide_growth_rate, wide_mode_stiffness

__all__ = ["Exact", "MAX_N", "exact_stats", "exact_sweep", "out_of_range_message"]


@dataclass(frozen=True)
class Exact:
    """Exact stationary moments of a harmonic ring (any N) from its Fourier modes.

    Cost is O(N) closed-form evaluations. The reported errors are floating-point round-off
    bounds (~1e-16 relative, larger only for ``x2`` next to the threshold, where it diverges).
    Handles only linear rings: ``n = 2``, any ``k`` and ``k4``, no cubic coupling (``k3 = 0``).

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5, n=2), "exact")
    >>> round(r.eta * 39, 12)
    20.0
    """

    name: ClassVar[str] = "exact"
    #: No tolerance (exact to round-off), deterministic, no budget or progress to report; a
    #: sweep's points are evaluated together (:meth:`solve_many`).
    capabilities: ClassVar[Capabilities] = Capabilities(title="exact", solve_many=True)

    def unsupported_reason(self, h: Harvester) -> str | None:
        """``None`` if this solver handles ``h``, else why not."""
        if not h.potential.is_harmonic:
            return (f"the exact solver needs a harmonic potential (n = 2), got n = {h.n:g}; "
                    "use method='fpe' (N = 1) or 'mc'")
        if h.k3 != 0.0:
            return (f"the exact solver needs linear forces, but k3 = {h.k3:g} (cubic coupling) is nonlinear; "
                    "use method='mc' (or 'auto'), or k3 = 0")
        if h.N > MAX_N:
            return (f"the exact solver evaluates every mode of the ring: N must be in [1, {MAX_N}], "
                    f"got N = {h.N}")
        return None

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics of ``h``; unstable rings come back with status and growth rate."""
        return exact_stats([h])[0]

    def solve_many(self, hs: Sequence[Harvester]) -> list[Stats]:
        """:meth:`solve` for each of ``hs``, in one vectorized evaluation per ring size and
        parameter set (:func:`exact_stats`)."""
        return exact_stats(hs)


#: Round-off of a computed stiffness 2a + 4k sin^2(pi q/N), relative to 2a + 4|k| sin^2(pi q/N).
_KAPPA_ROUNDOFF = 4.0 * np.finfo(float).eps

#: Largest ring the exact solver evaluates (time and memory are linear in N: ~0.5 s per 10^6 modes).
MAX_N = 2**22

#: Modes evaluated together (a sweep is cut into blocks of whole points of at most this many modes).
_BLOCK = 2**20

#: Observables that must be representable for a result to exist; the others become None.
_REQUIRED = ("V2", "Pin", "eta")


def _wide_ring(kappa: Wide | Float, scale: Wide | Float, marginal: np.ndarray,
               params: Params, N: int) -> tuple[dict[str, Wide | Float], dict[str, Wide | Float]]:
    """Ring moments (means over the last axis) and their floating-point error, as :class:`Wide`.

    The error is the change of each moment when every stiffness moves by its own round-off
    :math:`\\delta_q = 4\\epsilon(2a + 4|k|\\sin^2(\\pi q/N))`, plus a few ulps of the result. It is
    ~1e-16 relative for well-conditioned rings and grows like :math:`\\delta/\\kappa_{min}` for
    ``x2`` close to the threshold, where ``x2`` diverges. Modes set to zero stiffness
    (``marginal``) are not moved: the result there is by definition the limit at zero stiffness.
    """
    num = type(kappa)
    mom = {key: val.mean() for key, val in _with_bonds(wide_mode_moments(kappa, params), N).items()}
    moved = _with_bonds(wide_mode_moments(kappa + num.where(marginal, 0.0, _KAPPA_ROUNDOFF * scale), params), N)
    err = {key: abs(moved[key].mean() - mom[key]) + _KAPPA_ROUNDOFF * abs(mom[key]) for key in mom}
    return mom, err


def _with_bonds(modes: dict[str, Wide | Float], N: int) -> dict[str, Wide | Float]:
    """Add the per-mode bond moment ``d2``: mode q of a ring of N (last axis) contributes
    :math:`\\mu_q\\langle|x_q|^2\\rangle`, :math:`\\mu_q = 4\\sin^2(\\pi q/N)`, to
    :math:`\\langle(x_{j+1} - x_j)^2\\rangle` (0 for a single unit)."""
    mu = 4.0 * np.sin(np.pi * np.arange(N) / N) ** 2
    return {**modes, "d2": modes["x2"] * mu}


def _sweep_block(a: np.ndarray, k: np.ndarray, N: int, params: Params, k4: float) -> dict[str, np.ndarray]:
    """:func:`exact_sweep` on 1-D arrays of points; plain arrays, NaN where a value does not exist.

    Evaluated in plain floats first (:class:`~fpe_harvester.wide.Float`, ~10x faster), and again
    in :class:`~fpe_harvester.wide.Wide` arithmetic if anything overflowed or underflowed; the two
    give bit-identical results wherever the first succeeds.
    """
    try:
        with np.errstate(all="raise"):
            return _sweep_block_in(Float, a, k, N, params, k4)
    except FloatingPointError:
        return _sweep_block_in(Wide, a, k, N, params, k4)


def _sweep_block_in(num: type, a: np.ndarray, k: np.ndarray, N: int, params: Params,
                    k4: float = 0.0) -> dict[str, np.ndarray]:
    """:func:`_sweep_block` in the arithmetic ``num`` (:class:`Wide` or :class:`Float`)."""
    kappa, scale = wide_mode_stiffness(a, k, N, num, k4)
    soft = np.where(k < 0, N // 2, 0) if k4 == 0.0 else np.argmin(kappa.to_float(), axis=-1)
    kappa_min = kappa.to_float()[np.arange(a.size), soft]
    marginal_q, unstable_q = classify_modes(kappa, scale)
    stable = ~unstable_q.any(axis=-1)
    marginal = stable & marginal_q.any(axis=-1)
    kappa = num.where(marginal_q, 0.0, num.where(stable[:, None], kappa, 1.0))
    mom, err = _wide_ring(kappa, scale, marginal_q & stable[:, None], params, N)
    mom["eta"] = mom["V2"] / (params.R * mom["Pin"])
    rel = [(err[q] / mom[q]).to_float() for q in ("V2", "Pin")]
    err["eta"] = mom["eta"] * np.hypot(*rel)
    mom["Vrms"] = mom["V2"].sqrt()
    # propagated from V2, plus the square root's own rounding (found by tests/exact/test_range.py)
    err["Vrms"] = 0.5 * err["V2"] / mom["Vrms"] + _KAPPA_ROUNDOFF * mom["Vrms"]
    in_range = stable & np.logical_and.reduce([mom[q].representable() for q in _REQUIRED])
    out: dict[str, np.ndarray] = {}
    for key in ("V2", "Pin", "eta", "Vrms", "v2", "vV", "x2", "d2"):
        # an error below the normal range is still an honest (if imprecise) bound: only its
        # value decides; an error that overflows (next to the threshold) drops the value too
        value, error = mom[key].to_float(), err[key].to_float()
        ok = stable & mom[key].representable() & np.isfinite(error)
        if key in ("x2", "d2"):
            ok &= ~marginal
        out[key] = np.where(ok, value, np.nan)
        out[key + "_err"] = np.where(ok, error, np.nan)
    out.update(stable=stable, marginal=marginal, in_range=in_range, kappa_min=kappa_min)
    return out


def exact_sweep(
    a: np.ndarray | float,
    k: np.ndarray | float,
    N: int = 3,
    params: Params | None = None,
    k4: float = 0.0,
) -> dict[str, np.ma.MaskedArray]:
    """Vectorized exact statistics of harmonic rings over arrays of ``a`` and ``k``.

    Parameters
    ----------
    a, k : array_like
        Potential strengths (> 0) and couplings; broadcast against each other (numpy's rules:
        for every pair of a list of ``a`` and a list of ``k``, give ``a`` as a column,
        ``a=[[0.5], [1.0]]``).
    N : int
        Ring size, in [1, :data:`MAX_N`] (for N = 1, ``k`` must be 0).
    params : Params, optional
        Physical parameters (paper's defaults).
    k4 : float
        Bi-Laplacian coupling shared by every point, any finite real (default 0; 0 for N = 1).

    Returns
    -------
    dict of numpy.ma.MaskedArray
        ``V2``, ``Vrms``, ``Pin``, ``eta``, ``v2``, ``vV``, ``x2`` and the round-off errors
        ``V2_err``, ``Pin_err``, ``eta_err``, ``Vrms_err``, ``v2_err``, ``vV_err``, ``x2_err``; points
        with no stationary state (``k < k_di``) are masked, never NaN, and so is ``x2`` at marginal
        points (``k = k_di``), where it diverges, and any value outside the normal double range.
        Also plain arrays ``"stable"`` (bool, marginal included), ``"marginal"`` (bool),
        ``"in_range"`` (bool: stable, and ``V2``, ``Pin`` and ``eta`` are normal doubles) and
        ``"kappa_min"`` (smallest mode stiffness, ``inf`` past the double range), and the swept
        parameters ``"a"`` and ``"k"`` broadcast to the shape of the results.

    Notes
    -----
    The closed form is evaluated in :class:`~fpe_harvester.wide.Wide` arithmetic: bit-for-bit
    the float result where that stays in range, and no intermediate overflow anywhere else.
    Cost: N closed-form evaluations per point; 10,000 points of an N = 3 ring take a few
    milliseconds.

    Raises
    ------
    ParameterError
        ``a`` or ``k`` out of range, or shapes that do not broadcast.

    Examples
    --------
    >>> r = exact_sweep(a=[[0.5], [1.0]], k=[-0.3, -0.2, 0.0], N=3)
    >>> r["eta"].shape, r["a"][1, 0], r["k"][1, 0]
    ((2, 3), np.float64(1.0), np.float64(-0.3))
    """
    params = params or Params()
    N = check_int("N", N, low=1, high=MAX_N)
    try:
        a_arr, k_arr = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(k, dtype=float))
    except ValueError:
        raise ParameterError(
            f"a and k must broadcast against each other, got shapes {np.shape(a)} and {np.shape(k)}; for every "
            "pair of two lists give a as a column, e.g. a=[[0.5], [1.0]], k=[-0.3, -0.2, 0.0]") from None
    if not (np.all(np.isfinite(a_arr)) and np.all(a_arr > 0)):
        raise ParameterError("a must be finite and > 0 everywhere in the sweep, valid range (0, inf)")
    if not np.all(np.isfinite(k_arr)):
        raise ParameterError("k must be finite everywhere in the sweep")
    if N == 1 and np.any(k_arr != 0):
        raise ParameterError("k must be 0 for a single unit (N = 1)")
    k4 = check_real("k4", k4)
    if N == 1 and k4 != 0.0:
        raise ParameterError(f"k4 must be 0 for a single unit (N = 1), got {k4!r}")
    flat_a, flat_k = a_arr.ravel(), k_arr.ravel()
    step = max(1, _BLOCK // N)
    blocks = [_sweep_block(flat_a[i:i + step], flat_k[i:i + step], N, params, k4)
              for i in range(0, max(flat_a.size, 1), step)]
    out: dict[str, np.ma.MaskedArray] = {}
    for key in blocks[0]:
        val = np.concatenate([b[key] for b in blocks]).reshape(a_arr.shape)
        plain = key in ("stable", "marginal", "in_range", "kappa_min")
        out[key] = val if plain else np.ma.masked_invalid(val)
    out.update(a=a_arr.copy(), k=k_arr.copy())
    return out


def exact_stats(hs: Sequence[Harvester]) -> list[Stats]:
    """Exact results of harmonic harvesters, one :func:`exact_sweep` per ring size and parameters.

    The single path from the closed form to :class:`Stats`: :meth:`Exact.solve` calls it with one
    harvester, a scene with all its harmonic points. Marginal points (``k = k_di``) get their
    finite limits and ``x2 = None``; unstable ones no numbers, a message and the growth rate.
    A secondary moment (``v2``, ``vV``, ``x2``) outside the normal double range is ``None`` and
    the message says so.

    Raises
    ------
    MethodNotAvailableError
        A harvester is not harmonic (n != 2), or its ring is larger than :data:`MAX_N`.
    ParameterError
        ``V2``, ``Pin`` or ``eta`` of a stable harvester is outside the normal double range; the
        message names the most extreme parameter and the range that keeps them representable.
    """
    groups: dict[tuple[int, Params, float], list[int]] = {}
    for i, h in enumerate(hs):
        reason = Exact().unsupported_reason(h)
        if reason:
            raise MethodNotAvailableError(reason)
        groups.setdefault((h.N, h.params, h.k4), []).append(i)
    results: dict[int, Stats] = {}
    for (N, params, k4), idx in groups.items():
        sweep = exact_sweep(np.array([hs[i].a for i in idx]), np.array([hs[i].k for i in idx]), N, params, k4)
        for j, i in enumerate(idx):
            results[i] = _point_stats(hs[i], {key: val[j] for key, val in sweep.items()})
    return [results[i] for i in range(len(hs))]


def _sci(x: Wide) -> str:
    """``x`` in scientific notation, also beyond the double range (e.g. ``-4e+400``)."""
    if x.representable():
        return f"{float(x.to_float()):.4g}"
    lg = float(x.log10())
    e = math.floor(lg)
    return f"{'-' if x.sign() < 0 else ''}{10 ** (lg - e):.2g}e{e:+d}"


def _point_stats(h: Harvester, point: dict[str, Any]) -> Stats:
    """:class:`Stats` of ``h`` from its entries of :func:`exact_sweep`."""
    kmin = float(point["kappa_min"])
    kmin_w = kappa_min(h)
    kd = k_di(h.N, h.a, h.k4)
    rate_w = wide_growth_rate(kmin_w, h.params)
    rate = float(rate_w.to_float()) if rate_w is not None and rate_w.representable() else None
    info = {"N": h.N, "kappa_min": kmin, "k_di": kd}
    grows = (f"exp({rate:.4g} t)" if rate is not None else
             f"exp(lambda t), lambda = {_sci(rate_w)} (beyond double range)" if rate_w is not None else
             "exp(lambda t)")
    if not point["stable"]:
        return Stats(
            status=Status.UNSTABLE,
            method=Exact.name,
            growth_rate=rate,
            info=info,
            message=(
                f"unstable: k = {h.k:.10g} is beyond k_di = {kd:.10g}; mode q = {softest_mode(h)} has stiffness "
                f"{_sci(kmin_w)} < 0 and grows like {grows}. Choose k > k_di."
            ),
        )
    if not point["in_range"]:
        raise ParameterError(out_of_range_message(h))
    marginal = bool(point["marginal"])
    message = "stable"
    if marginal:
        message = (
            f"marginal: k = k_di = {kd:.10g}; the critical mode has zero stiffness, so its x "
            "diffuses (x2 is unbounded) while V2, Pin and eta are the finite limits"
        )
    secondary = {}
    dropped = []
    for key in ("v2", "vV", "x2", "d2"):
        value = point[key]
        if value is np.ma.masked or (key == "d2" and h.N == 1):
            secondary[key] = secondary[key + "_err"] = None
            if not (key in ("x2", "d2") and marginal) and h.N > 1:
                dropped.append(key)
        else:
            secondary[key], secondary[key + "_err"] = float(value), float(point[key + "_err"])
    if dropped:
        message += (f"; {', '.join(dropped)} not reported: outside the double range "
                    f"({SMALLEST_NORMAL:.3g} to {LARGEST:.3g}) for these parameters")
    return Stats.from_moments(
        V2=float(point["V2"]), V2_err=float(point["V2_err"]),
        Pin=float(point["Pin"]), Pin_err=float(point["Pin_err"]),
        R=h.params.R,
        Vrms_err=float(point["Vrms_err"]),
        **secondary,
        status=Status.MARGINAL if marginal else Status.STABLE,
        message=message,
        method=Exact.name,
        growth_rate=rate,
        info=info,
    )


def _wide_required(h: Harvester) -> dict[str, Wide]:
    """``V2``, ``Pin`` and ``eta`` of a stable ``h`` as :class:`Wide` (mirror modes evaluated once)."""
    q = np.arange(h.N // 2 + 1)
    weight = np.where((q == 0) | (2 * q == h.N), 1.0, 2.0)
    kappa, scale = wide_mode_stiffness(h.a, h.k, h.N, k4=h.k4)
    kappa, scale = kappa[q], scale[q]
    marginal, _ = classify_modes(kappa, scale)
    mom = wide_mode_moments(Wide.where(marginal, 0.0, kappa), h.params)
    scale = Wide.of(q.size / h.N)
    out = {key: (mom[key] * weight).mean() * scale for key in ("V2", "Pin")}
    out["eta"] = out["V2"] / (h.params.R * out["Pin"])
    return out


def _in_range(h: Harvester) -> bool:
    return all(bool(v.representable()) for v in _wide_required(h).values())


#: Ring sizes up to which an out-of-range message searches the valid range of the culprit.
_SEARCH_MAX_N = 2**16


def _inward(x: float, upper: bool) -> str:
    """``x`` to two significant digits, rounded toward the inside of the range it bounds."""
    e = math.floor(math.log10(x))
    digits = x / 10.0**e * 10
    digits = math.floor(digits * (1 - 1e-12)) if upper else math.ceil(digits * (1 + 1e-12))
    return f"{digits / 10:.1f}e{e:+d}"


def out_of_range_message(h: Harvester) -> str:
    """Why a stable harmonic ``h`` has no representable answer, and which parameter to change.

    Names the quantities outside the normal double range with their magnitudes, and the
    parameter farthest (in log scale) from its default whose change alone brings them back,
    with the bound found by bisection in log scale (the other parameters as given).
    """
    mags = _wide_required(h)
    bad = [key for key, val in mags.items() if not val.representable()]
    what = ", ".join(f"{key} ~ {_sci(mags[key])}" for key in bad)
    limits = f"normal doubles span {SMALLEST_NORMAL:.3g} to {LARGEST:.3g}"
    defaults = {"a": 0.5, **Params().to_dict()}
    values = {"a": h.a, **h.params.to_dict()}
    order = sorted((name for name in defaults if values[name] > 0),
                   key=lambda name: -abs(math.log2(values[name]) - math.log2(defaults[name])))
    for name in order[:3] if h.N <= _SEARCH_MAX_N else ():
        if values[name] == defaults[name] or not _in_range(h.replace(**{name: defaults[name]})):
            continue
        good, bad_end = math.log2(defaults[name]), math.log2(values[name])
        for _ in range(40):
            mid = 0.5 * (good + bad_end)
            if _in_range(h.replace(**{name: 2.0**mid})):
                good = mid
            else:
                bad_end = mid
        upper = values[name] > defaults[name]
        return (f"{name} = {values[name]:g} is out of range for the exact solver here: {what} "
                f"({limits}); with the other parameters as given, {name} {'<=' if upper else '>='} "
                f"{_inward(2.0**good, upper)} keeps them representable (or rescale the problem: docs/model.md §5)")
    given = ", ".join(f"{name} = {values[name]:g}" for name in order[:3])
    return (f"the parameters ({given}, ...) put {what} outside double precision ({limits}); "
            "rescale the problem (docs/model.md §5)")
