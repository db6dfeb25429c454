"""Monte Carlo design study: path-steps per second of the engine.

One time step of one ring, fine level only, on all usable cores: N = 1 (harmonic, kink n = 1)
and N = 3 (harmonic, n = 3); with the CPU seconds, for a machine shared with other work.

``python -m validation.studies.mc_throughput [--quick] [--out DIR]`` writes ``bench_montecarlo_throughput.json`` and
``bench_montecarlo_throughput.png``.
"""

from __future__ import annotations

import time
from typing import Any

from fpe_harvester import Harvester
from montecarlo import simulate
from fpe_harvester.parallel import default_threads
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "rate", "throughput", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_throughput"


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


def draw(res: dict[str, Any], ax: Any) -> None:
    """Path-steps per wall second and per CPU second, one pair of bars per system."""
    rows = {k: v for k, v in res.items() if isinstance(v, dict)}
    y = range(len(rows))
    ax.barh([i - 0.2 for i in y], [v["path_steps_per_s"] for v in rows.values()], 0.4, label="per wall s")
    ax.barh([i + 0.2 for i in y], [v["path_steps_per_cpu_s"] or 0.0 for v in rows.values()], 0.4,
            label="per CPU s")
    ax.set_yticks(list(y), list(rows), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("path-steps per second")
    ax.legend(fontsize=7)


#: The engine's throughput (:func:`throughput`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(throughput, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
