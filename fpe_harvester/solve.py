"""One call for every solver: ``solve(harvester, method, **settings)``, and ``solve_many`` for many.

The solvers are chosen by object or by name from :data:`~fpe_harvester.solvers.METHODS`; what
each one takes is read from its declared :class:`~fpe_harvester.solvers.Capabilities`, never
from its name. The common settings (``tol``, ``seed``, ``max_time`` or ``max_seconds``,
``progress``) are accepted for every method: each solver uses those it has, and the result's
``info["ignored"]`` lists the others. ``method="auto"`` asks the solvers in the order of
:data:`~fpe_harvester.solvers.METHODS` whether they handle the system and the first that does
answers; where it stops short of its tolerance (status ``not_converged``) the next one that
handles the system runs within a time budget and :func:`fallback_result` keeps the better
numbers. That policy lives here only: the command line, the scenes and the optimizer call
:func:`solve`, :func:`solve_many` or :func:`choose_method`.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from .errors import MethodNotAvailableError, ParameterError, check_int, check_real
from .model import Harvester
from .result import QUANTITIES, Stats, Status
from .solvers import COMMON_SETTINGS, METHODS, Capabilities, Solver, option_names, solver_class, title

__all__ = ["Solver", "METHODS", "FALLBACK_SECONDS", "get_solver", "choose_method", "solve", "solve_many",
           "fallback_result", "relative_eta_error"]

#: Default wall-time budget (s) of the solver that takes over in ``solve(method="auto")`` where
#: the first one stops short of its tolerance.
FALLBACK_SECONDS = 60.0


def _split(settings: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The common settings (validated; ``None`` for tol, seed or max_time means "not given") and
    the solver-specific rest."""
    rest = dict(settings)
    if "max_seconds" in rest:
        alias = rest.pop("max_seconds")
        if rest.get("max_time", alias) != alias:
            raise ParameterError(f"max_time and max_seconds name one setting, the wall-time budget in seconds; "
                                 f"got max_time = {rest['max_time']!r} and max_seconds = {alias!r}")
        rest["max_time"] = alias
    common = {key: rest.pop(key) for key in COMMON_SETTINGS if key in rest}
    common = {key: value for key, value in common.items() if value is not None or key == "progress"}
    if "tol" in common:
        common["tol"] = check_real("tol", common["tol"], low=0.0, high=1.0, low_open=True, high_open=True)
    if "seed" in common:
        common["seed"] = check_int("seed", common["seed"], low=0)
    if "max_time" in common:
        common["max_time"] = check_real("max_time", common["max_time"], low=0.0, low_open=True)
    progress = common.get("progress")
    if not (progress is None or isinstance(progress, bool) or callable(progress)):
        raise ParameterError(f"progress must be True, False, None (a bar only on a terminal) or a callable, "
                             f"got {progress!r} (type {type(progress).__name__})")
    return common, rest


def _targets(cls: type) -> dict[str, str | None]:
    """Which setting of ``cls`` each common setting sets (None: it has no such setting)."""
    caps = cls.capabilities
    return {"tol": "tol" if caps.tol else None, "seed": "seed" if caps.seed else None,
            "max_time": caps.max_time, "progress": "progress" if caps.progress else None}


