"""One call for every solver: ``solve(harvester, method)``.

Solvers are small immutable settings objects with a ``name``, an
``unsupported_reason(harvester)`` method (``None`` when they can handle it) and
``solve(harvester) -> Stats``. They are chosen by object or by name from
:data:`METHODS`, a plain dict of import paths (imported on first use, so that the
Monte Carlo and Fokker--Planck stacks load only when asked for).
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any, Protocol

from .errors import MethodNotAvailableError, ParameterError
from .model import Harvester
from .result import Stats

__all__ = ["Solver", "METHODS", "get_solver", "choose_method", "solve"]


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


def solve(h: Harvester, method: str | Solver = "auto", **options: Any) -> Stats:
    """Stationary statistics of a harvester.

    Parameters
    ----------
    h : Harvester
        The problem: potential, ring size, coupling and parameters.
    method : {"auto", "exact", "fpe", "mc"} or solver object
        ``"auto"`` picks the cheapest method that handles ``h`` (harmonic: exact; single
        nonlinear unit: Fokker--Planck; coupled nonlinear ring: Monte Carlo).
    **options
        Settings passed to the solver's constructor when ``method`` is a name
        (e.g. ``tol=1e-6`` for ``"fpe"``, ``seed=1`` for ``"mc"``).

    Returns
    -------
    Stats
        Values with errors and a status; an unstable system is reported, not raised
        (call :meth:`Stats.raise_for_status` to turn that into an exception).

    Raises
    ------
    ParameterError
        Unknown method or invalid solver option.
    MethodNotAvailableError
        The chosen solver cannot handle this problem (e.g. ``"exact"`` with n != 2).
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    solver = get_solver(method, h, **options)
    reason = solver.unsupported_reason(h)
    if reason:
        raise MethodNotAvailableError(reason)
    return solver.solve(h)
