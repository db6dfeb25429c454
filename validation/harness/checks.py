"""Pass/fail checks with tolerances built from the reported errors.

A check compares two numbers that carry error estimates. It passes when

.. math::

    |a - b| \\le n_\\sigma \\sqrt{\\delta_a^2 + \\delta_b^2} + f_{abs} + f_{rel}\\,|b|

where :math:`\\delta_a, \\delta_b` are the errors the solvers report (one standard error for
Monte Carlo, truncation/mesh error for Fokker--Planck, 0 for exact), :math:`n_\\sigma` is the
number of error bars allowed (4 by default) and the floors cover what the errors do not
(round-off for exact numbers). The tolerance is stated in every result, so a reader can
see what was promised and what was delivered.

Outcomes say what was checked: PASS only for a comparison computed in this run; RECORDED for
one whose verdict reads committed data only (it names the file and the command that writes it
again, and is counted apart: it holds for that data, not for this run's code); FINDING for a
disagreement with a published value that a second, independent solver confirms (not a failure
of ours, not a pass either); SKIP for a check that compared nothing (a solver not installed, no
number to compare); FAIL for a comparison that failed or a check that raised.
"""

from __future__ import annotations

import enum
import math
import os
import signal
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from fpe_harvester.errors import MethodNotAvailableError, check_real
from fpe_harvester.model import Harvester
from fpe_harvester.result import Stats
from fpe_harvester.solve import get_solver, solve

__all__ = [
    "Outcome",
    "CheckResult",
    "agree",
    "expect",
    "recorded",
    "skipped",
    "failed",
    "finding",
    "guarded",
    "SolveCache",
    "solver_available",
    "CheckTimeout",
    "Context",
]


class Outcome(str, enum.Enum):
    """Result of one check.

    PASS: ours, computed in this run, agrees with what it was held to. RECORDED: the verdict
    reads committed data only (the file and the command that writes it again are named); it
    holds for that data, and is counted apart from the passes. FINDING: a published value
    disagrees with ours and a second, independent solver confirms ours (the run still succeeds).
    FAIL: ours is wrong, or the check raised. SKIP: nothing was compared.
    """

    PASS = "PASS"
    RECORDED = "RECORDED"
    FINDING = "FINDING"
    FAIL = "FAIL"
    SKIP = "SKIP"


@dataclass(frozen=True)
class CheckResult:
    """One pass/recorded/finding/fail/skip verdict with the numbers behind it.

    Attributes
    ----------
    name : str
        What was checked (e.g. ``"exact vs mc: N = 3, k = -0.2, eta"``).
    section : str
        Report section the check belongs to.
    outcome : Outcome
        PASS, FINDING, FAIL or SKIP.
    detail : str
        The comparison in words: values, errors, tolerance, or why it was skipped.
    value, reference : float or None
        The two numbers compared (``None`` for checks that are not a comparison).
    diff, tolerance : float or None
        :math:`|a - b|` and the tolerance it was held to.
    seconds : float
        Wall time spent on the check, >= 0.
    source, command : str
        A RECORDED check's committed data file and the command that writes it again ("" else).
    """

    name: str
    section: str
    outcome: Outcome
    detail: str = ""
    value: float | None = None
    reference: float | None = None
    diff: float | None = None
    tolerance: float | None = None
    seconds: float = 0.0
    source: str = ""
    command: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "outcome", Outcome(self.outcome))
        check_real("seconds", self.seconds, low=0.0)

    @property
    def passed(self) -> bool:
        return self.outcome is Outcome.PASS

    def to_dict(self) -> dict[str, Any]:
        return {f.name: (getattr(self, f.name).value if f.name == "outcome" else getattr(self, f.name))
                for f in fields(self)}


def _finite(x: float | None) -> bool:
    return x is not None and math.isfinite(float(x))


