"""What the refinement and :func:`~.stationary.stationary` need of a Fokker--Planck scheme.

A *scheme* is one way to discretize the stationary Fokker--Planck equation of a single
unit (today ``"x"``: DG in x times Hermite functions of (v, V, xi), :mod:`.schemes.x`;
``"xv"``: DG in (x, v) times Hermite functions of (V, xi), :mod:`.schemes.xv`). Three
protocols describe it, from the outside in:

- :class:`Scheme`, the entry of the registry :data:`~.schemes.SCHEMES`: whether it solves a
  harvester, whether ``scheme="auto"`` should pick it, the options only it has, and how it
  turns the user's :class:`~.settings.Settings` into a refinement :class:`RefinementPlan`
  and a :class:`Discretization`.
- :class:`Discretization`, what :func:`~.refine.refine` refines: a family of levels indexed
  by the Hermite degree M and an integer mesh knob ``size`` (one refinement step doubles
  it), with its cost model and limits.
- :class:`Level`, one solved level: its moments (see :func:`~.moments.harvester_moments`),
  its fields on x, and its description.

The plan a scheme makes, :class:`RefinementPlan` (the starting level and the limits), is
defined here too.

Adding a scheme is one subpackage of :mod:`.schemes` (its level, discretization, default
plan and mesh, and a :class:`Scheme` object) and one entry in :data:`~.schemes.SCHEMES`;
neither the refinement nor :func:`~.stationary.stationary` changes. Members with a default
below need not be written by a scheme that subclasses the protocol.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from ..model import Harvester
    from .settings import Settings

__all__ = ["Level", "Discretization", "Scheme", "RefinementPlan", "default_memory_gb"]


@dataclass(frozen=True)
class RefinementPlan:
    """Starting level and limits of the refinement (made by a scheme,
    :meth:`Scheme.plan`).

    Attributes
    ----------
    M : int
        Hermite degree to start from (fixed with ``fixed``), >= 2.
    size : int
        The discretization's mesh knob to start from (fixed with ``fixed``); one refinement
        step doubles it.
    fixed : bool
        If True, solve at (M, size) and estimate the error from one refinement step of each
        knob (M + 2, twice the size); no adaptation.
    max_M, max_size, max_dofs : int
        Limits; the solve reports NOT_CONVERGED when tol needs more. ``max_dofs`` counts
        the unknowns of the whole domain (:meth:`~.protocol.Discretization.unknowns`).
    max_seconds : float or None
        Wall-time budget (s); no level starts whose predicted cost would exceed it.
    max_gb : float or None
        Memory bound of one level in GB (:meth:`~.protocol.Discretization.gigabytes`);
        default (None): half the physical memory.
    """

    M: int
    size: int
    fixed: bool = False
    max_M: int = 24
    max_size: int = 256
    max_dofs: int = 600_000
    max_seconds: float | None = None
    max_gb: float | None = None

    @property
    def memory_limit(self) -> float:
        """The memory bound in GB (``max_gb`` or half the physical memory)."""
        return default_memory_gb() if self.max_gb is None else self.max_gb


def default_memory_gb() -> float:
    """Half the physical memory in GB (8 GB if the platform does not tell)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 8.0
    return max(0.5 * total / 1e9, 1.0)