def _arguments(cls: type, common: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """Constructor arguments of ``cls`` from the common settings and its own options (which win),
    and the common settings it has no use for (``progress`` is not listed: it changes no number)."""
    args, ignored = dict(options), []
    progress_kind = cls.capabilities.progress
    for key, value in common.items():
        target = _targets(cls)[key]
        if target is None:
            if key != "progress":
                ignored.append(key)
        elif target not in args:
            if key == "progress" and value is None:
                # a bar only on a terminal (tqdm's rule): a solver drawing its own keeps its default
                # there, one reporting lines gets True (solve draws the bar)
                value = _terminal() if progress_kind == "lines" else (None if _terminal() else False)
            args[target] = value
    name = cls.name
    valid = option_names(cls)
    unknown = sorted(set(args) - set(valid))
    if unknown:
        raise ParameterError(
            f"invalid option for method {name!r}: no option {', '.join(map(repr, unknown))}; valid options: "
            + (", ".join(valid) if valid else "none") + f" (and the common settings {', '.join(COMMON_SETTINGS)})")
    return args, ignored


def _terminal() -> bool:
    return bool(getattr(sys.stderr, "isatty", lambda: False)())


def _build(method: str | Solver, common: Mapping[str, Any], options: Mapping[str, Any]) -> tuple[Solver, list[str]]:
    """The solver ``method`` (a name, or an object whose settings the common ones replace) and
    the common settings it ignores."""
    own_common, own = _split(options)  # a common setting given for this solver wins
    common = {**common, **own_common}
    if not isinstance(method, str):
        if own:
            raise ParameterError(
                f"solver options {sorted(own)} cannot be combined with a solver object; "
                "use dataclasses.replace on the object instead")
        args, ignored = _arguments(type(method), common, {})
        return (dataclasses.replace(method, **args) if args else method), ignored
    cls = solver_class(method)
    args, ignored = _arguments(cls, common, own)
    try:
        return cls(**args), ignored
    except TypeError as exc:
        raise ParameterError(f"invalid option for method {method!r}: {exc}") from exc


def _candidate(name: str, h: Harvester, common: Mapping[str, Any], options: Mapping[str, Any]) -> str | None:
    """Why solver ``name`` with these settings declines ``h`` (None: it handles it). A common
    setting outside its range is a reason to decline; an invalid option of its own is an error."""
    try:
        solver, _ = _build(name, common, options)
    except MethodNotAvailableError as exc:
        return str(exc)
    except ParameterError as exc:
        _build(name, {}, options)  # raises if its own options are at fault
        return str(exc)
    return solver.unsupported_reason(h)


def _choose(h: Harvester, common: Mapping[str, Any], options: Mapping[str, Mapping[str, Any]],
            extra: Mapping[str, Any], after: str | None = None,
            unusable: Callable[[Capabilities], str | None] | None = None) -> tuple[str, dict[str, str]]:
    """The first solver of :data:`~fpe_harvester.solvers.METHODS` (after ``after``; with
    ``unusable``, among those it finds no fault with) that handles ``h``, and the reasons of those
    that declined. ``extra`` options go to the solvers that have them all."""
    order = list(METHODS)  # read at each call: the registry is the one place that orders them
    order = order[order.index(after) + 1:] if after else order
    declined: dict[str, str] = {}
    for name in order:
        own = dict(options.get(name, {}))
        try:
            cls = solver_class(name)
        except MethodNotAvailableError as exc:
            declined[name] = str(exc)
            continue
        fault = None if unusable is None else unusable(cls.capabilities)
        if fault:
            declined[name] = fault
            continue
        fits = set(extra) <= set(option_names(cls))
        reason = _candidate(name, h, common, {**own, **extra} if fits else own)
        if reason is None:
            return name, declined
        declined[name] = reason
    raise MethodNotAvailableError("no solver handles this system with these settings: "
                                  + "; ".join(f"{title(n)}: {r}" for n, r in declined.items()))


def _solver_options(solver_options: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, Any]]:
    if solver_options is None:
        return {}
    if not isinstance(solver_options, Mapping):
        raise ParameterError(f"solver_options must map method names to settings, got {solver_options!r}")
    out = {}
    for name, opts in solver_options.items():
        solver_class(name)  # a known method
        if not isinstance(opts, Mapping):
            raise ParameterError(f"solver_options[{name!r}] must be a mapping of settings, got {opts!r}")
        out[name] = dict(opts)
    return out


def get_solver(method: str | Solver = "auto", h: Harvester | None = None, **settings: Any) -> Solver:
    """Build a solver from a name (``"auto"`` needs ``h``: :func:`choose_method`) and its settings,
    or pass one through with the common settings applied. Common settings the solver has no use
    for are dropped (:func:`solve` lists them in ``info["ignored"]``).

    Raises
    ------
    ParameterError
        Unknown method, an option the solver does not have, or an invalid value.
    """
    common, extra = _split(settings)
    if method == "auto":
        if h is None:
            raise ParameterError("method='auto' needs the harvester to choose a solver")
        method = _choose(h, common, {}, extra)[0]
    return _build(method, common, extra)[0]