def agree(
    name: str,
    section: str,
    a: float | None,
    err_a: float | None,
    b: float | None,
    err_b: float | None,
    *,
    n_sigma: float = 4.0,
    floor: float = 0.0,
    rel_floor: float = 0.0,
    max_rel_tol: float | None = None,
    note: str = "",
) -> CheckResult:
    """Compare ``a +- err_a`` with ``b +- err_b``.

    Parameters
    ----------
    name, section : str
        Label and report section.
    a, b : float or None
        The two values; ``None`` or non-finite fails the check (a solver that could not
        produce a number where one was expected).
    err_a, err_b : float or None
        Their error estimates, >= 0 (``None`` counts as 0 and is said so in the detail).
    n_sigma : float
        Error bars allowed, > 0 (default 4).
    floor, rel_floor : float
        Absolute and relative (to ``|b|``) floors added to the tolerance, >= 0.
    max_rel_tol : float, optional
        Cap on the tolerance relative to ``|b|``, > 0: a comparison whose error bars allow more
        cannot tell right from wrong, so it fails whatever the difference (e.g. a result that
        did not converge and reports a 100 % error).
    note : str
        Extra context appended to the detail.

    Returns
    -------
    CheckResult
        PASS iff :math:`|a-b| \\le n_\\sigma\\sqrt{\\delta_a^2+\\delta_b^2} + f + f_{rel}|b|` (and that
        tolerance is within ``max_rel_tol * |b|``).

    Examples
    --------
    >>> agree("x", "s", 1.0, 0.1, 1.3, 0.0).outcome.value
    'PASS'
    >>> agree("x", "s", 1.0, 0.01, 1.3, 0.0).outcome.value
    'FAIL'
    >>> agree("x", "s", 1.0, 0.1, 1.3, 0.0, max_rel_tol=0.05).outcome.value
    'FAIL'
    """
    n_sigma = check_real("n_sigma", n_sigma, low=0.0, low_open=True)
    floor = check_real("floor", floor, low=0.0)
    rel_floor = check_real("rel_floor", rel_floor, low=0.0)
    suffix = f"; {note}" if note else ""
    if not (_finite(a) and _finite(b)):
        return CheckResult(name, section, Outcome.FAIL, f"no finite value to compare: a = {a}, b = {b}{suffix}",
                           value=a, reference=b)
    missing = [lbl for lbl, e in (("a", err_a), ("b", err_b)) if e is None]
    ea = 0.0 if err_a is None else abs(float(err_a))
    eb = 0.0 if err_b is None else abs(float(err_b))
    if not (math.isfinite(ea) and math.isfinite(eb)):
        return CheckResult(name, section, Outcome.FAIL, f"non-finite error estimate ({err_a}, {err_b}){suffix}",
                           value=a, reference=b)
    diff = abs(float(a) - float(b))
    tol = n_sigma * math.hypot(ea, eb) + floor + rel_floor * abs(float(b))
    capped = max_rel_tol is not None and tol > check_real("max_rel_tol", max_rel_tol, low=0.0,
                                                          low_open=True) * abs(float(b))
    ok = diff <= tol and not capped
    detail = (
        f"{a:.8g} +- {ea:.2g} vs {b:.8g} +- {eb:.2g}: |diff| = {diff:.3g} "
        f"{'<=' if diff <= tol else '>'} tol = {n_sigma:g}*sqrt(err_a^2+err_b^2)"
        f"{f' + {floor:.1g}' if floor else ''}{f' + {rel_floor:.1g}*|b|' if rel_floor else ''} = {tol:.3g}"
    )
    if capped:
        detail += (f"; FAIL: the tolerance exceeds the cap {max_rel_tol:g}*|b| = {max_rel_tol * abs(float(b)):.3g}, "
                   "so these error bars cannot tell right from wrong")
    if missing:
        detail += f" (no error reported for {', '.join(missing)}: taken as 0)"
    return CheckResult(name, section, Outcome.PASS if ok else Outcome.FAIL, detail + suffix,
                       value=float(a), reference=float(b), diff=diff, tolerance=tol)


def expect(name: str, section: str, condition: bool, detail: str) -> CheckResult:
    """A yes/no check computed in this run (e.g. "status is unstable and growth rate > 0")."""
    return CheckResult(name, section, Outcome.PASS if condition else Outcome.FAIL, detail)


def recorded(name: str, section: str, condition: bool, detail: str, *, source: str, command: str) -> CheckResult:
    """A yes/no check whose verdict reads committed data only: RECORDED if ``condition`` holds
    for that data (not a pass: nothing was computed in this run), FAIL if it does not.

    Parameters
    ----------
    source : str
        The data file, relative to the repository (e.g. ``"validation/data/coupling.json"``).
    command : str
        The command that writes it again.

    Examples
    --------
    >>> recorded("x", "s", True, "ok", source="validation/data/x.json", command="python -m x").outcome.value
    'RECORDED'
    >>> recorded("x", "s", False, "off", source="validation/data/x.json", command="python -m x").outcome.value
    'FAIL'
    """
    if not (source and command):
        raise ValueError(f"a recorded check names its data file and the command that writes it; "
                         f"got source = {source!r}, command = {command!r}")
    where = f" [recorded: {source}, written by {command}]"
    return CheckResult(name, section, Outcome.RECORDED if condition else Outcome.FAIL, detail + where,
                       source=source, command=command)


