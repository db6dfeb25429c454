"""Exception hierarchy of fpe-harvester.

Every error raised on purpose by the library derives from :class:`HarvesterError`,
so a script can catch them all at once while still telling bad input
(:class:`ParameterError`, a :class:`ValueError`) from a numerical failure
(:class:`UnstableSystemError`, :class:`NotConvergedError`, both
:class:`RuntimeError`).
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

__all__ = [
    "HarvesterError",
    "ParameterError",
    "UnstableSystemError",
    "NotConvergedError",
    "MethodNotAvailableError",
    "check_real",
    "check_int",
    "check_choice",
]


class HarvesterError(Exception):
    """Base class of every error raised on purpose by fpe-harvester."""


class ParameterError(HarvesterError, ValueError):
    """An input value is outside its valid range or of the wrong type."""


class UnstableSystemError(HarvesterError, RuntimeError):
    """The system has no stationary state (some mode grows without bound)."""


class NotConvergedError(HarvesterError, RuntimeError):
    """A solver could not reach the requested accuracy."""


class MethodNotAvailableError(HarvesterError, ValueError):
    """The requested solver cannot handle this problem."""


def _describe(value: Any) -> str:
    return f"{value!r} (type {type(value).__name__})"


def check_real(
    name: str,
    value: Any,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``value`` as a float after checking type, finiteness and range.

    Parameters
    ----------
    name : str
        Parameter name used in the error message (e.g. ``"tau_p"``).
    value : Any
        The value to check. ``bool`` is rejected even though it is an ``int``.
    low, high : float, optional
        Bounds of the valid range; ``None`` means unbounded.
    low_open, high_open : bool
        Whether the corresponding bound is excluded.

    Raises
    ------
    ParameterError
        If ``value`` is not a finite real number inside the range.

    Examples
    --------
    >>> check_real("m", 2, low=0.0, low_open=True)
    2.0
    """
    lo = "(" if low_open or low is None else "["
    hi = ")" if high_open or high is None else "]"
    lo_txt = "-inf" if low is None else f"{low:g}"
    hi_txt = "inf" if high is None else f"{high:g}"
    rng = f"{lo}{lo_txt}, {hi_txt}{hi}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise ParameterError(f"{name} must be a real number in {rng}, got {_describe(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise ParameterError(f"{name} must be finite, in {rng}; got {_describe(value)}")
    bad_low = low is not None and (x <= low if low_open else x < low)
    bad_high = high is not None and (x >= high if high_open else x > high)
    if bad_low or bad_high:
        raise ParameterError(f"{name} must be in {rng}, got {_describe(value)}")
    return x


def check_int(name: str, value: Any, *, low: int | None = None, high: int | None = None) -> int:
    """Return ``value`` as an int after checking type and range (bounds included).

    Raises
    ------
    ParameterError
        If ``value`` is not an integer (floats with integral value are accepted) in range.
    """
    rng = f"[{'-inf' if low is None else low}, {'inf' if high is None else high}]"
    if isinstance(value, bool):
        raise ParameterError(f"{name} must be an integer in {rng}, got {_describe(value)}")
    if isinstance(value, Real) and not isinstance(value, int):
        if not math.isfinite(float(value)) or float(value) != int(value):
            raise ParameterError(f"{name} must be an integer in {rng}, got {_describe(value)}")
        value = int(value)
    if not isinstance(value, int):
        raise ParameterError(f"{name} must be an integer in {rng}, got {_describe(value)}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise ParameterError(f"{name} must be an integer in {rng}, got {_describe(value)}")
    return value


def check_choice(name: str, value: Any, choices: Any) -> Any:
    """Return ``value`` if it is one of ``choices``, else raise :class:`ParameterError`."""
    choices = tuple(choices)
    if value not in choices:
        valid = ", ".join(repr(c) for c in choices)
        raise ParameterError(f"{name} must be one of {valid}; got {_describe(value)}")
    return value
