"""The Fokker--Planck schemes (:class:`~fpe_harvester.fpe.protocol.Scheme`), one subpackage
each, and the registry :data:`SCHEMES` that :func:`~fpe_harvester.fpe.stationary.stationary`
resolves ``scheme=`` through. A new scheme is a new subpackage and one entry here."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...errors import ParameterError
from ...model import Harvester
from ..protocol import Scheme
from .x.scheme import XScheme
from .xv.scheme import XVScheme

if TYPE_CHECKING:
    from ..settings import Settings

__all__ = ["SCHEMES", "SCHEME_CHOICES", "check_settings", "resolve_scheme"]

#: The schemes by name.
SCHEMES: dict[str, Scheme] = {"x": XScheme(), "xv": XVScheme()}

#: The values ``scheme=`` accepts: ``"auto"`` and the names of the registered schemes.
SCHEME_CHOICES = ("auto", *SCHEMES)


def check_settings(settings: Settings) -> Settings:
    """``settings`` if its scheme is ``"auto"`` or a registered one and every scheme accepts
    its options (:meth:`~fpe_harvester.fpe.protocol.Scheme.check`), else ParameterError."""
    if settings.scheme not in SCHEME_CHOICES:
        raise ParameterError(f"scheme must be one of {', '.join(map(repr, SCHEME_CHOICES))}, "
                             f"got {settings.scheme!r} (type {type(settings.scheme).__name__})")
    for scheme in SCHEMES.values():
        scheme.check(settings)
    return settings


def resolve_scheme(h: Harvester, settings: Settings) -> Scheme:
    """The scheme that ``settings.scheme`` means for ``h`` (ParameterError if it cannot
    solve ``h`` or an option of another scheme is given).

    ``"auto"`` is the scheme of highest priority that solves ``h`` and prefers it
    (:meth:`~fpe_harvester.fpe.protocol.Scheme.preferred`): ``"xv"`` for 1 <= n < 2 (for
    1 < n < 2 only without an x-mesh setting), else ``"x"``.
    """
    check_settings(settings)
    if settings.scheme == "auto":
        ranked = sorted(SCHEMES.values(), key=lambda s: -s.priority)
        scheme = next(s for s in ranked if not s.refusal(h) and s.preferred(h, settings))
    else:
        scheme = SCHEMES[settings.scheme]
        why = scheme.refusal(h)
        if why:
            raise ParameterError(why)
    for other in SCHEMES.values():
        for name, what in other.options.items():
            if other is not scheme and name not in scheme.options and settings.given(name):
                raise ParameterError(f"{name} is {what} of scheme {other.name!r}; got scheme {scheme.name!r} "
                                     f"(n = {h.n:g})")
    return scheme