def skipped(name: str, section: str, why: str) -> CheckResult:
    """A check that could not run (solver not installed, module missing)."""
    return CheckResult(name, section, Outcome.SKIP, f"skipped: {why}")


def failed(name: str, section: str, why: str) -> CheckResult:
    """A check that could not produce a verdict because something broke."""
    return CheckResult(name, section, Outcome.FAIL, why)


def finding(name: str, section: str, detail: str, value: float | None = None,
            reference: float | None = None) -> CheckResult:
    """A published ``reference`` that disagrees with our ``value``, confirmed by a second solver.

    Only the caller can know that the second solver is independent and agrees with the first;
    the detail must say so with the numbers.
    """
    diff = None if value is None or reference is None else abs(float(value) - float(reference))
    return CheckResult(name, section, Outcome.FINDING, detail, value=value, reference=reference, diff=diff)


class CheckTimeout(BaseException):
    """A check exceeded its wall-time budget (counts as a hang).

    A :class:`BaseException`, like :class:`KeyboardInterrupt`, so that code under test that
    catches ``Exception`` (e.g. a scene runner recording failed points) cannot swallow it.
    """


@contextmanager
def _alarm(seconds: float | None) -> Iterator[None]:
    # SIGALRM interrupts Python-level loops (replica loops, sweeps); a single compiled kernel
    # cannot be interrupted, so solvers are also given their own time budgets.
    usable = seconds is not None and hasattr(signal, "SIGALRM")
    if usable:
        try:
            def handler(signum: int, frame: Any) -> None:
                raise CheckTimeout(f"exceeded the {seconds:g} s budget")

            old = signal.signal(signal.SIGALRM, handler)
        except ValueError:  # not in the main thread
            usable = False
    if usable:
        signal.setitimer(signal.ITIMER_REAL, float(seconds))
    try:
        yield
    finally:
        if usable:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, old)


def guarded(
    name: str,
    section: str,
    fn: Callable[[], list[CheckResult] | CheckResult],
    timeout: float | None = None,
    out_of_budget: str | None = None,
) -> list[CheckResult]:
    """Run a check function; turn a missing solver into SKIP and any crash into FAIL.

    The wall time is recorded on every returned result. A crash is a failure with the
    exception and its location in the detail, so one broken check does not stop the run.
    Exceeding ``timeout`` seconds is a hang (FAIL), unless ``out_of_budget`` is given: then
    the timeout was the run's overall budget, and the check is skipped with that reason.
    """
    t0 = time.perf_counter()
    try:
        with _alarm(timeout):
            out = fn()
        results = [out] if isinstance(out, CheckResult) else list(out)
    except MethodNotAvailableError as exc:
        results = [skipped(name, section, f"solver not available for this case: {exc}")]
    except CheckTimeout as exc:
        results = [skipped(name, section, out_of_budget) if out_of_budget else failed(name, section, f"hang: {exc}")]
    except Exception as exc:  # noqa: BLE001 - every crash must be reported, not raised
        where = traceback.extract_tb(exc.__traceback__)[-1]
        results = [failed(name, section, f"crashed: {type(exc).__name__}: {exc} "
                                         f"(at {where.filename.rsplit('/', 1)[-1]}:{where.lineno})")]
    dt = (time.perf_counter() - t0) / max(len(results), 1)
    return [replace(r, seconds=r.seconds or dt) for r in results]


def solver_available(method: str) -> str | None:
    """``None`` if solver ``method`` can be built, else the reason it cannot."""
    try:
        get_solver(method)
    except MethodNotAvailableError as exc:
        return str(exc)
    return None


def _solve_portable(h: Harvester, solver: Any) -> dict[str, Any]:
    """:func:`fpe_harvester.solve.solve` in a worker process; the result travels as a dict."""
    return solve(h, solver).to_dict()


