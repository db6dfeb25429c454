"""Benchmarks and design studies: one module per study, each runnable on its own with
``python -m validation.studies.<name> [--quick] [--out DIR]``, writing ``<STEM>.json`` and
``<STEM>.png`` (:mod:`.cli` is their shared command line and output).

* benchmarks, error against wall time, whose short versions the report's benchmark section runs
  (:mod:`validation.sections.benchmarks`): :mod:`.exact` (against scipy's dense Lyapunov solve),
  :mod:`.fpe` (Fokker--Planck; :mod:`.kink` and :mod:`.xmesh` are its kink and x-mesh parts) and
  :mod:`.montecarlo` (which runs the Monte Carlo studies below in one go); :mod:`.xvspeed` times
  the level solves of the Fokker--Planck scheme ``"xv"`` against a base commit;
* Monte Carlo design studies: :mod:`.mc_rng`, :mod:`.mc_throughput`, :mod:`.mc_equal_error`,
  :mod:`.mc_bias`, :mod:`.mc_tau`, :mod:`.mc_steep`, :mod:`.mc_controls`, :mod:`.mc_martingale`,
  :mod:`.mc_policy`, :mod:`.mc_boundary`, :mod:`.mc_kink_dt`;
* the kink (n = 1): :mod:`.kinkstudy` (its time-step law) and :mod:`.kinkref` (an independent
  reference scheme with exact crossings);
* the strong kink's candidate discretization: :mod:`.xvw` (DG in (x, v, V) with V graded toward
  0, discrete ordinates in xi; measured, not a product scheme), its W = V - K_c x variant
  :mod:`.xvw_w` and its hybrid :mod:`.xvw_hybrid` (Hermite functions in V on the bulk's
  (x, v) elements, the V mesh on the trap's; also the force of 1 < n).

The modules are imported when run, not here.
"""

from __future__ import annotations

from .cli import axes_plot, bench_main, run_study, save_benchmark

__all__ = ["axes_plot", "bench_main", "run_study", "save_benchmark"]
