"""Benchmark of the level solves of scheme ``"xv"``: a base commit against the working tree.

Every case is solved by :func:`fpe_harvester.solve` (``method="fpe"``) in a fresh Python
process, once with the code of a base commit (extracted by ``git archive`` into a
temporary folder) and once with the working tree, the two interleaved so that they share
the machine's load. Each run reports its wall and CPU seconds (the process's, which a busy
machine inflates less than the wall time), its peak resident memory, eta with its
estimated error, and its levels (M, DG degree, unknowns, GMRES iterations, seconds).

Cases: n = 1 at a = 1 and 0.5 (tol 1e-4; the scheme ``"xv"``) and n = 3, a = 0.5 at
tol 1e-6 (scheme ``"x"``, which shares only the refinement loop).

``python -m validation.studies.fpe.xvspeed [--quick] [--out DIR] [--base COMMIT]`` writes
``bench_xvspeed.json`` and ``bench_xvspeed.png`` (seconds per level, base against tree).
The full run takes 15-30 minutes on a busy 2-core machine; ``--quick`` runs n = 1, a = 0.5
only.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
from typing import Any

from validation.studies.cli import axes_plot, save_benchmark

__all__ = ["STEM", "CASES", "BASE", "run", "solve_case"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_xvspeed"

#: (n, a, tol) of the benchmark; the first is the quick case.
CASES = [(1.0, 0.5, 1e-4), (1.0, 1.0, 1e-4), (3.0, 0.5, 1e-6)]

#: The commit before the faster level solves.
BASE = "6a83443"

#: The checkout (validation/studies/fpe/ is three levels below it).
ROOT = pathlib.Path(__file__).resolve().parents[3]

#: Run in the child process: one solve, its timings and levels as JSON on stdout.
_CHILD = """
import json, resource, sys, time
from fpe_harvester import Harvester, solve
n, a, tol = map(float, sys.argv[1:4])
t0, c0 = time.perf_counter(), time.process_time()
s = solve(Harvester.build(n=n, a=a), "fpe", tol=tol)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
info = s.info
print(json.dumps({"wall_s": wall, "cpu_s": cpu, "solver_s": info.get("seconds"),
                  "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6,
                  "status": str(s.status), "eta": s.eta, "eta_err": s.eta_err,
                  "scheme": info.get("scheme"), "M": info.get("M"), "order": info.get("order"),
                  "levels": [{k: lv.get(k) for k in ("M", "order", "dofs", "iterations", "seconds", "eta")}
                             for lv in info.get("history", [])]}))
"""


def solve_case(tree: pathlib.Path, n: float, a: float, tol: float) -> dict[str, Any]:
    """One solve of (n, a, tol) with the code in ``tree``, in a fresh process."""
    out = subprocess.run([sys.executable, "-c", _CHILD, str(n), str(a), str(tol)], cwd=tree,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _base_tree(commit: str, folder: pathlib.Path) -> pathlib.Path:
    """The package at ``commit`` extracted into ``folder``."""
    archive = subprocess.run(["git", "archive", commit, "fpe_harvester", "montecarlo"], cwd=ROOT,
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def _draw(res: dict, ax: Any) -> None:
    for case, style in zip(res["cases"], ("o", "s", "^")):
        for key, ls in (("base", "--"), ("tree", "-")):
            lv = case[key]["levels"]
            ax.plot([x["dofs"] for x in lv], [x["seconds"] for x in lv], ls, marker=style,
                    label=f"n = {case['n']:g}, a = {case['a']:g} ({key})")
    ax.set(xscale="log", yscale="log", xlabel="unknowns of the level", ylabel="seconds of the level",
           title=f"levels: base {res['base']} against the tree")
    ax.legend(fontsize=7)


def run(quick: bool = False, out: pathlib.Path | str | None = None, base: str = BASE) -> dict[str, Any]:
    """Solve every case with the base commit and with the tree (interleaved); write
    ``bench_xvspeed.json`` and ``.png`` into ``out``."""
    cases = CASES[:1] if quick else CASES
    res: dict[str, Any] = {"quick": quick, "base": base, "cases": []}
    with tempfile.TemporaryDirectory() as tmp:
        old = _base_tree(base, pathlib.Path(tmp))
        for n, a, tol in cases:
            before = solve_case(old, n, a, tol)
            after = solve_case(ROOT, n, a, tol)
            res["cases"].append({"n": n, "a": a, "tol": tol, "base": before, "tree": after,
                                 "cpu_ratio": after["cpu_s"] / before["cpu_s"],
                                 "eta_difference": after["eta"] - before["eta"]})
    save_benchmark(res, out, STEM, axes_plot(_draw, (7.0, 4.6)))
    return res


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """``python -m validation.studies.fpe.xvspeed [--quick] [--out DIR] [--base COMMIT]``."""
    ap = argparse.ArgumentParser(prog="python -m validation.studies.fpe.xvspeed", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="n = 1, a = 0.5 only (about a minute)")
    ap.add_argument("--out", type=pathlib.Path, default=pathlib.Path("validation_report"), metavar="DIR")
    ap.add_argument("--base", default=BASE, metavar="COMMIT", help=f"the code to compare with (default {BASE})")
    args = ap.parse_args(argv)
    res = run(args.quick, args.out, args.base)
    print(json.dumps([{k: c[k] for k in ("n", "a", "tol", "cpu_ratio", "eta_difference")}
                      | {f"{w}_{k}": c[w][k] for w in ("base", "tree") for k in ("cpu_s", "eta", "eta_err", "peak_gb")}
                      for c in res["cases"]], indent=2))
    return res


if __name__ == "__main__":
    main()
