"""Benchmarks and design studies, by subject: one module per study, each runnable on its own with
``python -m validation.studies.<subject>.<name> [--quick] [--out DIR]``, writing ``<STEM>.json``
and ``<STEM>.png`` (:mod:`.cli` is their shared command line and output; :data:`.cli.DATA` the
folder of their recorded runs, ``validation/data``).

* :mod:`.exact`: the exact solver's benchmark (:mod:`.exact.bench`);
* :mod:`.fpe`: Fokker--Planck, its benchmark (:mod:`.fpe.bench`, with its kink and x-mesh parts
  :mod:`.fpe.kink` and :mod:`.fpe.xmesh`), the level solves of scheme ``"xv"`` against a base
  commit (:mod:`.fpe.xvspeed`) and the measured domain (:mod:`.fpe.domain`);
* :mod:`.mc`: Monte Carlo, its benchmark (:mod:`.mc.bench`, which runs the design studies of the
  folder in one go) and each design study on its own;
* :mod:`.kink`: the kink n = 1 in Monte Carlo: its time-step law (:mod:`.kink.timestep`), an
  independent reference scheme with exact crossings (:mod:`.kink.reference`) and the exact-flow
  construction's bias (:mod:`.kink.exactflow_bias`);
* :mod:`.prototypes`: discretizations measured and not adopted (the strong kink's DG scheme in
  (x, v, V), :mod:`.prototypes.xvw`);
* every solver at once: :mod:`.work_precision` (error against wall time, beside the baselines);
  the physics beyond the paper: :mod:`.coupling` (rings made stable by cubic bonds).

The report's benchmark section (:mod:`validation.sections.benchmarks`) runs the short versions of
the three benchmarks and draws the recorded work-precision diagrams. The modules are imported
when run, not here.
"""

from __future__ import annotations

from .cli import axes_plot, bench_main, run_study, save_benchmark

__all__ = ["axes_plot", "bench_main", "run_study", "save_benchmark"]
