"""One call for every solver: ``solve(harvester, method)``.

Solvers are small immutable settings objects with a ``name``, an
``unsupported_reason(harvester)`` method (``None`` when they can handle it) and
``solve(harvester) -> Stats``. They are chosen by object or by name from
:data:`METHODS`, a plain dict of import paths (imported on first use, so that the
Monte Carlo and Fokker--Planck stacks load only when asked for).

``method="auto"`` never leaves the caller without numbers where Fokker--Planck stops short of
its tolerance: Monte Carlo then runs within a time budget and :func:`fallback_result` (also
used by the scenes) keeps the better of the two and says which solver gave the numbers.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from typing import Any, Protocol

from .errors import MethodNotAvailableError, ParameterError, check_real
from .model import Harvester
from .result import QUANTITIES, Stats, Status

__all__ = ["Solver", "METHODS", "FALLBACK_SECONDS", "get_solver", "choose_method", "solve",
           "fallback_result", "relative_eta_error"]

#: Default wall-time budget (s) of the Monte Carlo run of ``solve(method="auto")`` where
#: Fokker--Planck stops short of its tolerance. n = 1, a = 2 (where Fokker--Planck gives no
#: number): Monte Carlo reaches about 3e-3 on eta in that time on 2 cores.
FALLBACK_SECONDS = 60.0


class Solver(Protocol):
    """What every solver settings object provides."""

    name: str

    def unsupported_reason(self, h: Harvester) -> str | None: ...

    def solve(self, h: Harvester) -> Stats: ...


#: Solver classes by name, as ``"module:Class"`` import paths.
METHODS: dict[str, str] = {
    "exact": "fpe_harvester.exact:Exact",
    "fpe": "fpe_harvester.fpe:FokkerPlanck",
    "mc": "montecarlo:MonteCarlo",
}


def _solver_class(name: str) -> type:
    if name not in METHODS:
        valid = ", ".join(repr(m) for m in (*METHODS, "auto"))
        raise ParameterError(f"method must be one of {valid}; got {name!r} (type {type(name).__name__})")
    module, _, cls = METHODS[name].partition(":")
    try:
        return getattr(importlib.import_module(module), cls)
    except (ImportError, AttributeError) as exc:
        raise MethodNotAvailableError(
            f"method {name!r} is not available yet in this installation ({exc})"
        ) from exc


def choose_method(h: Harvester) -> str:
    """The cheapest adequate method: linear (harmonic, ``k3 = 0``, any ``k`` and ``k4``) -> exact,
    single nonlinear unit -> fpe (a single unit has no coupling), else mc (so a harmonic ring
    with cubic coupling ``k3 != 0`` goes to Monte Carlo)."""
    if h.is_linear:
        return "exact"
    if h.N == 1:
        return "fpe"
    return "mc"


def get_solver(method: str | Solver = "auto", h: Harvester | None = None, **options: Any) -> Solver:
    """Build a solver from a name (``"auto"`` needs ``h``) and its settings, or pass one through."""
    if not isinstance(method, str):
        if options:
            raise ParameterError(
                f"solver options {sorted(options)} cannot be combined with a solver object; "
                "use dataclasses.replace on the object instead"
            )
        return method
    if method == "auto":
        if h is None:
            raise ParameterError("method='auto' needs the harvester to choose a solver")
        method = choose_method(h)
    cls = _solver_class(method)
    valid = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else None
    unknown = sorted(set(options) - set(valid)) if valid is not None else []
    if unknown:
        raise ParameterError(
            f"invalid option for method {method!r}: no option {', '.join(map(repr, unknown))}; valid options: "
            + (", ".join(valid) if valid else "none (the exact solver needs no settings: its results are "
               "exact to round-off)"))
    try:
        return cls(**options)
    except TypeError as exc:
        raise ParameterError(f"invalid option for method {method!r}: {exc}") from exc


def solve(h: Harvester, method: str | Solver = "auto", *, fallback_time: float | None = FALLBACK_SECONDS,
          **options: Any) -> Stats:
    """Stationary statistics of a harvester.

    Parameters
    ----------
    h : Harvester
        The problem: potential, ring size, coupling and parameters.
    method : {"auto", "exact", "fpe", "mc"} or solver object
        ``"auto"`` picks the cheapest method that handles ``h`` (harmonic: exact; single
        nonlinear unit: Fokker--Planck; coupled nonlinear ring: Monte Carlo).
    fallback_time : float or None
        ``"auto"`` only: where Fokker--Planck stops short of its tolerance (status
        ``not_converged``), Monte Carlo runs for at most this many seconds (wall time, >= 0;
        default :data:`FALLBACK_SECONDS`) with the same tolerance, and the better result is
        returned (see :func:`fallback_result`). ``None`` or 0: no fallback. ``method="fpe"``
        never falls back: it reports its own ``not_converged``.
    **options
        Settings passed to the solver's constructor when ``method`` is a name
        (e.g. ``tol=1e-6`` for ``"fpe"``, ``seed=1`` for ``"mc"``).

    Returns
    -------
    Stats
        Values with errors and a status; an unstable system is reported, not raised
        (call :meth:`Stats.raise_for_status` to turn that into an exception). After a
        fallback, ``method`` names the solver whose numbers these are and ``info["fallback"]``
        holds the numbers of the other.

    Raises
    ------
    ParameterError
        Unknown method, invalid solver option or negative ``fallback_time``.
    MethodNotAvailableError
        The chosen solver cannot handle this problem (e.g. ``"exact"`` with n != 2).
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    if fallback_time is not None:
        fallback_time = check_real("fallback_time", fallback_time, low=0.0)
    solver = get_solver(method, h, **options)
    reason = solver.unsupported_reason(h)
    if reason:
        raise MethodNotAvailableError(reason)
    res = solver.solve(h)
    if method == "auto" and solver.name == "fpe" and fallback_time and res.status is Status.NOT_CONVERGED:
        return _monte_carlo_fallback(h, res, fallback_time, solver.tol, options.get("progress"))
    return res


