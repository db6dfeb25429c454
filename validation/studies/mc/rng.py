"""Monte Carlo design study: the cost of one standard normal with the candidate generators.

numba's legacy ``np.random`` inside ``prange``, bulk numpy ``Generator`` draws, a ``Generator``
drawn inside numba: the measurement that decided the engine's choice.

``python -m validation.studies.mc.rng [--quick] [--out DIR]`` writes ``bench_montecarlo_rng.json`` and
``bench_montecarlo_rng.png``.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from numba import njit, prange

from fpe_harvester.parallel import default_threads
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "rng_costs", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_rng"


@njit(parallel=True, cache=True)
def _legacy_prange(nchunks: int, nper: int, seeds: np.ndarray) -> np.ndarray:
    acc = np.zeros(nchunks)
    for c in prange(nchunks):
        np.random.seed(seeds[c])
        s = 0.0
        for _ in range(nper):
            s += np.random.standard_normal()
        acc[c] = s
    return acc


@njit(nogil=True, cache=True)
def _generator_inside(gen: np.random.Generator, nper: int) -> float:
    s = 0.0
    for _ in range(nper):
        s += gen.standard_normal()
    return s


def rng_costs(n: int, threads: int) -> dict[str, float]:
    """Nanoseconds of wall time per standard normal, all threads busy where possible.

    A hand-written xoshiro256++ + ziggurat generator inlined in numba was also tried while
    building the engine: 10 ns per normal on its fast path alone, no better than numba's own
    ``Generator`` support, so it was dropped.
    """
    nch = 8 * threads
    per = n // nch
    seeds = np.arange(nch, dtype=np.uint32)
    gens = [np.random.default_rng(i) for i in range(nch)]
    _legacy_prange(2, 10, seeds)
    _generator_inside(gens[0], 10)
    out: dict[str, float] = {}
    t0 = time.perf_counter()
    _legacy_prange(nch, per, seeds)
    out["numba_legacy_np_random_prange"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    buf = [np.empty(per) for _ in range(threads)]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(lambda i: gens[i].standard_normal(out=buf[i % threads]), range(nch)))
    out["numpy_generator_bulk_threads"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    t0 = time.perf_counter()
    gens[0].standard_normal(out=buf[0])
    out["numpy_generator_bulk_1thread"] = (time.perf_counter() - t0) / per * 1e9
    t0 = time.perf_counter()
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(lambda g: _generator_inside(g, per), gens))
    out["generator_inside_numba_threads"] = (time.perf_counter() - t0) / (nch * per) * 1e9
    t0 = time.perf_counter()
    _generator_inside(gens[0], per)
    out["generator_inside_numba_1thread"] = (time.perf_counter() - t0) / per * 1e9
    out["chosen"] = "generator_inside_numba_threads"
    return out


def study(quick: bool) -> dict[str, float]:
    """:func:`rng_costs` on 2^22 normals (quick) or 2^25, on all usable cores."""
    return rng_costs(2**22 if quick else 2**25, default_threads())


def draw(res: dict[str, Any], ax: Any) -> None:
    """Nanoseconds per normal, one bar per generator."""
    costs = {k: v for k, v in res.items() if isinstance(v, float) and k != "wall_s"}
    ax.barh(list(costs), list(costs.values()))
    ax.set_xlabel("wall time per standard normal [ns]")
    ax.set_title(f"chosen: {res.get('chosen')}", fontsize=8)
    ax.tick_params(axis="y", labelsize=6)


#: The generators' costs (:func:`study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
