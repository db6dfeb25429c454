"""Monte Carlo design study: throughput of the engine and cost of the path loop.

Three parts, with CPU seconds (process or calling thread), for a machine shared with other work:

* ``rates``: path-steps per second, one time step of one ring, fine level only, on all usable
  cores: N = 1 (harmonic, kink n = 1) and N = 3 (harmonic, n = 3);
* ``kernel``: CPU nanoseconds per path-step of the path loop alone (:func:`montecarlo.simulate`
  on one thread, Richardson pair) at P = 2, 8, 64 paths per chunk, for the n = 3 ring (N = 3,
  k = -0.5) at tau = 1 (frozen-xi step) and tau = 1e-4 (joint step): the solver runs chunks of
  2-16 paths, where the loop's per-step overhead shows;
* ``solve``: process CPU seconds of a seeded ``solve(h, "mc", seed=2, tol=1e-2)`` after a
  warm-up solve (compilation), for the harmonic ring (N = 3, k = -0.33), the n = 3 ring and the
  n = 3 unit at tau = 1e-4.

Medians of repeats; compare two trees by running this in each, one after the other (timings on a
shared machine drift). ``python -m validation.studies.mc.throughput [--quick] --out validation/data``
writes ``bench_montecarlo_throughput.json`` and ``.png`` (the name the Monte Carlo benchmark reads).
"""

from __future__ import annotations

import statistics
import time
from typing import Any

from fpe_harvester import Harvester, solve
from fpe_harvester.parallel import default_threads
from montecarlo import simulate
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "rate", "throughput", "kernel_ns", "solve_cpu", "study", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_throughput"

#: Systems of the solve timings (keyword arguments of :meth:`Harvester.build`).
SOLVE_CASES = {"harmonic_ring_N3_k-0.33": {"N": 3, "k": -0.33},
               "n3_ring_N3_k-0.5": {"n": 3, "N": 3, "k": -0.5},
               "n3_unit_tau1e-4": {"n": 3, "tau": 1e-4}}


def rate(h: Harvester, dt: float, paths: int, replicas: int, t_run: float) -> dict[str, float]:
    simulate(h, dt=dt, paths=2, replicas=1, t_burn=0.0, t_run=dt * 4, seed=0)  # compile
    cpu0 = time.process_time()
    e = simulate(h, dt=dt, paths=paths, replicas=replicas, t_burn=0.0, t_run=t_run, seed=1)
    cpu = time.process_time() - cpu0
    # CPU seconds of all threads: on a shared machine the wall rate understates what the
    # cores deliver; per-core rate x cores is what an idle machine would give (an estimate)
    return {"path_steps": e.path_steps, "wall_s": e.wall_time, "cpu_s": cpu,
            "path_steps_per_s": e.path_steps / e.wall_time,
            "unit_steps_per_s": e.path_steps * h.N / e.wall_time,
            "path_steps_per_cpu_s": e.path_steps / cpu if cpu > 0 else None,
            "idle_machine_estimate_path_steps_per_s":
                e.path_steps / cpu * default_threads() if cpu > 0 else None}


def throughput(quick: bool) -> dict[str, dict[str, float]]:
    """:func:`rate` of four systems at dt = 0.01, 256 paths x 4 replicas, t_run = 10 (quick) or 50."""
    t_run = 10.0 if quick else 50.0
    return {
        "N1_harmonic": rate(Harvester.build(a=0.5), 0.01, 256, 4, t_run),
        "N1_kink_n1_a0.5": rate(Harvester.build(a=0.5, n=1), 0.01, 256, 4, t_run),
        "N3_harmonic_k-0.2": rate(Harvester.build(a=0.5, N=3, k=-0.2), 0.01, 256, 4, t_run),
        "N3_n3_k-0.5": rate(Harvester.build(a=0.5, n=3, N=3, k=-0.5), 0.01, 256, 4, t_run),
    }


def kernel_ns(tau: float, paths: int, path_steps: float, repeats: int) -> float:
    """Median thread-CPU nanoseconds per path-step of :func:`montecarlo.simulate` on one thread
    (the loop itself: the setup is negligible at this length) for the n = 3 ring (N = 3,
    k = -0.5, a = 0.5) at ``tau``, dt = 0.02 with Richardson pair, ``paths`` per chunk and
    about ``path_steps`` ring steps per repeat."""
    h = Harvester.build(a=0.5, n=3, N=3, k=-0.5, tau=tau)
    replicas = 4
    t_run = max(1.0, path_steps / (paths * replicas) * 0.02)
    kw = {"dt": 0.02, "paths": paths, "replicas": replicas, "t_burn": 0.0, "richardson": True,
          "chunk": paths, "threads": 1}
    simulate(h, t_run=0.1, seed=0, **kw)  # compile
    ns = []
    for r in range(repeats):
        t0 = time.thread_time()
        e = simulate(h, t_run=t_run, seed=1 + r, **kw)
        ns.append((time.thread_time() - t0) / e.path_steps * 1e9)
    return statistics.median(ns)


def solve_cpu(h: Harvester, tol: float, repeats: int) -> dict[str, Any]:
    """Median process CPU seconds of ``solve(h, "mc", seed=2, tol=tol)`` after a warm-up solve,
    with its eta (float.hex: the same tree gives the same bits)."""
    solve(h, "mc", seed=1, tol=3e-2, progress=False)
    cpu = []
    for _ in range(repeats):
        t0 = time.process_time()
        r = solve(h, "mc", seed=2, tol=tol, progress=False)
        cpu.append(time.process_time() - t0)
    return {"cpu_s": statistics.median(cpu), "runs_cpu_s": cpu, "eta_hex": float(r.eta).hex()}


def study(quick: bool) -> dict[str, Any]:
    """:func:`throughput`, :func:`kernel_ns` at tau = 1, 1e-4 and P = 2, 8, 64, and
    :func:`solve_cpu` of :data:`SOLVE_CASES` (tol 1e-2, 3 repeats; quick: tol 3e-2, 1 repeat,
    a tenth of the kernel's path-steps)."""
    steps, repeats = (4e4, 3) if quick else (4e5, 5)
    kernel = {f"tau={tau:g}": {f"P={P}": kernel_ns(tau, P, steps, repeats) for P in (2, 8, 64)}
              for tau in (1.0, 1e-4)}
    tol, n = (3e-2, 1) if quick else (1e-2, 3)
    solves = {name: solve_cpu(Harvester.build(a=0.5, **kw), tol, n) for name, kw in SOLVE_CASES.items()}
    return {"rates": throughput(quick), "kernel_ns_per_path_step": kernel, "solve": solves}


def draw(res: dict[str, Any], ax: Any) -> None:
    """Path-steps per wall second and per CPU second, one pair of bars per system."""
    rows = res["rates"]
    y = range(len(rows))
    ax.barh([i - 0.2 for i in y], [v["path_steps_per_s"] for v in rows.values()], 0.4, label="per wall s")
    ax.barh([i + 0.2 for i in y], [v["path_steps_per_cpu_s"] or 0.0 for v in rows.values()], 0.4,
            label="per CPU s")
    ax.set_yticks(list(y), list(rows), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("path-steps per second")
    ax.legend(fontsize=7)


#: The study (:func:`study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
