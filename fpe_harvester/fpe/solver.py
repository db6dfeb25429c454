"""The Fokker--Planck solver object (``method="fpe"``) of :func:`fpe_harvester.solve`."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import HarvesterError, MethodNotAvailableError, ParameterError
from ..model import Harvester
from ..result import Stats, Status
from ..solvers import Capabilities, Tolerance
from .domain import outside_reason
from .schemes import check_settings
from .settings import Settings
from .stationary import ring_reason, solve_settings

__all__ = ["FokkerPlanck"]


@dataclass(frozen=True)
class FokkerPlanck:
    """Stationary statistics of a single oscillator :math:`U = a|x|^n` from its Fokker--Planck equation.

    The density is expanded in normalized Hermite functions of (v, V, xi) up to total
    degree M and discretized in x by upwind discontinuous Galerkin (scikit-fem); M and
    the mesh are refined until the estimated relative error on eta is below ``tol``
    (see :func:`~fpe_harvester.fpe.stationary`). Reaching the limits gives status
    NOT_CONVERGED with the best estimate and its error.

    For 1 <= n < 2 and a potential strong against the drive (the strong kink: n = 1, a = 2 at
    the defaults) the refinement does not converge; there the solver declines at once
    (:meth:`unsupported_reason`, the measured domain of :mod:`~fpe_harvester.fpe.domain`) and
    names Monte Carlo, unless ``force=True``.

    Parameters
    ----------
    tol : float
        Requested relative error on eta, in (0, 0.1]. Default 1e-4.
    M : int, optional
        Hermite total degree (>= 2). Together with ``elements``: a fixed level whose
        error is estimated against one refinement of each knob.
    elements : int, optional
        Number of elements in x (even, >= 2).
    order : int, optional
        DG polynomial order, 2..5 (default 3).
    domain : float
        Domain factor :math:`\\Theta = U(L)/T_{eff}` in [5, 200]. Default 30.
    max_M : int
        Largest Hermite degree the refinement may use (default 24).
    max_seconds : float, optional
        Wall-time budget of the refinement.
    max_gb : float, optional
        Memory bound (GB) of one discretization level; default half the physical memory.
    progress : bool or callable
        True prints one line per level; a callable receives the lines.
    scheme : str
        ``"auto"`` (default): for 1 <= n < 2 DG in (x, v) with Hermite functions of
        (V, xi) (``"xv"``, :mod:`~fpe_harvester.fpe.schemes.xv`; for 1 < n < 2 ``"x"`` if
        ``mesh`` or ``elements`` is given), else DG in x with Hermite functions of
        (v, V, xi) (``"x"``). ``"x"`` forces the latter for 1 <= n < 2 too (benchmarks
        compare them). For ``"xv"``, ``elements`` is not used and ``order`` is the DG
        degree in x and v.
    mesh : str
        x mesh of scheme ``"x"``: ``"auto"`` (default, the algebraic one), ``"algebraic"``
        (graded toward 0 for n < 2, toward the walls otherwise; a mesh step bisects every
        element), ``"geometric"`` (n < 2: layers toward 0) or ``"adaptive"`` (any n: a
        mesh step bisects only the elements an error indicator marks, see
        :mod:`~fpe_harvester.fpe.schemes.x.adapt`).
    force : bool
        Attempt the solve outside the measured domain of the solver (see
        :mod:`~fpe_harvester.fpe.domain`) instead of declining at once. Default False: outside
        it, :meth:`unsupported_reason` names the domain and Monte Carlo, and
        :func:`~fpe_harvester.solve` raises :class:`~fpe_harvester.errors.MethodNotAvailableError`.

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5, n=2), "fpe", tol=1e-3, M=4, elements=16)
    >>> r.status.value, abs(r.eta - 20 / 39) < 1e-6
    ('stable', True)
    """

    name: ClassVar[str] = "fpe"
    #: What the drivers read (:class:`~fpe_harvester.solvers.Capabilities`): tol in (0, 0.1],
    #: deterministic, a wall-time budget ``max_seconds``, one progress line per refinement level,
    #: single-threaded and slow enough for a process pool.
    capabilities: ClassVar[Capabilities] = Capabilities(
        title="Fokker-Planck", tol=Tolerance(0.1, 1e-4), max_time="max_seconds", progress="lines", pooled=True)

    tol: float = 1e-4
    M: int | None = None
    elements: int | None = None
    order: int | None = None
    domain: float = 30.0
    max_M: int = 24
    max_seconds: float | None = None
    max_gb: float | None = None
    progress: bool | Callable[[str], None] = False
    scheme: str = "auto"
    mesh: str = "auto"
    force: bool = False

    def __post_init__(self) -> None:
        settings = self.settings
        for name in ("tol", "M", "elements", "order", "domain", "max_seconds", "max_gb"):
            object.__setattr__(self, name, getattr(settings, name))
        if not isinstance(self.force, bool):
            raise ParameterError(f"force must be True or False, got {self.force!r} "
                                 f"(type {type(self.force).__name__})")

    @functools.cached_property
    def settings(self) -> Settings:
        """The validated settings of the stationary solve (made, and so checked, at construction)."""
        return check_settings(Settings(tol=self.tol, M=self.M, elements=self.elements, order=self.order,
                                       domain=self.domain, max_M=self.max_M, max_seconds=self.max_seconds,
                                       max_gb=self.max_gb, scheme=self.scheme, mesh=self.mesh))

    def unsupported_reason(self, h: Harvester) -> str | None:
        """``None`` if the solver takes ``h``, else why not and what to use instead: a ring
        (Monte Carlo, or exact if harmonic), or a single unit outside the measured domain at
        this ``tol`` (:func:`~.domain.outside_reason`: Monte Carlo, or ``force=True``). Costs
        a few milliseconds; :func:`~fpe_harvester.solve` calls it before solving."""
        if h.N != 1:
            return ring_reason(h)
        if self.force:
            return None
        return outside_reason(h, self.tol)

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics with error estimates (status NOT_CONVERGED if tol is not met)."""
        reason = self.unsupported_reason(h)
        if reason:
            raise MethodNotAvailableError(reason)
        progress = self.progress
        if progress is True:
            progress = print
        try:
            sol = solve_settings(h, self.settings, grid=3, progress=progress or None)
        except HarvesterError:
            raise
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            # Numerical breakdown outside the refinement loop (whitening, field evaluation):
            # report it as a status, the caller asked for numbers, not a traceback.
            return Stats(status=Status.NOT_CONVERGED, method="fpe",
                         message=f"Fokker-Planck solve failed numerically ({type(exc).__name__}: {exc}); "
                                 "use method='mc'", info={"tol": self.tol})
        return sol.stats