class SolveCache:
    """Solve each (harvester, method, options) once per validation run.

    Options the solver class does not define are dropped (and listed in ``dropped``), so the
    validation code can ask for ``max_time`` or ``tol`` even from a solver that lacks them.

    With ``background=True``, :meth:`prefetch` starts a solve in a worker process (one, forked
    at the first prefetch) and :meth:`solve` waits for it: the steps announce their
    Fokker--Planck solves at the start of the run, and the worker computes them while this
    process runs Monte Carlo. A Fokker--Planck solve uses about one core, Monte Carlo two
    threads, so on two cores the two lanes fill the machine instead of taking turns. The result
    is the same as a solve in this process (same solver, same settings; a time budget
    ``max_seconds`` is wall time in the worker, so under load it buys less).
    """

    def __init__(self, background: bool = False) -> None:
        self._store: dict[tuple[Any, ...], Stats] = {}
        self._pending: dict[tuple[Any, ...], Any] = {}
        self._pool: Any = None
        self.background = background
        self.dropped: dict[str, set[str]] = {}
        self.seconds: dict[str, float] = {}
        #: Solves given to the worker, those a step then asked for, and how long this process
        #: waited for them [s].
        self.announced = 0
        self.prefetched = 0
        self.waited = 0.0

    def results(self) -> list[tuple[Harvester, str, Stats]]:
        """Every (harvester, method, result) solved so far, in order."""
        return [(key[0], key[1], r) for key, r in self._store.items()]

    def _solver(self, h: Harvester, method: str, options: dict[str, Any]) -> tuple[tuple[Any, ...], Any]:
        key = (h, method, tuple(sorted(options.items())))
        base = get_solver(method, h)
        names = {f.name for f in fields(base)} if hasattr(base, "__dataclass_fields__") else set()
        accepted = {k: v for k, v in options.items() if k in names}
        extra = set(options) - set(accepted)
        if extra:
            self.dropped.setdefault(method, set()).update(extra)
        return key, (replace(base, **accepted) if accepted else base)

    def prefetch(self, h: Harvester, method: str, **options: Any) -> None:
        """Start solving in the worker process (``background`` only; else nothing). Errors are
        left for :meth:`solve` to raise where the step asks for the result."""
        if not self.background:
            return
        try:
            key, solver = self._solver(h, method, options)
            if key in self._store or key in self._pending:
                return
            if self._pool is None:
                import multiprocessing
                from concurrent.futures import ProcessPoolExecutor

                # fork: the worker starts from this process as it is (nothing to re-import); the
                # first prefetch comes before any Monte Carlo run has started numba's threads
                methods = multiprocessing.get_all_start_methods()
                self._pool = ProcessPoolExecutor(
                    max_workers=1, mp_context=multiprocessing.get_context("fork" if "fork" in methods else "spawn"))
            self._pending[key] = self._pool.submit(_solve_portable, h, solver)
            self.announced += 1
        except Exception:  # noqa: BLE001 - the step's own solve reports it
            return

    def solve(self, h: Harvester, method: str, **options: Any) -> Stats:
        """Stats of ``h`` by ``method`` with the given settings (cached)."""
        key, solver = self._solver(h, method, options)
        if key not in self._store:
            t0 = time.perf_counter()
            job = self._pending.pop(key, None)
            result = None
            if job is not None:
                from concurrent.futures.process import BrokenProcessPool

                from fpe_harvester.scenes.cache import stats_from_dict

                try:
                    result = stats_from_dict(job.result())
                    self.prefetched += 1
                    self.waited += time.perf_counter() - t0
                except BrokenProcessPool:  # the worker died (memory?): solve here instead
                    result = None
            if result is None:
                result = solve(h, solver)
            self._store[key] = result
            self.seconds[method] = self.seconds.get(method, 0.0) + time.perf_counter() - t0
        return self._store[key]

    def reference(self, h: Harvester, name: str, compute: Callable[[], Stats], **settings: Any) -> Stats:
        """The result of a validation reference that is not one of the product's solvers (e.g. the
        exact-flow Monte Carlo, :mod:`validation.references.exactflow`), computed once per
        ``(h, name, settings)`` by ``compute()`` and kept with the solvers' results (so that the
        identities and the table of results include it)."""
        key = (h, name, tuple(sorted(settings.items())))
        if key not in self._store:
            t0 = time.perf_counter()
            self._store[key] = compute()
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
        return self._store[key]

    def worker_cpu(self) -> float:
        """Processor time [s] used so far by the live worker process (0 without one).

        A running child is not in ``getrusage(RUSAGE_CHILDREN)`` until it has ended and been
        waited for (:meth:`close`), so it is read from ``/proc/<pid>/stat`` (Linux; elsewhere
        0, and the sections' processor times leave the worker out).
        """
        total = 0.0
        for pid in list(getattr(self._pool, "_processes", None) or {}):
            try:
                with open(f"/proc/{pid}/stat") as f:
                    # fields after the command name (which may hold spaces): utime, stime are 14, 15
                    rest = f.read().rsplit(")", 1)[1].split()
                total += (int(rest[11]) + int(rest[12])) / os.sysconf("SC_CLK_TCK")
            except (OSError, ValueError, IndexError):
                continue
        return total

    def close(self) -> None:
        """Stop the worker process; solves announced but never asked for are dropped."""
        if self._pool is not None:
            # waits for a solve in progress (none, when every announced solve was asked for), so
            # that the worker's processor time is counted in the run's
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        self._pending.clear()