class Level(Protocol):
    """One solved level of a discretization.

    Attributes
    ----------
    M : int
        Hermite degree.
    moments : dict
        ``V2, Pin, eta, v2, vV, vxi, x2`` and the identity residuals ``res_V2`` and
        ``res_power`` (:func:`~.moments.harvester_moments`), possibly more.
    seconds : float
        Wall time of the level (s).
    dofs : int
        Number of unknowns.
    """

    M: int
    moments: dict[str, float]
    seconds: float
    dofs: int

    @property
    def size(self) -> int:
        """The refinement's mesh knob the level was solved on."""
        ...

    @property
    def elements(self) -> int:
        """Elements of the whole mesh (for messages)."""
        ...

    @property
    def half_width(self) -> float:
        """Half-width of the x domain: the result's grid spans [-half_width, half_width]."""
        ...

    def summary(self) -> dict[str, Any]:
        """JSON-ready description for the refinement history."""
        ...

    def info(self) -> dict[str, Any]:
        """Discretization details for the result's ``info`` (``scheme`` among them)."""
        ...

    def fields(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """x-marginal ``density`` and the conditional means ``v_mean``, ``V_mean``, ``xi_mean``
        at the points ``x`` (:func:`~.moments.conditional_fields`)."""
        ...


class Discretization(Protocol):
    """A family of levels indexed by the Hermite degree M and an integer mesh ``size`` (one
    refinement step doubles it), as :func:`~.refine.refine` sees it.

    Attributes
    ----------
    order : int
        DG order (for the observed mesh order of :func:`~.estimate.mesh_error`).
    algebraic : bool
        Hermite errors with algebraic tails (n < 2, see :mod:`.estimate`).
    advice : str
        What a user can do when no level gives an error estimate (ends the stop message).
    work_exponents : tuple of float
        Range of the exponent q of the cost model :meth:`work`.
    mesh_check_degree : int
        Lowest Hermite degree at which a mesh check is meaningful.
    refine_early : bool
        Refine the mesh as soon as the first mesh check fails (a cheap refinement step,
        the element-wise one). Default False.
    """

    order: int
    algebraic: bool
    advice: str
    work_exponents: tuple[float, float]
    mesh_check_degree: int
    refine_early: bool = False

    @property
    def check_floor(self) -> int:
        """Lowest degree of a mesh check at M - 4 once M - 2 is above it (default
        :attr:`mesh_check_degree`)."""
        return self.mesh_check_degree

    @property
    def check_ceiling(self) -> int | None:
        """Highest degree of a mesh check (None: none, the check follows M at M - 4). A
        discretization whose mesh error hardly changes with M checks its mesh there at
        every M, at a fraction of the cost of a check at M - 4."""
        return None

    def solve(self, M: int, size: int, lower: Level | None = None) -> Level:
        """Solve level (M, size); ``lower`` is a solved lower degree on the same mesh."""
        ...

    def unknowns(self, M: int, size: int) -> int:
        """Unknowns of the whole domain at level (M, size)."""
        ...

    def gigabytes(self, M: int, size: int) -> float:
        """Memory (GB) of level (M, size)."""
        ...

    def max_degree(self, size: int) -> int:
        """The highest M the mesh of ``size`` carries."""
        ...

    def work(self, M: int, size: int) -> tuple[float, float]:
        """Cost model of a level, ``(w, u)``: the time scales like :math:`w\\,u^q`, q in
        :attr:`work_exponents` (measured from the solved levels)."""
        ...

    def describe(self, size: int) -> str:
        """The mesh of ``size`` in words (e.g. '16 elements')."""
        ...

    def outgrown(self, size: int) -> None:
        """M needs more than mesh ``size`` carries: called before the refinement asks for
        ``2 * size`` (default: nothing to do)."""


class Scheme(Protocol):
    """An entry of the scheme registry :data:`~.schemes.SCHEMES`.

    Attributes
    ----------
    name : str
        The user's name of the scheme (``scheme=...``).
    priority : int
        ``scheme="auto"`` takes the scheme of highest priority that :meth:`preferred` says
        suits the harvester.
    options : Mapping[str, str]
        The :class:`~.settings.Settings` fields only this scheme reads, each with what it is
        (``{"mesh": "the x mesh"}``); giving one with another scheme is an error. Default none.
    setup_failure : str
        Start of the message when :meth:`build` fails numerically.
    """

    name: str
    priority: int
    setup_failure: str
    options: Mapping[str, str] = {}

    def refusal(self, h: Harvester) -> str:
        """Why the scheme cannot solve ``h`` (empty if it can; default: it can)."""
        return ""

    def preferred(self, h: Harvester, settings: Settings) -> bool:
        """Whether ``scheme="auto"`` should take this scheme for ``h`` and ``settings``."""
        ...

    def check(self, settings: Settings) -> None:
        """Raise :class:`~fpe_harvester.errors.ParameterError` if an option of
        :attr:`options` has an invalid value (default: nothing to check)."""

    def plan(self, h: Harvester, settings: Settings) -> RefinementPlan:
        """The starting level and the limits of the refinement."""
        ...

    def build(self, h: Harvester, settings: Settings, plan: RefinementPlan, tol: float, deadline: float | None
              ) -> Discretization:
        """The discretization of ``h``; ``deadline`` is a :func:`time.perf_counter` value
        after which a solve may stop (None: no budget)."""
        ...
