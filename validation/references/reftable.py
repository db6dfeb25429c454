"""The project's own table of reference values: long runs, with how each was computed.

``validation/references/data/reference_values.json`` holds, per case, eta, V2 and Pin with their errors,
the solver and its settings, the seed, the command that regenerates it, the commit and the
wall time: Fokker--Planck values at tight tolerances where the solver converges (single
units), long Monte Carlo runs elsewhere (rings, the kink at a = 2). It is a regression
anchor: the tests and the report compare fresh results against it, within the combined
errors. It does not replace the cross-solver checks (a value and its reference here may
come from the same solver).

``python -m validation.references.reftable`` regenerates every entry from committed code (all
cases: about an hour on 2 cores) and stamps each with the commit; it refuses to run on a tree
with uncommitted changes to the code (:data:`CODE`), so that every stamp names code one can
check out. ``--only LABEL ...`` recomputes some cases and keeps the others, ``--stale`` those
that are stale (:func:`staleness`), ``--list`` shows every case with its state.

**When an entry is stale.** A solver's code changes often without its results changing (a
restructuring holds them bit for bit: ``tests/validation/references/test_seeded.py``), so a
change of code does not make an entry stale; a change of results does. An entry is current when

1. its stamp is a commit of this history (not an uncommitted tree);
2. its system and settings are its case's in :data:`CASES` (the time guards ``max_seconds`` and
   ``max_time`` excepted when the entry reached its tolerance or stopped before either the
   recorded or the case's guard: it did not meet them);
3. no commit after its stamp changed the seeded results of its solver
   (:data:`validation.references.seeded.PATH`, rewritten only when a solver's results change
   deliberately, by ``python -m validation.references.seeded --write``); and
4. if its stamp is older than the seeded-results file, no commit between the two changed its
   solver's code (:data:`CODE`): before that file, a code change was the only record.

The seeded cases are the promise: a change of results that none of them sees is not seen here
either.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import subprocess
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from fpe_harvester import Harvester, Stats, Status, solve

__all__ = ["RefCase", "CASES", "CODE", "PATH", "KINK_PATH", "SEEDED", "GUARDS", "load", "lookup", "as_stats",
           "recorded_kink", "recorded_mc", "compute", "compare", "staleness", "stale_note", "UncommittedError", "main"]

#: Where the table lives.
PATH = Path(__file__).parent / "data" / "reference_values.json"
#: The kink's (n = 1) long Monte Carlo runs, one entry per a (``"a0.5"``, ``"a1"``, ``"a2"``).
KINK_PATH = Path(__file__).parent / "data" / "kink_mc_reference_values.json"


@dataclass(frozen=True)
class RefCase:
    """One entry: a label, the system (``Harvester.build`` arguments), the solver and its settings."""

    label: str
    system: dict[str, Any]
    method: str
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def h(self) -> Harvester:
        return Harvester.build(**self.system)


def _fpe(n: float, a: float, tol: float) -> RefCase:
    # max_seconds is a guard, never the stop (see _mc): an entry ends on its tolerance, the memory
    # bound or the mesh's limits, which give the same number on a busier machine.
    return RefCase(f"fpe n = {n:g}, a = {a:g}", {"n": n, "a": a}, "fpe", {"tol": tol, "max_seconds": 7200.0})


def _mc(label: str, system: dict[str, Any], tol: float, seed: int, max_replicas: int | None = None) -> RefCase:
    # max_time is a guard, never the stop: a run stopped by the clock would give another number
    # on a busier machine; where tol is out of reach, max_replicas stops it at the same point.
    budget = {} if max_replicas is None else {"max_replicas": max_replicas}
    return RefCase(label, system, "mc", {"tol": tol, "seed": seed, "max_time": 7200.0, "progress": False, **budget})


#: The cases: Fokker--Planck to 1e-7 for smooth walls (1e-8 for n = 3, a = 0.5, the reference
#: of the work-precision study's Fokker--Planck curve down to 1e-7; 1e-6 where 1e-7 is out of
#: reach in minutes), to 1e-5 for n = 1.5, 1e-6 and 1e-5 for the kink (a = 0.5 and 1: the references of
#: the work-precision study's Fokker--Planck kink curves); Monte Carlo to 1e-3 for the strong kink
#: (the kink's long Monte Carlo runs to 3e-4 are in kink_mc_reference_values.json), and to 2e-4
#: for the rings and four single smooth units (the Fokker--Planck error bounds' independent
#: references).
CASES: tuple[RefCase, ...] = (
    *(_fpe(n, a, 1e-8 if (n, a) == (3.0, 0.5) else 1e-7) for n in (3.0, 4.0) for a in (0.5, 1.0, 2.0)),
    *(_fpe(n, a, 1e-6) for n in (6.0, 8.0) for a in (0.5, 1.0, 2.0)),
    *(_fpe(1.5, a, 1e-5) for a in (0.5, 1.0, 2.0)),
    _fpe(1.0, 0.5, 1e-6),
    _fpe(1.0, 1.0, 1e-5),
    # a replica budget in case 1e-3 is not reached, so that the entry stops at the same point on any
    # machine (at 2fd6895 it reached 9.8e-4 after 2048 replicas; at 2c06b4c 1.6e-3 after 2512)
    _mc("mc n = 1, a = 2", {"n": 1.0, "a": 2.0}, 1e-3, 101, max_replicas=2512),
    # single smooth units by Monte Carlo: the independent references of the Fokker--Planck error bounds
    _mc("mc n = 1.5, a = 1", {"n": 1.5, "a": 1.0}, 2e-4, 104),
    _mc("mc n = 3, a = 0.5", {"n": 3.0, "a": 0.5}, 2e-4, 105),
    _mc("mc n = 4, a = 1", {"n": 4.0, "a": 1.0}, 2e-4, 106),
    _mc("mc n = 8, a = 0.5", {"n": 8.0, "a": 0.5}, 2e-4, 107),
    # rings to 2e-4: the independent reference of the work-precision study's ring (errors to 1e-3 and below)
    _mc("mc n = 3, N = 3, a = 0.5, k = -0.5", {"n": 3.0, "a": 0.5, "N": 3, "k": -0.5}, 2e-4, 102),
    _mc("mc n = 4, N = 3, a = 0.5, k = -0.5", {"n": 4.0, "a": 0.5, "N": 3, "k": -0.5}, 2e-4, 103),
)


#: The code an entry depends on, per method (paths from the repository root): a commit that
#: changes any of them after an entry's makes that entry stale.
CODE: dict[str, tuple[str, ...]] = {
    "fpe": ("fpe_harvester/fpe", "fpe_harvester/model.py"),
    "mc": ("montecarlo", "fpe_harvester/model.py"),
}
_ROOT = Path(__file__).resolve().parents[2]


class UncommittedError(RuntimeError):
    """The code an entry would be computed from has uncommitted changes."""


def _git(*args: str) -> str:
    out = subprocess.run(["git", *args], cwd=_ROOT, capture_output=True, text=True, timeout=30)
    if out.returncode != 0:
        raise RuntimeError(f"git {' '.join(args)} failed: {out.stderr.strip()}")
    return out.stdout.strip()


def _commit(method: str) -> str:
    """The short hash of HEAD; raises :class:`UncommittedError` if the code ``method`` uses
    (:data:`CODE`, and this module) differs from it."""
    dirty = _git("status", "--porcelain", "--untracked-files=no", "--", *CODE[method],
                 str(Path(__file__).resolve().relative_to(_ROOT)))
    if dirty:
        raise UncommittedError(f"uncommitted changes to the code a {method!r} entry depends on:\n{dirty}\n"
                               "commit them first, so that the entry's stamp names code one can check out")
    return _git("rev-parse", "--short", "HEAD")


#: The seeded-results file (:mod:`validation.references.seeded`), relative to the repository.
SEEDED = "validation/references/data/seeded_results.json"
#: Options that only guard a run's time: not settings of an entry that reached its tolerance.
GUARDS = ("max_seconds", "max_time", "progress")


@functools.lru_cache(maxsize=None)
def _git_read(*args: str) -> str:
    """:func:`_git` for read-only queries, remembered for the process (history does not change
    under a validation run)."""
    return _git(*args)


def _seeded_changed(commit: str, method: str) -> bool:
    """Whether ``commit`` changed the seeded results of ``method`` (a case present before and after
    whose numbers differ; Fokker--Planck beyond the file's relative tolerance)."""
    from .seeded import FPE_RTOL

    def cases(rev: str) -> dict[str, dict[str, Any]]:
        try:
            data = json.loads(_git_read("show", f"{rev}:{SEEDED}"))
        except (RuntimeError, json.JSONDecodeError):
            return {}
        return {c["label"]: c["numbers"] for c in data.get("cases", []) if c.get("method") == method}

    before, after = cases(f"{commit}^"), cases(commit)
    for label in before.keys() & after.keys():
        for q, old in before[label].items():
            new = after[label].get(q)
            if method == "mc" or old is None or new is None:
                if old != new:
                    return True
            elif abs(float(new) - float(old)) > FPE_RTOL * max(abs(float(old)), 1e-300):
                return True
    return False


def staleness(entry: dict[str, Any] | None, method: str, case: RefCase | None = None) -> str | None:
    """Why ``entry`` must be regenerated, or None if it is current (the rule of the module
    docstring; ``case`` gives the settings it must have, when known)."""
    if entry is None:
        return "missing"
    commit = str(entry.get("commit", ""))
    if not commit or "+" in commit or commit == "unknown":
        return f"stamped {commit!r}: not a commit"
    try:
        _git_read("cat-file", "-e", f"{commit}^{{commit}}")
    except RuntimeError:
        return f"commit {commit} is not in this repository's history"
    if case is not None:
        if entry.get("system") != case.system:
            return f"its system {entry.get('system')} is not its case's {case.system}"
        opts = entry.get("options", {})
        took = float(entry.get("seconds", math.inf))
        # a guard is no setting of an entry that reached its tolerance or stopped well before it
        guards = [k for k in GUARDS if k == "progress" or entry.get("status") == "stable"
                  or took < min(float(opts.get(k, math.inf)), float(case.options.get(k, math.inf)))]
        mine = {k: v for k, v in opts.items() if k not in guards}
        wanted = {k: v for k, v in case.options.items() if k not in guards}
        if mine != wanted:
            return f"its settings {mine} are not its case's {wanted}"
    # the earlier cause first: code changed before any seeded result could tell whether it moved
    first = _git_read("log", "--format=%h", "--diff-filter=A", "--", SEEDED).split()
    if first:
        older = _git_read("log", "--format=%h", f"{commit}..{first[-1]}", "--", *CODE[method]).split()
        if older:
            return (f"{len(older)} commit(s) changed its solver's code before the seeded results were recorded "
                    f"({older[0]}, ...)")
    changed = [c for c in _git_read("log", "--format=%h", f"{commit}..HEAD", "--", SEEDED).split()
               if _seeded_changed(c, method)]
    if changed:
        return f"the seeded {method} results changed after it ({', '.join(changed)})"
    return None


def stale_note(entry: dict[str, Any], method: str, label: str | None = None) -> str:
    """``""`` for a current entry, else ``"; STALE: <why>"`` for a report's detail (a table entry
    is looked up by ``label`` among :data:`CASES` for its settings)."""
    case = next((c for c in CASES if c.label == label), None)
    try:
        why = staleness(entry, method, case)
    except (RuntimeError, OSError) as exc:  # no git here (an installed copy): say so
        why = f"staleness unknown ({exc})"
    return f"; STALE: {why}" if why else ""


def compute(case: RefCase) -> dict[str, Any]:
    """Solve one case and describe how (JSON-ready).

    Raises
    ------
    UncommittedError
        The code the case depends on has uncommitted changes (checked before solving).
    """
    commit = _commit(case.method)
    t0 = time.perf_counter()
    r = solve(case.h, case.method, **case.options)
    entry: dict[str, Any] = {
        "system": case.system, "method": case.method, "options": case.options, "status": r.status.value,
        "message": r.message, "seconds": round(time.perf_counter() - t0, 1), "commit": commit,
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "command": f"python -m validation.references.reftable --only '{case.label}'",
    }
    for q in ("eta", "V2", "Pin"):
        v, e = r.value(q)
        entry[q], entry[q + "_err"] = v, e
    return entry


def load(path: Path = PATH) -> dict[str, dict[str, Any]]:
    """The table: label -> entry (empty if it does not exist)."""
    return json.loads(path.read_text()) if path.exists() else {}


def lookup(h: Harvester, method: str, max_rel_err: float = math.inf, path: Path = PATH) -> dict[str, Any] | None:
    """The table's entry for system ``h`` solved by ``method`` (with its ``label`` added), or
    None when the table has none, it carries no error, or its relative error on eta exceeds
    ``max_rel_err``."""
    table = load(path)
    for c in CASES:
        if c.method == method and c.h == h and table.get(c.label, {}).get("eta_err") is not None:
            entry = table[c.label]
            return {**entry, "label": c.label} if entry["eta_err"] <= max_rel_err * abs(entry["eta"]) else None
    return None


def as_stats(entry: dict[str, Any], status: Status | None = None) -> Stats:
    """A table entry (:func:`lookup`) as a result, with its origin in the message; ``status``
    replaces the recorded one (e.g. STABLE for a reference known to be accurate enough)."""
    values = {q: entry[q] for q in ("eta", "V2", "Pin")} | {q + "_err": entry[q + "_err"] for q in ("eta", "V2", "Pin")}
    return Stats(**values, status=status or Status(entry["status"]), method=entry["method"],
                 message=f"reference table '{entry['label']}' ({entry['status']}, {entry['date']}, commit "
                         f"{entry['commit']}, seed {entry['options'].get('seed')}): {entry['message']}"
                         + stale_note(entry, entry["method"], entry["label"]))


def recorded_kink(a: float) -> dict[str, Any] | None:
    """The long Monte Carlo run of the kink (n = 1) at ``a`` recorded in :data:`KINK_PATH`
    (eta, V2, Pin with errors, seed, dt, ...), or None if none is recorded for that ``a``."""
    if not KINK_PATH.exists():
        return None
    return json.loads(KINK_PATH.read_text()).get(f"a{a:g}")


def _kink_stale_note() -> str:
    """:func:`stale_note` for the kink's long runs, stamped by the last commit that wrote their file."""
    try:
        stamp = _git_read("log", "-1", "--format=%h", "--", str(KINK_PATH.relative_to(_ROOT))).strip()
    except (RuntimeError, OSError, ValueError) as exc:
        return f"; staleness unknown ({exc})"
    return stale_note({"commit": stamp}, "mc")


def recorded_mc(h: Harvester) -> Stats | None:
    """The independent long Monte Carlo run recorded for the single unit ``h``: the kink's own
    file (``validation/references/data/kink_mc_reference_values.json``, n = 1), else this table; None if
    there is none."""
    if h.N == 1 and h.n == 1.0:
        d = recorded_kink(h.a)
        if d is None:
            return None
        return Stats(status=Status.STABLE, method="mc", eta=d["eta"], eta_err=d["eta_err"],
                     message=f"long run in validation/references/data/kink_mc_reference_values.json (seed {d.get('seed')}): "
                             f"{d['message']}" + _kink_stale_note(),
                     V2=d["V2"], V2_err=d["V2_err"], Pin=d["Pin"], Pin_err=d["Pin_err"])
    entry = lookup(h, "mc")
    return None if entry is None else as_stats(entry, Status.STABLE)


def compare(label: str, r: Stats, sigmas: float = 4.0, path: Path = PATH) -> list[tuple[str, bool, str]]:
    """``r`` against the table's entry ``label``, per quantity: |r - ref| <= sigmas x the
    combined error (Monte Carlo standard errors and Fokker--Planck bounds alike; an entry that
    stopped short of its tolerance counts with the error it reached). Returns (label, passed,
    detail) triples; an entry that is missing or has no error fails."""
    entry = load(path).get(label)
    if entry is None or entry.get("eta_err") is None:
        why = "missing" if entry is None else f"without an error ({entry.get('status')}: {entry.get('message')})"
        return [(f"reference table: {label}", False, f"entry {why} (python -m validation.references.reftable)")]
    out = []
    note = stale_note(entry, entry["method"], label)
    for q in ("eta", "V2", "Pin"):
        v, e = r.value(q)
        ref, ref_e = entry[q], entry[q + "_err"] or 0.0
        if v is None or e is None:
            out.append((f"reference table: {label}: {q}", False, f"{r.method} gave no {q} ({r.status.value})"))
            continue
        comb = math.hypot(e, ref_e)
        ok = abs(v - ref) <= sigmas * comb
        out.append((f"reference table: {label}: {q}", ok,
                    f"{v:.8g} +- {e:.2g} vs table {ref:.8g} +- {ref_e:.2g} ({entry['method']}, {entry['status']}, "
                    f"{entry['date']}, "
                    f"commit {entry['commit']}): |diff| = {abs(v - ref):.2g} vs {sigmas:g} x {comb:.2g}{note}"))
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: recompute all cases, those named by ``--only`` or the stale ones, and write
    the table (after each case, so an interrupted run keeps what it finished)."""
    p = argparse.ArgumentParser(prog="python -m validation.references.reftable", description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", metavar="LABEL", help="labels to recompute (default: all)")
    p.add_argument("--stale", action="store_true", help="recompute only the stale entries (see --list)")
    p.add_argument("--out", default=str(PATH), help=f"table to update (default {PATH})")
    p.add_argument("--list", action="store_true", help="list the cases, their cost and state, and exit")
    args = p.parse_args(argv)
    out = Path(args.out)
    table = load(out)
    labels = [c.label for c in CASES]
    if args.list:
        for c in CASES:
            why = staleness(table.get(c.label), c.method, c)
            print(f"{c.label:40s} {table.get(c.label, {}).get('seconds', '-'):>7} s  {why or 'current'}")
        return 0
    unknown = sorted(set(args.only or ()) - set(labels))
    if unknown:
        print(f"python -m validation.references.reftable: error: --only: unknown labels {unknown}; see --list",
              file=sys.stderr)
        return 2
    todo = [c for c in CASES if (not args.only or c.label in args.only)
            and (not args.stale or staleness(table.get(c.label), c.method, c))]
    try:
        for c in {c.method for c in todo}:
            _commit(c)
    except UncommittedError as exc:
        print(f"python -m validation.references.reftable: error: {exc}", file=sys.stderr)
        return 1
    for case in todo:
        entry = compute(case)
        table[case.label] = entry
        out.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
        print(f"{case.label:40s} {entry['status']:14s} eta {entry['eta']} +- {entry['eta_err']} "
              f"({entry['seconds']} s, commit {entry['commit']})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
