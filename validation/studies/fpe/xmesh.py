"""Benchmark of the x mesh for 1 < n < 2: algebraic grading against geometric layers.

Two parts, both in one run so that the two meshes share the machine's load:

* *Mesh error against unknowns* (n = 1.5, a = 1, fixed Hermite degree M): eta on the
  algebraic mesh (nodes graded like :math:`t^{2.5}` toward 0) and on the geometric one
  (uniform bulk, 4 layers of ratio 0.15 toward 0, Gauss--Jacobi quadrature of the force on
  the element at 0) with 4-32 elements per half, against the algebraic mesh with 64
  elements per half at the same M. This isolates the mesh error from the Hermite error
  (a convergence check, not a correctness check).
* *Tolerance-driven solves* through :func:`fpe_harvester.solve` (solver seconds from
  ``info``, budget 60 s): n in {1.25, 1.5, 1.75} x a in {0.5, 1, 2} at tol = 1e-4 on both
  meshes, and n = 8 (one mesh: the wall-graded one) at 1e-4 and, for a = 0.5, 1e-6.

``python -m validation.studies.fpe.xmesh [--quick] [--out DIR]`` writes ``bench_xmesh.json`` and
``bench_xmesh.png`` (error against unknowns and against seconds). The full run takes
15-25 minutes on 2 cores; ``--quick`` runs M = 6 and n = 1.5, a = 0.5 only.
"""

from __future__ import annotations

import pathlib
import time
from typing import Any

from fpe_harvester import Harvester, solve
from fpe_harvester.fpe.schemes.x import XMeshRule, discretize
from fpe_harvester.fpe.schemes.x.discretize import Whitening, solve_level
from validation.studies.cli import bench_main, save_benchmark

__all__ = ["STEM", "run", "mesh_series", "tol_case"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_xmesh"

MESHES = ("algebraic", "geometric")
SUB_QUADRATIC = [(n, a) for n in (1.25, 1.5, 1.75) for a in (0.5, 1.0, 2.0)]
STEEP = [(8.0, a, tol) for a in (0.5, 1.0, 2.0) for tol in (1e-4,)] + [(8.0, 0.5, 1e-6)]
BUDGET = 60.0


def mesh_series(M: int, sizes: tuple[int, ...], n: float = 1.5, a: float = 1.0) -> dict[str, Any]:
    """eta at degree M on both meshes with ``sizes`` elements per half, and the reference
    (algebraic, 64 per half); each point with its unknowns, seconds and error."""
    h = Harvester.build(a=a, n=n)
    w = Whitening.of(h)

    def level(mesh: str, nh: int) -> dict[str, Any]:
        discretize.clear_x_cache()
        t0 = time.perf_counter()
        lv = solve_level(h, M, XMeshRule.of(h, mesh).build(h, w, nh), 3, w)
        return {"half_elements": nh, "elements": lv.elements, "dofs": 2 * lv.dofs,
                "seconds": time.perf_counter() - t0, "eta": lv.moments["eta"]}

    ref = level("algebraic", 64)
    out: dict[str, Any] = {"n": n, "a": a, "M": M, "reference": ref}
    for mesh in MESHES:
        pts = [level(mesh, nh) for nh in sizes]
        for p in pts:
            p["error"] = abs(p["eta"] - ref["eta"]) / abs(ref["eta"])
        out[mesh] = pts
    return out


def tol_case(n: float, a: float, tol: float, mesh: str = "auto") -> dict[str, Any]:
    """One tolerance-driven solve: status, eta and its error, solver seconds, M, elements."""
    discretize.clear_x_cache()
    r = solve(Harvester.build(a=a, n=n), "fpe", tol=tol, mesh=mesh, max_seconds=BUDGET)
    return {"n": n, "a": a, "tol": tol, "mesh": mesh, "status": r.status.value, "eta": r.eta,
            "eta_err": r.eta_err, "seconds": r.info.get("seconds"), "M": r.info.get("M"),
            "elements": r.info.get("elements")}


def run(quick: bool = False, out: pathlib.Path | None = None) -> dict:
    """Both parts (see the module docstring); writes the JSON and the figure into ``out``."""
    degrees = (6,) if quick else (8, 12)
    sizes = (4, 8, 16) if quick else (4, 8, 16, 32)
    res: dict[str, Any] = {"mesh_series": [mesh_series(M, sizes) for M in degrees]}
    cases = [(1.5, 0.5)] if quick else SUB_QUADRATIC
    res["sub_quadratic"] = [tol_case(n, a, 1e-4, mesh) for n, a in cases for mesh in MESHES]
    res["steep"] = [] if quick else [tol_case(n, a, tol) for n, a, tol in STEEP]
    save_benchmark(res, out, STEM, _plot)
    return res


def _plot(res: dict, path: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for series in res["mesh_series"]:
        for mesh, marker in zip(MESHES, ("o", "s")):
            pts = [p for p in series[mesh] if p["error"] > 0]
            label = f"{mesh}, M = {series['M']}"
            axes[0].loglog([p["dofs"] for p in pts], [p["error"] for p in pts], marker=marker, label=label)
            axes[1].loglog([p["seconds"] for p in pts], [p["error"] for p in pts], marker=marker, label=label)
    n, a = res["mesh_series"][0]["n"], res["mesh_series"][0]["a"]
    for ax, xlabel in zip(axes, ("unknowns (whole mesh)", "seconds per level")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("relative mesh error of eta (fixed M)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"x mesh, n = {n:g}, a = {a:g}: algebraic grading against geometric layers")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    bench_main(run, __doc__)
