"""The solver protocol and the registry: what a solver declares, so that drivers ask instead of
testing its name.

A solver is a small immutable settings object (a frozen dataclass whose fields are its settings)
with a ``name``, ``unsupported_reason(h)`` and ``solve(h)``, and a :class:`Capabilities`
declaration: the tolerance it takes, whether it is random, its wall-time budget, how it reports
progress, how its points are best run and its vectorized ``solve_many`` if it has one. The
drivers (:func:`~fpe_harvester.solve.solve`, the command line, the scenes, the optimizer) read
only these. :data:`METHODS` maps names to solver classes as ``"module:Class"`` import paths
(imported on first use, so that the Monte Carlo and Fokker--Planck stacks load only when asked
for); its order is the order in which ``method="auto"`` asks them. A new solver is one module
and one entry there.
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from .errors import MethodNotAvailableError, ParameterError
from .model import Harvester
from .result import Stats

__all__ = ["Tolerance", "Capabilities", "Solver", "METHODS", "COMMON_SETTINGS",
           "solver_class", "capabilities", "title", "option_names"]


@dataclass(frozen=True)
class Tolerance:
    """The relative tolerance on eta a solver accepts: ``(0, high]``, or ``(0, high)`` when
    ``high_open``, and its default.

    Examples
    --------
    >>> str(Tolerance(0.1, 1e-4))
    '(0, 0.1]'
    """

    high: float
    default: float
    high_open: bool = False

    def __str__(self) -> str:
        return f"(0, {self.high:g}{')' if self.high_open else ']'}"


@dataclass(frozen=True)
class Capabilities:
    """What a solver takes and how a driver may run it; every member has a default, so a solver
    declares only what it has.

    Attributes
    ----------
    title : str
        Its name in messages (``"Fokker-Planck"``).
    tol : Tolerance or None
        The relative tolerance on eta it takes as its setting ``tol``; ``None``: it has none
        (exact to round-off).
    seed : bool
        Random: it takes a setting ``seed`` (an int >= 0) and its numbers depend on it.
    max_time : str or None
        The name of its wall-time budget setting (seconds), if it has one.
    progress : {None, "bar", "lines"}
        How it reports progress through its setting ``progress``: ``"bar"``, it draws its own
        bar (``True``, ``False`` or ``None``: only on a terminal); ``"lines"``, it calls
        ``progress(line)`` once per step and the driver draws the bar.
    threads : bool
        It runs its own worker threads, as many as its setting ``threads``.
    pooled : bool
        Single-threaded and slow: a sweep gains from running its points in a process pool.
    solve_many : bool
        It has ``solve_many(hs) -> list[Stats]``, all points in one vectorized call.
    portable : callable or None
        ``portable(settings) -> dict``: the settings whose defaults depend on the machine and
        shape the numbers, fixed to this machine's values, so that a point computed on another
        machine (a Dask worker) gives the same numbers.
    common_random_numbers : callable or None
        ``common_random_numbers(solver, h, replicas) -> dict``: settings that make its runs at
        every parameter value near ``h`` share their random numbers, ``replicas`` independent
        replicas per run (the noisy optimizer's requirement; random solvers only).
    """

    title: str
    tol: Tolerance | None = None
    seed: bool = False
    max_time: str | None = None
    progress: str | None = None
    threads: bool = False
    pooled: bool = False
    solve_many: bool = False
    portable: Callable[[Mapping[str, Any]], dict[str, Any]] | None = None
    common_random_numbers: Callable[[Any, Harvester, int], dict[str, Any]] | None = None

    def __post_init__(self) -> None:
        if self.progress not in (None, "bar", "lines"):
            raise ValueError(f"progress must be None, 'bar' or 'lines', got {self.progress!r}")


class Solver(Protocol):
    """What every solver provides (``solve_many`` only where its capabilities say so)."""

    name: ClassVar[str]
    capabilities: ClassVar[Capabilities]

    def unsupported_reason(self, h: Harvester) -> str | None:
        """``None`` when the solver handles ``h``, else why not and what to use."""

    def solve(self, h: Harvester) -> Stats:
        """The stationary statistics of ``h``."""


#: Solver classes by name, as ``"module:Class"`` import paths (or the class itself), in the order
#: in which ``method="auto"`` asks them whether they handle a system: the cheapest first; the
#: first that does answers, the next one takes over where it stops short of its tolerance.
METHODS: dict[str, str | type] = {
    "exact": "fpe_harvester.exact:Exact",
    "fpe": "fpe_harvester.fpe:FokkerPlanck",
    "mc": "montecarlo:MonteCarlo",
}

#: Settings every method accepts: each solver uses those it has and ignores the others
#: (``max_seconds`` is another name of ``max_time``).
COMMON_SETTINGS: tuple[str, ...] = ("tol", "seed", "max_time", "progress")


def solver_class(name: str) -> type:
    """The solver class registered as ``name``.

    Raises
    ------
    ParameterError
        ``name`` is not in :data:`METHODS`.
    MethodNotAvailableError
        Its module cannot be imported in this installation.
    """
    if not isinstance(name, str) or name not in METHODS:
        valid = ", ".join(repr(m) for m in (*METHODS, "auto"))
        raise ParameterError(f"method must be one of {valid}; got {name!r} (type {type(name).__name__})")
    entry = METHODS[name]
    if isinstance(entry, type):
        return entry
    module, _, cls = entry.partition(":")
    try:
        return getattr(importlib.import_module(module), cls)
    except (ImportError, AttributeError) as exc:
        raise MethodNotAvailableError(
            f"method {name!r} is not available yet in this installation ({exc})"
        ) from exc


def capabilities(name: str) -> Capabilities:
    """The declared :class:`Capabilities` of the solver registered as ``name``."""
    return solver_class(name).capabilities


def title(name: str) -> str:
    """The solver's name in messages (its ``name`` if it is not registered or not installed)."""
    try:
        return capabilities(name).title
    except (ParameterError, MethodNotAvailableError):
        return name


def option_names(cls: type) -> Sequence[str]:
    """The settings of a solver class: its dataclass fields."""
    return [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
