"""Seeded results: the numbers a redesign must not change.

A restructuring of a solver (a new registry, a renamed option, a kernel moved to another module)
must leave its results as they were: Monte Carlo bit for bit with the same seed, Fokker--Planck
to round-off. ``validation/references/data/seeded_results.json`` records, for each case of
:data:`CASES`, every quantity and its error (Monte Carlo as ``float.hex``, so that the file
holds each bit; Fokker--Planck as decimals compared to :data:`FPE_RTOL` relative), the status
and the run's size; ``tests/validation/references/test_seeded.py`` recomputes them all (about
a minute on 2 cores) and fails on the first difference.

A deliberate change of results (a new scheme, a corrected bias) rewrites the file with
``python -m validation.references.seeded --write``; its commit says so and why. ``--only LABEL``
recomputes some cases, ``--check`` compares without writing (the test's check, from the
command line).

The cases cover what the solvers' step and control code can take: the harmonic ring (its
twin exact), the n = 3 ring and unit (the frozen step), tau = 1e-4 (the joint step, and the
kink's averaged-noise step), the kink at a = 0.5 and a = 2 (located crossings), a ring with
the bi-Laplacian and cubic couplings, Richardson extrapolation, the runs without the twin or
the martingale controls, and Fokker--Planck at n = 3 and n = 1.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fpe_harvester import Harvester, QUANTITIES, Stats, solve

__all__ = ["SeededCase", "CASES", "PATH", "FPE_RTOL", "compute", "compare", "load", "main"]

#: Where the recorded results live.
PATH = Path(__file__).parent / "data" / "seeded_results.json"
#: Relative tolerance on each Fokker--Planck number (its sparse solves and BLAS may round
#: differently on another machine or thread count; a change of design moves them far more).
FPE_RTOL = 1e-10

#: Monte Carlo settings shared by every seeded case: small runs (each well under two seconds),
#: enough replicas for the richest control set (martingale, boundary and twin), a fixed batch
#: (the results depend on it, not on the threads) and no progress bar.
_MC = {"seed": 20171122, "tol": 0.05, "paths": 2, "t_run": 20.0, "t_burn": 5.0, "min_replicas": 128,
       "max_replicas": 128, "batch": 2, "progress": False}


@dataclass(frozen=True)
class SeededCase:
    """One seeded solve: a label, the system (``Harvester.build`` arguments), method and settings."""

    label: str
    system: dict[str, Any]
    method: str
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def h(self) -> Harvester:
        return Harvester.build(**self.system)


def _mc(label: str, system: dict[str, Any], **options: Any) -> SeededCase:
    return SeededCase(label, system, "mc", {**_MC, **options})


#: The seeded cases, in the order they run.
CASES: tuple[SeededCase, ...] = (
    _mc("mc harmonic unit", {"a": 0.5, "n": 2}),
    _mc("mc harmonic ring", {"a": 0.5, "n": 2, "N": 3, "k": -0.3}),
    _mc("mc harmonic ring, tau = 1e-4", {"a": 0.5, "n": 2, "N": 3, "k": -0.3, "tau": 1e-4}),
    _mc("mc n = 3 unit", {"a": 0.5, "n": 3}),
    _mc("mc n = 3 unit, tau = 1e-4", {"a": 0.5, "n": 3, "tau": 1e-4}),
    _mc("mc n = 3 ring", {"a": 0.5, "n": 3, "N": 3, "k": -0.5}),
    _mc("mc n = 3 ring, extrapolated", {"a": 0.5, "n": 3, "N": 3, "k": -0.5}, extrapolate=True),
    _mc("mc n = 3 ring, no twin", {"a": 0.5, "n": 3, "N": 3, "k": -0.5}, control=False),
    _mc("mc n = 3 ring, no martingale", {"a": 0.5, "n": 3, "N": 3, "k": -0.5}, martingale=False),
    _mc("mc n = 1.5 unit", {"a": 0.5, "n": 1.5}),
    _mc("mc kink unit, a = 0.5", {"a": 0.5, "n": 1}),
    _mc("mc kink unit, a = 2", {"a": 2.0, "n": 1}),
    _mc("mc kink ring, tau = 1e-4", {"a": 0.5, "n": 1, "N": 2, "k": 0.2, "tau": 1e-4}),
    _mc("mc kink ring, k3 and k4", {"a": 0.5, "n": 1, "N": 3, "k": -0.5, "k3": 1.0, "k4": 0.05}),
    _mc("mc n = 4 ring, k3 and k4", {"a": 0.5, "n": 4, "N": 4, "k": -0.2, "k3": 0.5, "k4": 0.02}),
    SeededCase("fpe n = 3 unit", {"a": 0.5, "n": 3}, "fpe", {"tol": 1e-4, "progress": False}),
    SeededCase("fpe kink unit, a = 0.5", {"a": 0.5, "n": 1}, "fpe", {"tol": 1e-3, "progress": False}),
)


def _record(case: SeededCase, res: Stats, seconds: float) -> dict[str, Any]:
    exact_bits = case.method == "mc"
    numbers: dict[str, Any] = {}
    for q in QUANTITIES:
        for name, value in zip((q, f"{q}_err"), res.value(q)):
            if value is None:
                numbers[name] = None
            else:
                numbers[name] = float(value).hex() if exact_bits else float(value)
    size = {key: res.info[key] for key in ("replicas", "dt", "paths", "control_set", "M", "dofs")
            if key in res.info}
    return {"label": case.label, "system": case.system, "method": case.method, "options": case.options,
            "status": res.status.value, "numbers": numbers, "size": _plain(size),
            "seconds": round(seconds, 2)}


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "item"):
        return obj.item()
    return obj


def compute(case: SeededCase) -> dict[str, Any]:
    """Solve ``case`` and return its record (numbers, status, size, wall time)."""
    t0 = time.perf_counter()
    res = solve(case.h, case.method, **case.options)
    return _record(case, res, time.perf_counter() - t0)


def compare(recorded: dict[str, Any], fresh: dict[str, Any]) -> list[str]:
    """The differences between a recorded and a fresh record of one case (empty: identical).

    Monte Carlo numbers must be bit-identical; Fokker--Planck numbers equal to :data:`FPE_RTOL`
    relative; the status and the run's size equal."""
    label = recorded["label"]
    out = []
    if recorded["status"] != fresh["status"]:
        out.append(f"{label}: status {fresh['status']!r}, recorded {recorded['status']!r}")
    if _plain(recorded["size"]) != _plain(fresh["size"]):
        out.append(f"{label}: run size {fresh['size']}, recorded {recorded['size']}")
    for name, old in recorded["numbers"].items():
        new = fresh["numbers"].get(name)
        if old is None or new is None:
            if old is not new:
                out.append(f"{label}: {name} = {new!r}, recorded {old!r}")
        elif recorded["method"] == "mc":
            if old != new:
                out.append(f"{label}: {name} = {float.fromhex(new)!r} ({new}), recorded "
                           f"{float.fromhex(old)!r} ({old})")
        elif not math.isclose(new, old, rel_tol=FPE_RTOL, abs_tol=0.0):
            out.append(f"{label}: {name} = {new!r}, recorded {old!r} (relative difference "
                       f"{abs(new - old) / abs(old):.2g} > {FPE_RTOL:g})")
    return out


