"""Benchmarks: error versus wall time of each solver, with the baselines it replaces.

One module per solver, each runnable on its own and writing ``<STEM>.json`` and ``<STEM>.png``:

* ``python -m validation.studies.exact``: the exact solver against scipy's dense Lyapunov solve;
* ``python -m validation.studies.fpe``: Fokker--Planck error against wall time, time to a tolerance;
* ``python -m validation.studies.montecarlo``: Monte Carlo speed, cost at equal error, time-step
  bias, against a plain numpy Euler--Maruyama loop;

(each takes ``--quick`` and ``--out DIR``; :mod:`.cli` is their shared command line).
:mod:`validation.sections.benchmarks` is the report step of ``harvester validate``: it runs the three and puts
their error/time pairs on one plot. The modules are imported when run, not here.
"""

from __future__ import annotations

from .cli import bench_main, save_benchmark

__all__ = ["bench_main", "save_benchmark"]
