"""The Fokker--Planck solver object (``method="fpe"``) of :func:`fpe_harvester.solve`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import HarvesterError, MethodNotAvailableError, ParameterError, check_int, check_real
from ..model import Harvester
from ..result import Stats, Status
from .stationary import MESHES, SCHEMES, _ring_reason, resolve_scheme, stationary

__all__ = ["FokkerPlanck"]


@dataclass(frozen=True)
class FokkerPlanck:
    """Stationary statistics of a single oscillator :math:`U = a|x|^n` from its Fokker--Planck equation.

    The density is expanded in normalized Hermite functions of (v, V, xi) up to total
    degree M and discretized in x by upwind discontinuous Galerkin (scikit-fem); M and
    the mesh are refined until the estimated relative error on eta is below ``tol``
    (see :func:`~fpe_harvester.fpe.stationary`). Reaching the limits gives status
    NOT_CONVERGED with the best estimate and its error.

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
        (V, xi) (``"xv"``, :mod:`~fpe_harvester.fpe.kink`; for 1 < n < 2 ``"x"`` if
        ``mesh`` or ``elements`` is given), else DG in x with Hermite functions of
        (v, V, xi) (``"x"``). ``"x"`` forces the latter for 1 <= n < 2 too (benchmarks
        compare them). For ``"xv"``, ``elements`` is not used and ``order`` is the DG
        degree in x and v.
    mesh : str
        x mesh of scheme ``"x"``: ``"auto"`` (default, the algebraic one), ``"algebraic"``
        (graded toward 0 for n < 2, toward the walls otherwise; a mesh step bisects every
        element), ``"geometric"`` (n < 2: layers toward 0) or ``"adaptive"`` (any n: a
        mesh step bisects only the elements an error indicator marks, see
        :mod:`~fpe_harvester.fpe.adapt`).

    Examples
    --------
    >>> from fpe_harvester import Harvester, solve
    >>> r = solve(Harvester.build(a=0.5, n=2), "fpe", tol=1e-3, M=4, elements=16)
    >>> r.status.value, abs(r.eta - 20 / 39) < 1e-6
    ('stable', True)
    """

    name: ClassVar[str] = "fpe"

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

    def __post_init__(self) -> None:
        if self.scheme not in SCHEMES:
            raise ParameterError(f"scheme must be one of {', '.join(map(repr, SCHEMES))}, got {self.scheme!r} "
                                 f"(type {type(self.scheme).__name__})")
        if self.mesh not in MESHES:
            raise ParameterError(f"mesh must be one of {', '.join(map(repr, MESHES))}, got {self.mesh!r} "
                                 f"(type {type(self.mesh).__name__})")
        object.__setattr__(self, "tol", check_real("tol", self.tol, low=0.0, high=0.1, low_open=True))
        if self.M is not None:
            object.__setattr__(self, "M", check_int("M", self.M, low=2, high=60))
        if self.elements is not None:
            el = check_int("elements", self.elements, low=2, high=2048)
            if el % 2:
                raise MethodNotAvailableError(f"elements must be even (a node at x = 0), got {el}")
            object.__setattr__(self, "elements", el)
        if self.order is not None:
            object.__setattr__(self, "order", check_int("order", self.order, low=2, high=5))
        object.__setattr__(self, "domain", check_real("domain", self.domain, low=5.0, high=200.0))
        object.__setattr__(self, "max_M", check_int("max_M", self.max_M, low=4, high=60))
        if self.max_seconds is not None:
            object.__setattr__(self, "max_seconds",
                               check_real("max_seconds", self.max_seconds, low=0.0, low_open=True))
        if self.max_gb is not None:
            object.__setattr__(self, "max_gb", check_real("max_gb", self.max_gb, low=0.0, low_open=True))

    def unsupported_reason(self, h: Harvester) -> str | None:
        """``None`` for a single oscillator, else why not (rings: use mc, or exact if harmonic)."""
        if h.N != 1:
            return _ring_reason(h)
        return None

    def solve(self, h: Harvester) -> Stats:
        """Stationary statistics with error estimates (status NOT_CONVERGED if tol is not met)."""
        reason = self.unsupported_reason(h)
        if reason:
            raise MethodNotAvailableError(reason)
        progress = self.progress
        if progress is True:
            progress = print
        try:
            sol = stationary(
                h, self.tol, M=self.M,
                half_elements=None if self.elements is None
                or resolve_scheme(h, self.scheme, x_settings=h.n != 1.0) == "xv" else self.elements // 2,
                order=self.order, theta=self.domain, max_M=max(self.max_M, self.M or 0),
                max_seconds=self.max_seconds, max_gb=self.max_gb, grid=3, progress=progress or None,
                scheme=self.scheme, mesh=self.mesh,
            )
        except HarvesterError:
            raise
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            # Numerical breakdown outside the refinement loop (whitening, field evaluation):
            # report it as a status, the caller asked for numbers, not a traceback.
            return Stats(status=Status.NOT_CONVERGED, method="fpe",
                         message=f"Fokker-Planck solve failed numerically ({type(exc).__name__}: {exc}); "
                                 "use method='mc'", info={"tol": self.tol})
        return sol.stats