def choose_method(h: Harvester, solver_options: Mapping[str, Mapping[str, Any]] | None = None,
                  unusable: Callable[[Capabilities], str | None] | None = None, **settings: Any) -> str:
    """The name of the solver ``method="auto"`` picks for ``h``: the first of
    :data:`~fpe_harvester.solvers.METHODS` whose ``unsupported_reason(h)`` is None with these
    settings (harmonic: exact; one nonlinear unit: Fokker--Planck, where it declares it can
    answer; anything else: Monte Carlo). ``solver_options`` and ``settings`` are those of
    :func:`solve` (a solver's settings can decide whether it handles ``h``); ``unusable``, given
    a solver's capabilities, says why the caller cannot use it at all, or None (the optimizer
    needs an objective exact to round-off or one with common random numbers).

    Raises
    ------
    MethodNotAvailableError
        No solver handles ``h`` (the message gives each one's reason).
    """
    common, extra = _split(settings)
    return _choose(h, common, _solver_options(solver_options), extra, unusable=unusable)[0]


def solve(h: Harvester, method: str | Solver = "auto", *, fallback_time: float | None = FALLBACK_SECONDS,
          solver_options: Mapping[str, Mapping[str, Any]] | None = None, **settings: Any) -> Stats:
    """Stationary statistics of a harvester.

    Parameters
    ----------
    h : Harvester
        The problem: potential, ring size, coupling and parameters.
    method : {"auto", "exact", "fpe", "mc"} or solver object
        ``"auto"`` asks the solvers, cheapest first (exact, Fokker--Planck, Monte Carlo), whether
        they handle ``h`` (their ``unsupported_reason``) and the first that does answers;
        ``info["auto"]`` and the message say which it chose and which declined, and why.
    fallback_time : float or None
        ``"auto"`` only: where the answering solver stops short of its tolerance (status
        ``not_converged``), the next one that handles ``h`` runs for at most this many seconds
        (wall time, >= 0; default :data:`FALLBACK_SECONDS`) with the same settings, and the
        better result is returned (see :func:`fallback_result`). ``None`` or 0: no fallback. A
        method chosen by name never falls back.
    solver_options : mapping of method name to mapping, optional
        Settings for a solver by name, used when that solver runs (``"auto"``'s choice or its
        fallback), e.g. ``{"mc": {"dt": 0.01}}``; they take precedence over ``settings``.
    **settings
        The common settings, accepted for every method: ``tol`` (relative error on eta, in
        (0, 1); each solver checks its own range), ``seed`` (int >= 0), ``max_time`` or its
        other name ``max_seconds`` (wall-time budget, s), ``progress`` (True, False, or None: a
        progress bar on stderr only when it is a terminal; a solver reporting its steps in lines
        gets a bar whose last line is the value it reports). A solver without one ignores it and
        ``info["ignored"]`` lists it (``progress`` aside). Any other keyword is a setting of the solver chosen
        (e.g. ``M=8`` for ``"fpe"``, ``dt=0.01`` for ``"mc"``).

    Returns
    -------
    Stats
        Values with errors and a status; an unstable system is reported, not raised
        (call :meth:`Stats.raise_for_status` to turn that into an exception). ``harvester``
        is ``h``. After a fallback, ``method`` names the solver whose numbers these are and
        ``info["fallback"]`` holds the numbers of the other.

    Raises
    ------
    ParameterError
        Unknown method, invalid setting or negative ``fallback_time``.
    MethodNotAvailableError
        The solver named cannot handle this problem (e.g. ``"exact"`` with n != 2), or no
        solver can (``"auto"``).

    Examples
    --------
    >>> [solve(Harvester.build(a=0.5, n=2), tol=1e-3).info["ignored"]]
    [['tol']]
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    if fallback_time is not None:
        fallback_time = check_real("fallback_time", fallback_time, low=0.0)
    common, extra = _split(settings)
    # a solver built here draws a progress bar only on a terminal, unless told otherwise
    common = {"progress": None, **common} if isinstance(method, str) else common
    options = _solver_options(solver_options)
    name, solver, ignored, declined = _answerer(h, method, common, extra, options)
    res = _annotate(_run(solver, h), h, ignored)
    if method != "auto":
        return res
    if fallback_time and res.status is Status.NOT_CONVERGED:
        res = _fallback(h, res, name, common, options, fallback_time)
    return _chosen(res, name, declined)


def _answerer(h: Harvester, method: str | Solver, common: Mapping[str, Any], extra: Mapping[str, Any],
              options: Mapping[str, Mapping[str, Any]]) -> tuple[str, Solver, list[str], dict[str, str]]:
    """The solver that answers for ``h``: its name, the object, the common settings it ignores
    and (``"auto"``) the reasons of the solvers that declined before it.

    Raises
    ------
    MethodNotAvailableError
        The solver cannot handle ``h``.
    """
    declined: dict[str, str] = {}
    if method == "auto":
        name, declined = _choose(h, common, options, extra)
    else:
        name = method if isinstance(method, str) else method.name
    solver, ignored = _build(method if not isinstance(method, str) else name, common,
                             {**options.get(name, {}), **extra})
    reason = solver.unsupported_reason(h)
    if reason:
        raise MethodNotAvailableError(reason)
    return name, solver, ignored, declined


#: Seconds a solve runs before its progress bar appears (quick solves draw none).
BAR_DELAY = 1.0


def _run(solver: Solver, h: Harvester) -> Stats:
    """``solver.solve(h)``; a solver that reports progress in lines, asked for a bar, gets one on
    stderr whose last line is the value it reports."""
    if solver.capabilities.progress != "lines" or solver.progress is not True:
        return solver.solve(h)
    from tqdm import tqdm

    where = f" N={h.N}" if h.N > 1 else ""
    with tqdm(desc=f"{solver.name} n={h.n:g} a={h.a:g}{where}", unit="step", file=sys.stderr,
              delay=BAR_DELAY) as bar:
        def line(text: str) -> None:
            bar.set_postfix_str(text[:70], refresh=False)
            bar.update(1)

        res = dataclasses.replace(solver, progress=line).solve(h)
        bar.set_postfix_str(_reported(res))
    return res


def _reported(res: Stats) -> str:
    """The value a result reports, for the last line of its progress bar."""
    if res.eta is None:
        return f"no result ({res.status.value})"
    err = "" if res.eta_err is None else f" +- {res.eta_err:.2g}"
    return f"reported eta = {res.eta:.6g}{err} ({res.status.value})"


def _annotate(res: Stats, h: Harvester, ignored: Sequence[str]) -> Stats:
    """``res`` with its harvester and the ignored common settings in ``info["ignored"]``."""
    info = dict(res.info)
    if ignored:
        info["ignored"] = sorted(ignored)
    return dataclasses.replace(res, harvester=h, info=info)


def _chosen(res: Stats, name: str, declined: Mapping[str, str]) -> Stats:
    """A result of ``method="auto"``: which solver it chose (``name``) and which declined before
    it, and why, in ``info["auto"]`` and, when some declined, in the message."""
    info = {**res.info, "auto": {"chosen": name, "declined": dict(declined)}}
    message = res.message
    if declined:
        # the reason's first clause says why; the advice after it (which method to use) is moot
        why = ", ".join(f"{title(n)} ({_first_clause(reason)})" for n, reason in declined.items())
        note = f"method auto chose {title(name)}; declined: {why}"
        message = f"{message}; {note}" if message else note
    return dataclasses.replace(res, info=info, message=message)


def _first_clause(reason: str) -> str:
    """``reason`` up to its first ``"; "`` or ``". "`` outside parentheses (a clause whose own
    parenthesis holds a semicolon stays whole)."""
    depth = 0
    for i, char in enumerate(reason):
        depth += {"(": 1, ")": -1}.get(char, 0)
        if depth == 0 and char in ";." and reason[i + 1:i + 2] == " ":
            return reason[:i]
    return reason


def _fallback(h: Harvester, first: Stats, name: str, common: Mapping[str, Any],
              options: Mapping[str, Mapping[str, Any]], seconds: float) -> Stats:
    """The next solver after ``name`` that handles ``h``, within ``seconds`` (wall time) and the
    same settings, merged with ``first`` by :func:`fallback_result`; ``progress`` False (the
    caller's) silences its bar too. Without one, ``first`` is returned with a note."""
    if name == list(METHODS)[-1]:
        return first
    quiet = {**common, "progress": False if common.get("progress") is False else None}
    try:
        second_name, _ = _choose(h, quiet, options, {}, after=name)
    except MethodNotAvailableError as exc:
        return dataclasses.replace(first, message=f"{first.message}; no fallback ({exc})")
    own = dict(options.get(second_name, {}))
    # the budget of the solver that takes over, unless its own settings give one
    budget = {} if "max_time" in _split(own)[0] else {"max_time": seconds}
    solver, ignored = _build(second_name, {**quiet, **budget}, own)
    return fallback_result(first, _annotate(_run(solver, h), h, ignored))


def solve_many(hs: Sequence[Harvester], method: str | Solver = "auto", *,
               fallback_time: float | None = FALLBACK_SECONDS,
               solver_options: Mapping[str, Mapping[str, Any]] | None = None,
               on_result: Callable[[int, Stats], None] | None = None, **settings: Any) -> list[Stats]:
    """:func:`solve` for each harvester of ``hs``, in order; the points of a solver that declares
    ``solve_many`` (the exact one) are computed together in one vectorized call per solver.

    Every point is checked (its solver chosen and asked whether it handles it) before the first
    is computed. ``on_result(index, stats)`` is called as each result is ready (a progress bar,
    a log); the other parameters are those of :func:`solve`.

    Raises
    ------
    ParameterError, MethodNotAvailableError
        As :func:`solve`, for the first point at fault, before anything is computed.
    """
    hs = list(hs)
    for h in hs:
        if not isinstance(h, Harvester):
            raise ParameterError(f"every point must be a Harvester, got {h!r} (type {type(h).__name__})")
    common, extra = _split(settings)
    common = {"progress": None, **common} if isinstance(method, str) else common
    options = _solver_options(solver_options)
    out: list[Stats | None] = [None] * len(hs)
    groups: dict[int, tuple[Solver, list[str], list[tuple[int, dict[str, str]]]]] = {}
    for i, h in enumerate(hs):
        name, solver, ignored, declined = _answerer(h, method, common, extra, options)
        if solver.capabilities.solve_many:
            # one call per solver object (equal settings compare equal)
            key = next((k for k, g in groups.items() if g[0] == solver), len(groups))
            groups.setdefault(key, (solver, ignored, []))[2].append((i, declined))
    for solver, ignored, members in groups.values():
        for (i, declined), res in zip(members, solver.solve_many([hs[i] for i, _ in members])):
            out[i] = _annotate(res, hs[i], ignored)
            if method == "auto":
                out[i] = _chosen(out[i], solver.name, declined)
            if on_result is not None:
                on_result(i, out[i])
    for i, h in enumerate(hs):
        if out[i] is None:
            out[i] = solve(h, method, fallback_time=fallback_time, solver_options=options, **common, **extra)
            if on_result is not None:
                on_result(i, out[i])
    return [r for r in out if r is not None]


def fallback_result(first: Stats, second: Stats) -> Stats:
    """The result to report after ``first`` (not converged) was retried with ``second`` (the next
    solver of ``method="auto"``).

    ``second`` replaces ``first`` when it describes a stationary state (stable or marginal),
    or when ``first`` has no numbers; otherwise the one with the smaller relative error on
    eta is kept. The message says which solver gave the numbers and why; ``info["fallback"]``
    names that solver (``"kept"``) and holds the other one's method, status, message and
    numbers, each quantity with its error, None where it gave none (``"other"``), so that
    the two can be compared.

    Parameters
    ----------
    first, second : Stats
        The first solver's result (status ``not_converged``) and the fallback's.

    Returns
    -------
    Stats
        ``second`` or ``first``, with the message and ``info`` extended.
    """
    one, two = title(first.method), title(second.method)
    if first.eta is None:
        note = f"{one} gave no result ({first.message}); {two} used instead"
    elif second.ok or relative_eta_error(second) < relative_eta_error(first):
        err = "no error estimate" if first.eta_err is None else f"+- {first.eta_err:.2g}"
        note = (f"{one} did not reach the tolerance (eta = {first.eta:.6g} {err}: "
                f"{first.message}); {two} used instead")
    else:
        info = {**first.info, "fallback": _fallback_info(first, second)}
        return dataclasses.replace(first, message=f"{first.message}; {two} did no better ({second.message})",
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
