"""The user's settings of a stationary Fokker--Planck solve, validated once.

:func:`~.stationary.stationary` and :class:`~.solver.FokkerPlanck` both build a
:class:`Settings`, with the same names for the same options; its ``__post_init__`` is the one
place where tol, M, the mesh knob, order, the domain factor and the limits are checked. The
name of the scheme and the options of one scheme only (``mesh``, ``weight``) are checked by
the scheme registry (:func:`~.schemes.check_settings`), which knows the schemes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from ..errors import ParameterError, check_int, check_real

__all__ = ["Settings"]


@dataclass(frozen=True)
class Settings:
    """Settings of a stationary solve (see :func:`~.stationary.stationary` for their meaning).

    Attributes
    ----------
    tol : float
        Requested relative error on eta, in (0, 0.1].
    M : int or None
        Hermite degree to start from, in [2, 60].
    elements : int or None
        Elements of the whole x mesh of scheme ``"x"`` to start from (even, in [2, 2048]: a
        node at x = 0); scheme ``"xv"`` ignores it.
    order : int or None
        DG order in [2, 5].
    domain : float
        Domain factor :math:`\\Theta = U(L)/T_{eff}` in [5, 200].
    max_M : int
        Largest Hermite degree, in [4, 60]; raised to ``M`` if that is larger.
    max_dofs : int
        Unknowns allowed to a level (>= 1000).
    max_seconds, max_gb : float or None
        Wall-time budget (s) and memory bound (GB), > 0.
    scheme : str
        ``"auto"`` or a name of :data:`~.schemes.SCHEMES` (checked by
        :func:`~.schemes.check_settings`).
    mesh : str
        x mesh of scheme ``"x"``.
    weight : Whitening or None
        Gaussian weight of scheme ``"x"`` (a :class:`~.schemes.x.discretize.Whitening`; typed
        ``Any`` here so that the settings, which every scheme reads, import no scheme; scheme
        ``"x"`` checks its type).
    """

    tol: float = 1e-4
    M: int | None = None
    elements: int | None = None
    order: int | None = None
    domain: float = 30.0
    max_M: int = 24
    max_dofs: int = 600_000
    max_seconds: float | None = None
    max_gb: float | None = None
    scheme: str = "auto"
    mesh: str = "auto"
    weight: Any = None

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731
        fix("tol", check_real("tol", self.tol, low=0.0, high=0.1, low_open=True))
        if self.M is not None:
            fix("M", check_int("M", self.M, low=2, high=60))
        if self.elements is not None:
            fix("elements", check_int("elements", self.elements, low=2, high=2048))
            if self.elements % 2:
                raise ParameterError(f"elements must be even (a node at x = 0), got {self.elements}")
        if self.order is not None:
            fix("order", check_int("order", self.order, low=2, high=5))
        fix("domain", check_real("domain (the domain factor)", self.domain, low=5.0, high=200.0))
        fix("max_M", max(check_int("max_M", self.max_M, low=4, high=60), self.M or 0))
        fix("max_dofs", check_int("max_dofs", self.max_dofs, low=1000))
        if self.max_seconds is not None:
            fix("max_seconds", check_real("max_seconds", self.max_seconds, low=0.0, low_open=True))
        if self.max_gb is not None:
            fix("max_gb", check_real("max_gb", self.max_gb, low=0.0, low_open=True))

    def given(self, name: str) -> bool:
        """True if the field ``name`` differs from its default (the caller set it)."""
        default: Any = next(f.default for f in dataclasses.fields(self) if f.name == name)
        return getattr(self, name) is not default and getattr(self, name) != default