def load(path: Path = PATH) -> dict[str, dict[str, Any]]:
    """The recorded results by label."""
    data = json.loads(path.read_text())
    return {entry["label"]: entry for entry in data["cases"]}


def _write(records: list[dict[str, Any]], path: Path) -> None:
    import numba
    import numpy as np

    data = {"about": "seeded results; rewrite with: python -m validation.references.seeded --write",
            "machine": {"python": platform.python_version(), "numpy": np.__version__, "numba": numba.__version__,
                        "machine": platform.machine()},
            "cases": records}
    path.write_text(json.dumps(data, indent=1) + "\n")


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m validation.references.seeded [--write | --check] [--only LABEL ...]``."""
    parser = argparse.ArgumentParser(prog="python -m validation.references.seeded", description=__doc__.split("\n")[0])
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help="recompute and rewrite the recorded file")
    mode.add_argument("--check", action="store_true", help="recompute and compare (the default)")
    parser.add_argument("--only", nargs="+", metavar="LABEL", help="only these cases (exact labels)")
    args = parser.parse_args(argv)
    labels = {c.label for c in CASES}
    unknown = sorted(set(args.only or ()) - labels)
    if unknown:
        parser.error(f"--only: unknown case(s) {unknown}; valid: {sorted(labels)}")
    chosen = [c for c in CASES if not args.only or c.label in args.only]
    recorded = load() if PATH.exists() else {}
    fresh = {}
    for case in chosen:
        fresh[case.label] = compute(case)
        print(f"{case.label:40s} {fresh[case.label]['status']:14s} {fresh[case.label]['seconds']:6.2f} s",
              flush=True)
    if args.write:
        merged = [fresh.get(c.label) or recorded[c.label] for c in CASES if c.label in fresh or c.label in recorded]
        _write(merged, PATH)
        print(f"wrote {len(merged)} cases to {PATH}")
        return 0
    problems = [p for label, rec in fresh.items()
                for p in (compare(recorded[label], rec) if label in recorded else [f"{label}: not recorded"])]
    print("\n".join(problems) if problems else f"{len(fresh)} cases identical to {PATH.name}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