def _monte_carlo_fallback(h: Harvester, first: Stats, seconds: float, tol: float, progress: Any) -> Stats:
    """Monte Carlo for ``h`` within ``seconds`` (wall time) at relative tolerance ``tol`` on eta,
    merged with the Fokker--Planck result ``first`` by :func:`fallback_result`; ``progress``
    False (the caller's) silences its bar too. Without Monte Carlo (numba missing) ``first``
    is returned with a note."""
    try:
        mc = get_solver("mc", h, tol=tol, max_time=seconds, progress=False if progress is False else None)
    except MethodNotAvailableError as exc:
        return dataclasses.replace(first, message=f"{first.message}; no Monte Carlo fallback ({exc})")
    return fallback_result(first, mc.solve(h))


def fallback_result(first: Stats, second: Stats) -> Stats:
    """The result to report after ``first`` (Fokker--Planck, not converged) was retried with
    ``second`` (Monte Carlo).

    ``second`` replaces ``first`` when it describes a stationary state (stable or marginal),
    or when ``first`` has no numbers; otherwise the one with the smaller relative error on
    eta is kept. The message says which solver gave the numbers and why; ``info["fallback"]``
    names that solver (``"kept"``) and holds the other one's method, status, message and
    numbers, each quantity with its error, None where it gave none (``"other"``), so that
    the two can be compared. Measured on the
    paper's Fig. 1 grid at rtol 5e-3: n = 1.25, a = 2 stops at 8.9e-3 with Fokker--Planck
    (17 s; its Hermite levels stop converging) and Monte Carlo then reaches 4.6e-3 in 2.4 s.

    Parameters
    ----------
    first, second : Stats
        The Fokker--Planck result (status ``not_converged``) and the Monte Carlo one.

    Returns
    -------
    Stats
        ``second`` or ``first``, with the message and ``info`` extended.
    """
    if first.eta is None:
        note = f"Fokker-Planck gave no result ({first.message}); Monte Carlo used instead"
    elif second.ok or relative_eta_error(second) < relative_eta_error(first):
        err = "no error estimate" if first.eta_err is None else f"+- {first.eta_err:.2g}"
        note = (f"Fokker-Planck did not reach the tolerance (eta = {first.eta:.6g} {err}: "
                f"{first.message}); Monte Carlo used instead")
    else:
        info = {**first.info, "fallback": _fallback_info(first, second)}
        return dataclasses.replace(first, message=f"{first.message}; Monte Carlo did no better ({second.message})",
                                   info=info)
    info = {**second.info, "fallback": _fallback_info(second, first)}
    return dataclasses.replace(second, message=f"{second.message}; {note}", info=info)


def _fallback_info(kept: Stats, other: Stats) -> dict[str, Any]:
    """What a result tried twice records: the solver kept, and the other one's method, status,
    message and numbers (each quantity and its error, None where it gave none)."""
    numbers = {f"{q}{suffix}": v for q in QUANTITIES for suffix, v in zip(("", "_err"), other.value(q))}
    return {"kept": kept.method, "other": {"method": other.method, "status": other.status.value,
                                           "message": other.message, **numbers}}


def relative_eta_error(res: Stats) -> float:
    """eta_err / |eta|; inf when either is missing or eta is 0."""
    if res.eta is None or res.eta_err is None or res.eta == 0:
        return math.inf
    return res.eta_err / abs(res.eta)