@dataclass(frozen=True)
class Context:
    """Settings shared by every validation step of one run.

    Attributes
    ----------
    quick : bool
        CI mode: small subsets and short solver budgets (whole run < 3 minutes).
    out : pathlib.Path
        Output folder (figures, JSON, the report).
    cache : SolveCache
        Results solved so far in this run (reused by the identity checks).
    seed : int
        Base seed of every Monte Carlo run (>= 0), so a run is reproducible.
    bench : pathlib.Path or None
        Folder written by ``python -m validation.studies.* --out DIR`` (the exhaustive
        benchmarks), whose output the report includes; None: none.
    """

    quick: bool
    out: Path
    cache: SolveCache
    seed: int = 2017
    deadline: float | None = None
    bench: Path | None = None

    def check(self, name: str, section: str, fn: Callable[[], list[CheckResult] | CheckResult],
              cap: float | None = None) -> list[CheckResult]:
        """:func:`guarded` under the per-check budget ``cap`` [s] and the run's ``deadline``.

        Past the deadline (a :func:`time.perf_counter` value; quick mode) checks are skipped
        with that reason instead of run, so that CI always gets a report in time.
        """
        if self.deadline is None:
            return guarded(name, section, fn, timeout=cap)
        left = self.deadline - time.perf_counter()
        reason = "the quick run's overall time budget was used up before this check could finish"
        if left <= 0:
            return [skipped(name, section, reason)]
        if cap is not None and cap <= left:
            return guarded(name, section, fn, timeout=cap)
        return guarded(name, section, fn, timeout=left, out_of_budget=reason)

    def require(self, *methods: str) -> None:
        """Raise :class:`MethodNotAvailableError` unless every solver named is installed."""
        missing = [f"{m}: {why}" for m in methods if (why := solver_available(m))]
        if missing:
            raise MethodNotAvailableError("; ".join(missing))

    @property
    def mc_options(self) -> dict[str, Any]:
        """Monte Carlo settings: target relative error on eta and a wall-time budget [s] per point."""
        if self.quick:
            # Fewer paths and replicas than the solver's defaults: errors ~2x larger, cost ~4x lower.
            return {"seed": self.seed, "tol": 0.02, "max_time": 4.0, "progress": False, "paths": 96,
                    "min_replicas": 6}
        return {"seed": self.seed, "tol": 0.005, "max_time": 90.0, "progress": False}

    @property
    def fpe_options(self) -> dict[str, Any]:
        """Fokker--Planck settings: requested relative error on eta and a wall-time budget [s] per point."""
        # The tolerance is at most a fifth of Monte Carlo's (quick: a twentieth; the kink's 2-D scheme
        # needs ~6 s for 1e-3 on an idle machine), so that in a cross-check the Fokker-Planck error
        # adds at most 2 % to the combined error bar; every step that does not need more shares these
        # solves (the run's cache). Measured at the kink (full settings): n = 1, a = 1 costs 21 s at
        # 1e-3 against 60 s (not converged) at 2.5e-4; n = 1.5, a = 2 costs 4.7 s against 45 s. A step
        # that tests finer digits (the paper's printed eta) asks for its own tol. Full: 60 s per
        # point, so that the strong kink (n = 1, a = 2), which does not converge, costs a minute, not five.
        return {"tol": 1e-3, "max_seconds": 12.0} if self.quick else {"tol": 1e-3, "max_seconds": 60.0}

    def options(self, method: str) -> dict[str, Any]:
        return {"mc": self.mc_options, "fpe": self.fpe_options}.get(method, {})

    def solve(self, h: Harvester, method: str, **overrides: Any) -> Stats:
        """Solve through the run's cache with this context's settings for ``method``."""
        return self.cache.solve(h, method, **{**self.options(method), **overrides})

    def prefetch(self, h: Harvester, method: str, **overrides: Any) -> None:
        """Announce a later :meth:`solve` with the same arguments (:meth:`SolveCache.prefetch`)."""
        self.cache.prefetch(h, method, **{**self.options(method), **overrides})
