"""Benchmark of the exact harmonic solver: run time against error, with scipy's dense baseline.

Measured in one run:

* a single call of :func:`fpe_harvester.solve` (N = 3, a = 0.5, k = -0.33), its error against a
  40-digit Lyapunov solve;
* a ring of N = 1,000,000 units (target: under 1 s);
* a vectorized sweep of 10,000 (k, a) points for N = 3 (target: under 1 s);
* scipy's dense 4N x 4N Lyapunov solve (``solve_continuous_lyapunov``) for N = 2..128 and the
  Fourier closed form, their wall times and their errors, both measured against references
  independent of the library's floating-point evaluation: the closed form in 60-digit arithmetic
  (:func:`validation.references.mp_closed_form`), a 40-digit Lyapunov solve for the single call
  (:func:`~validation.references.mp_ring_moments`) and exact rational arithmetic
  (:func:`~validation.references.rational_eta`) where the mode stiffnesses are rational.

``python -m validation.studies.exact.bench [--quick] [--out DIR]`` writes ``bench_exact.json`` and
``bench_exact.png``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from fpe_harvester import Harvester, exact_sweep, solve
from fpe_harvester.exact import dense_covariance
from validation.studies.cli import bench_main, save_benchmark
from validation.references.analytic import mp_closed_form, mp_ring_moments, rational_eta

__all__ = ["STEM", "REPORT_KW", "ACCURACY", "run", "report_checks"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_exact"
#: Keyword arguments the report's benchmark section passes to :func:`run` (none: it runs it all).
REPORT_KW: dict[str, Any] = {}
#: Largest relative error of eta allowed against the independent references (the solver's
#: error is round-off, ~1e-16).
ACCURACY = 1e-13


def _best_time(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run(quick: bool = False, out: Path | None = None) -> dict[str, Any]:
    """Run the benchmark; returns (and writes, when ``out`` is given) the measurements."""
    repeat = 3 if quick else 7
    res: dict[str, Any] = {"quick": quick}

    paper = Harvester.build(a=0.5, N=3, k=-0.33)
    ref_eta = float(mp_ring_moments(paper)["eta"])
    t, r = _best_time(lambda: solve(paper), repeat)
    res["single_call_s"] = t
    res["single_call_eta_rel_error"] = abs(r.eta / ref_eta - 1)
    res["single_call_reference"] = "40-digit Lyapunov solve (validation.references.mp_ring_moments)"

    h = Harvester.build(a=0.5, N=1_000_000, k=-0.2)
    t, r = _best_time(lambda: solve(h), repeat)
    res["ring_1e6_s"] = t
    res["ring_1e6_target_s"] = 1.0

    a, k = np.meshgrid(np.linspace(0.01, 2.0, 100), np.linspace(-1.0, 0.5, 100))
    t, sw = _best_time(lambda: exact_sweep(a, k, N=3), repeat)
    res["sweep_10000_s"] = t
    res["sweep_10000_target_s"] = 1.0
    res["sweep_stable_fraction"] = float(sw["stable"].mean())

    # N = 4, a = 1/2, k = -1/16: kappa_q = 1 - sin^2(pi q/4)/4 = 1, 7/8, 3/4, 7/8 (all rational)
    kq = [Fraction(1), Fraction(7, 8), Fraction(3, 4), Fraction(7, 8)]
    V2_q, eta_q = rational_eta(kq)
    r = solve(Harvester.build(a=0.5, N=4, k=-1 / 16))
    res["rational_check"] = {
        "N": 4, "k": -1 / 16,
        "eta_exact": str(eta_q), "eta_rel_error": abs(r.eta / float(eta_q) - 1),
        "V2_rel_error": abs(r.V2 / float(V2_q) - 1),
    }

    rows = []
    for N in ([2, 4, 8, 16, 32] if quick else [2, 4, 8, 16, 32, 64, 128]):
        ring = Harvester.build(a=0.5, N=N, k=-0.2)
        t_fourier, rf = _best_time(lambda: solve(ring), repeat)
        t_dense, C = _best_time(lambda: dense_covariance(ring), 1 if N >= 64 else repeat)
        V2_dense = float(np.diag(C)[2::4].mean())
        Pin_dense = float(np.diag(C, 2)[1::4].mean()) * ring.params.sigma
        ref = float(mp_closed_form(ring)["eta"])
        rows.append({
            "N": N, "fourier_s": t_fourier, "dense_lyapunov_s": t_dense,
            "fourier_eta_rel_error": abs(rf.eta / ref - 1),
            "dense_eta_rel_error": abs(V2_dense / Pin_dense / ref - 1),
        })
    res["fourier_vs_dense"] = rows

    save_benchmark(res, out, STEM, _plot)
    return res


def report_checks(res: dict[str, Any]) -> list[tuple[str, bool, str]]:
    """What a run compared: the exact solver's eta against the 40-digit Lyapunov solve, the
    rational value and the 60-digit closed form, each within :data:`ACCURACY` (relative)."""
    fourier = max(r["fourier_eta_rel_error"] for r in res["fourier_vs_dense"])
    errors = {"N = 3 ring vs the 40-digit Lyapunov solve": res["single_call_eta_rel_error"],
              "N = 4 ring vs its rational value": res["rational_check"]["eta_rel_error"],
              "rings N = 2..: worst against the 60-digit closed form": fourier}
    return [(f"eta, {label}", err <= ACCURACY, f"relative error {err:.2g} (tolerance {ACCURACY:g})")
            for label, err in errors.items()]


def _plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["fourier_vs_dense"]
    N = [r["N"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    ax1.loglog(N, [r["fourier_s"] for r in rows], "o-", label="Fourier closed form")
    ax1.loglog(N, [r["dense_lyapunov_s"] for r in rows], "s-", label="scipy dense Lyapunov (4N)")
    ax1.set_xlabel("ring size N")
    ax1.set_ylabel("wall time [s]")
    ax1.legend()
    ax2.loglog([r["dense_lyapunov_s"] for r in rows],
               [max(r["dense_eta_rel_error"], 1e-17) for r in rows], "s-", label="dense Lyapunov")
    ax2.loglog([r["fourier_s"] for r in rows], [max(r["fourier_eta_rel_error"], 1e-17) for r in rows], "o-",
               label="Fourier closed form")
    ax2.set_xlabel("wall time [s]")
    ax2.set_ylabel("relative error of eta (vs 60-digit closed form)")
    ax2.legend()
    fig.suptitle(f"exact solver: N = 1e6 ring in {res['ring_1e6_s']:.3f} s, "
                 f"10^4-point sweep in {res['sweep_10000_s']:.4f} s")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__, drop=("fourier_vs_dense",))
