"""One result type for all three solvers: stationary statistics with errors and a status."""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Any

from .errors import NotConvergedError, ParameterError, UnstableSystemError
from .model import Harvester
from .wide import LARGEST, Wide

__all__ = ["QUANTITIES", "Stats", "Status", "parameters", "harvester_from_dict", "to_frame",
           "propagated_eta_error", "jsonable"]

#: Names of the stationary observables every solver reports, each with its error ``<name>_err``
#: (the one list of them: scenes, the point cache and the command line use it too).
QUANTITIES = ("eta", "V2", "Vrms", "Pin", "v2", "vV", "x2", "d2")


class Status(str, enum.Enum):
    """Outcome of a solve."""

    STABLE = "stable"
    """A stationary state exists and the numbers describe it."""
    MARGINAL = "marginal"
    """At a stability threshold: x of the critical mode diffuses; V statistics are finite limits."""
    UNSTABLE = "unstable"
    """No stationary state; ``growth_rate`` says how fast the critical mode grows."""
    METASTABLE = "metastable"
    """Long-lived state that eventually escapes (nonlinear ring with n < 2, k < 0)."""
    NOT_CONVERGED = "not_converged"
    """Requested accuracy not reached; numbers are the best estimate with their error."""



@dataclass(frozen=True)
class Stats:
    """Stationary statistics of a harvester, each paired with its error.

    Attributes
    ----------
    V2 : float or None
        Mean squared load voltage :math:`\\langle V^2\\rangle` (ring: averaged over units).
    Pin : float or None
        Injected mechanical power :math:`P_{in} = \\sigma\\langle v\\xi\\rangle`.
    eta : float or None
        Efficiency :math:`\\eta = \\langle V^2\\rangle / (R P_{in})`.
    Vrms : float or None
        :math:`\\sqrt{\\langle V^2\\rangle}`.
    v2, vV, x2 : float or None
        :math:`\\langle v^2\\rangle`, :math:`\\langle vV\\rangle`, :math:`\\langle x^2\\rangle`
        where the method provides them (``x2`` is ``None`` at a marginal point, where it diverges).
    d2 : float or None
        Mean squared bond of a ring, :math:`\\langle (x_{j+1} - x_j)^2\\rangle` (averaged over
        bonds); ``None`` for a single unit, at a marginal point, or where the method does not
        provide it.
    *_err : float or None
        Error estimate of each quantity (one standard error for Monte Carlo, truncation and
        mesh error for Fokker--Planck, 0 for exact). ``None`` when the value is ``None``.
    status : Status
        Stable, marginal, unstable, metastable or not converged.
    message : str
        What the status means for this problem and what to do about it.
    method : str
        Which solver produced the numbers (``"exact"``, ``"fpe"``, ``"mc"``).
    growth_rate : float or None
        Largest real part of the drift spectrum (> 0 when unstable), where known.
    info : Mapping
        Solver-specific details (time step, paths, degree M, mesh size, timings, ...);
        :func:`~fpe_harvester.solve.solve` adds ``"ignored"`` (the common settings the solver
        had no use for) and, for ``method="auto"``, ``"auto"`` (which solvers declined, and why).
    harvester : Harvester or None
        The system these numbers are for (set by :func:`~fpe_harvester.solve.solve`).

    Numbers are never NaN or inf: what cannot be computed is ``None`` and the status says why.
    """

    V2: float | None = None
    Pin: float | None = None
    eta: float | None = None
    Vrms: float | None = None
    v2: float | None = None
    vV: float | None = None
    x2: float | None = None
    d2: float | None = None
    V2_err: float | None = None
    Pin_err: float | None = None
    eta_err: float | None = None
    Vrms_err: float | None = None
    v2_err: float | None = None
    vV_err: float | None = None
    x2_err: float | None = None
    d2_err: float | None = None
    status: Status = Status.STABLE
    message: str = ""
    method: str = ""
    growth_rate: float | None = None
    info: Mapping[str, Any] = field(default_factory=dict)
    harvester: Harvester | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", Status(self.status))
        if self.harvester is not None and not isinstance(self.harvester, Harvester):
            raise ParameterError(f"harvester must be a Harvester or None, got {self.harvester!r} "
                                 f"(type {type(self.harvester).__name__})")
        for name in QUANTITIES:
            for key in (name, name + "_err"):
                value = getattr(self, key)
                if value is None:
                    continue
                value = float(value)
                if not math.isfinite(value):
                    raise ValueError(
                        f"internal error: {self.method or 'solver'} produced {key} = {value}; "
                        "non-finite numbers must be reported through the status"
                    )
                object.__setattr__(self, key, value)
        if self.growth_rate is not None:
            rate = float(self.growth_rate)
            if not math.isfinite(rate):
                raise ValueError(f"internal error: {self.method or 'solver'} produced growth_rate = {rate}; "
                                 "a rate beyond the double range must be None")
            object.__setattr__(self, "growth_rate", rate)
        object.__setattr__(self, "info", MappingProxyType(dict(self.info)))

    @classmethod
    def from_moments(
        cls,
        *,
        V2: float,
        Pin: float,
        R: float,
        V2_err: float = 0.0,
        Pin_err: float = 0.0,
        cov_V2_Pin: float = 0.0,
        eta_err: float | None = None,
        Vrms_err: float | None = None,
        **kwargs: Any,
    ) -> Stats:
        """Build from :math:`\\langle V^2\\rangle` and :math:`P_{in}`, deriving eta and Vrms.

        Errors are propagated to first order (:func:`propagated_eta_error`); ``cov_V2_Pin`` is
        the covariance of the two estimates (Monte Carlo replicas give it; it reduces the error
        on eta). A solver with its own estimate of eta's error (from a refinement sequence of
        eta itself, or including a time-step bias of eta) passes it as ``eta_err`` instead, and
        one whose error on :math:`\\sqrt{V^2}` includes more than the propagated part (the
        rounding of the square root, for exact numbers) passes ``Vrms_err``.
        The derived numbers are computed without intermediate overflow
        (:class:`~fpe_harvester.wide.Wide`), so they are the float results wherever those exist.

        Raises
        ------
        ParameterError
            ``V2`` is negative or not finite, ``Pin`` is 0 or not finite, or ``eta``, ``Vrms``
            or one of their errors falls outside the double range (the message gives its size).
        """
        where = kwargs.get("method") or "solver"
        if not (math.isfinite(V2) and V2 >= 0.0 and math.isfinite(Pin) and Pin != 0.0):
            raise ParameterError(f"{where}: eta = V2/(R Pin) needs a finite V2 >= 0 and a finite Pin != 0, "
                                 f"got V2 = {V2!r}, Pin = {Pin!r}")
        eta_w = Wide.of(V2) / (Wide.of(R) * Wide.of(Pin))
        eta = _float_or_refuse(where, "eta = V2/(R Pin)", eta_w)
        if eta_err is None:
            if V2 == 0.0:
                eta_err = _float_or_refuse(where, "eta_err", Wide.of(V2_err) / abs(Wide.of(R) * Wide.of(Pin)))
            else:
                eta_err = propagated_eta_error(eta, V2, V2_err, Pin, Pin_err, cov_V2_Pin)
        Vrms = math.sqrt(V2)
        if Vrms_err is not None:
            pass
        elif Vrms > 0.0:
            Vrms_err = _float_or_refuse(where, "Vrms_err", 0.5 * Wide.of(V2_err) / Wide.of(Vrms))
        else:
            Vrms_err = math.sqrt(V2_err)
        return cls(
            V2=V2, V2_err=V2_err, Pin=Pin, Pin_err=Pin_err, eta=eta, eta_err=eta_err,
            Vrms=Vrms, Vrms_err=Vrms_err, **kwargs,
        )

    @property
    def ok(self) -> bool:
        """True when the numbers describe a stationary state (stable or marginal)."""
        return self.status in (Status.STABLE, Status.MARGINAL)

    def value(self, name: str) -> tuple[float | None, float | None]:
        """``(value, error)`` of an observable by name (one of :data:`QUANTITIES`)."""
        if name not in QUANTITIES:
            raise KeyError(f"unknown observable {name!r}; valid: {', '.join(QUANTITIES)}")
        return getattr(self, name), getattr(self, name + "_err")

    def raise_for_status(self) -> Stats:
        """Return self if stable or marginal (the numbers describe a stationary state), else raise.

        Raises
        ------
        UnstableSystemError
            Status unstable (no stationary state) or metastable (paths eventually escape).
        NotConvergedError
            Status not converged (the numbers, if any, miss the requested accuracy).
        """
        if self.status in (Status.UNSTABLE, Status.METASTABLE):
            raise UnstableSystemError(self.message or f"the system is {self.status.value}: no stationary state")
        if self.status is Status.NOT_CONVERGED:
            raise NotConvergedError(self.message or "the requested accuracy was not reached")
        return self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: each quantity and ``<name>_err`` (``None`` where it does not exist),
        ``status``, ``message``, ``method``, ``growth_rate``, ``info`` and, when known, the
        system as ``harvester`` (:meth:`Harvester.to_dict`: ``a, n, N, k``, the nonzero ``k4``
        and ``k3``, and ``params``)."""
        out: dict[str, Any] = {}
        for f in fields(self):  # declaration order: V2, Pin, eta, Vrms, ...
            if f.name in QUANTITIES:
                out[f.name] = getattr(self, f.name)
                out[f.name + "_err"] = getattr(self, f.name + "_err")
        out.update(
            status=self.status.value,
            message=self.message,
            method=self.method,
            growth_rate=self.growth_rate,
            info=jsonable(dict(self.info)),
        )
        if self.harvester is not None:
            out["harvester"] = self.harvester.to_dict()
        return out

    def to_record(self) -> dict[str, Any]:
        """One flat row: the system's parameters (:func:`parameters`, when known), each quantity
        and its error, ``status``, ``method`` and ``message``; what a table of results holds."""
        out: dict[str, Any] = {} if self.harvester is None else parameters(self.harvester)
        for name in QUANTITIES:
            out[name], out[name + "_err"] = self.value(name)
        out.update(status=self.status.value, method=self.method, message=self.message)
        return out

    def to_frame(self) -> Any:
        """:meth:`to_record` as a one-row ``pandas.DataFrame`` (needs pandas: ``pip install
        "fpe-harvester[pandas]"``); missing values are NaN there."""
        return to_frame([self.to_record()])


def parameters(h: Harvester) -> dict[str, Any]:
    """Every parameter of ``h`` in one flat dict: ``a, n, N, k, k4, k3`` and the
    :class:`~fpe_harvester.model.Params` fields (``m, gamma, Kv, Kc, sigma, tau, D, tau_p, R``).

    Examples
    --------
    >>> list(parameters(Harvester.build(a=0.5, n=3)))[:6]
    ['a', 'n', 'N', 'k', 'k4', 'k3']
    """
    return {"a": h.a, "n": h.n, "N": h.N, "k": h.k, "k4": h.k4, "k3": h.k3, **h.params.to_dict()}


def harvester_from_dict(d: Mapping[str, Any]) -> Harvester:
    """Inverse of :meth:`Harvester.to_dict` (also accepts the flat form of :func:`parameters`).

    Raises
    ------
    ParameterError
        A value out of range or a key that is not a parameter.
    """
    flat = {key: value for key, value in d.items() if key != "params"}
    try:
        return Harvester.build(**flat, **dict(d.get("params", {})))
    except TypeError as exc:
        raise ParameterError(f"not a harvester description ({exc}): {dict(d)!r}") from None


def to_frame(records: list[dict[str, Any]]) -> Any:
    """A ``pandas.DataFrame`` with one row per record (flat dicts; ``None`` becomes NaN in
    numeric columns).

    Raises
    ------
    ImportError
        pandas is not installed (it is the optional extra ``pandas``).
    """
    try:
        import pandas as pd
    except ImportError as exc:
        raise ImportError('to_frame() needs pandas, an optional dependency: pip install "fpe-harvester[pandas]" '
                          f"(or pip install pandas); it failed with: {exc}") from exc
    return pd.DataFrame.from_records(records)


def propagated_eta_error(eta: float, V2: float, V2_err: float, Pin: float, Pin_err: float,
                         cov_V2_Pin: float = 0.0) -> float:
    """First-order error of :math:`\\eta \\propto V^2/P_{in}` from the errors of its two factors.

    .. math::

        \\left(\\frac{\\delta\\eta}{\\eta}\\right)^2 = \\left(\\frac{\\delta V^2}{V^2}\\right)^2
        + \\left(\\frac{\\delta P}{P}\\right)^2 - \\frac{2\\,\\mathrm{cov}}{V^2 P}

    Evaluated without intermediate overflow or underflow (:class:`~fpe_harvester.wide.Wide`),
    with the float result wherever that exists.

    Raises
    ------
    ParameterError
        ``V2`` or ``Pin`` is 0 (the relative errors do not exist), or the error is beyond the
        double range.

    Examples
    --------
    >>> round(propagated_eta_error(0.5, 1.0, 0.03, 2.0, 0.08), 12)
    0.025
    """
    if V2 == 0.0 or Pin == 0.0:
        raise ParameterError(f"relative errors need V2 != 0 and Pin != 0, got V2 = {V2!r}, Pin = {Pin!r}")
    V2w, Pw = Wide.of(V2), Wide.of(Pin)
    rel2 = (Wide.of(V2_err) / V2w) ** 2 + (Wide.of(Pin_err) / Pw) ** 2 - 2.0 * Wide.of(cov_V2_Pin) / (V2w * Pw)
    rel = rel2.sqrt() if rel2.sign() > 0 else Wide.of(0.0)
    return _float_or_refuse("propagated_eta_error", "eta_err", abs(Wide.of(eta)) * rel)


def _float_or_refuse(where: str, what: str, value: Wide) -> float:
    """``value`` as a float, or a :class:`ParameterError` saying it is beyond the double range."""
    x = float(value.to_float())
    if not math.isfinite(x):
        raise ParameterError(f"{where}: {what} ~ 10^{float(value.log10()):.1f} exceeds the largest double "
                             f"({LARGEST:.3g}); rescale the problem (docs/model.md §5)")
    return x


def jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and nested containers to JSON-ready Python objects."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if hasattr(obj, "tolist"):
        return jsonable(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, enum.Enum):
        return obj.value
    return obj
