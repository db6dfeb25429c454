"""Benchmark of the Monte Carlo engine: speed, cost at equal error, time-step bias, RNG choice.

The studies, one module each (each runnable on its own with ``python -m``, writing its own JSON and
figure), run here in one go: :mod:`.rng` (generators' cost), :mod:`.throughput`
(path-steps per second), :mod:`.equal_error` (against a numpy Euler--Maruyama loop at equal
error), :mod:`.bias` (time-step bias), :mod:`.tau` (noise correlation time),
:mod:`.steep` (steep walls), :mod:`.controls` (harmonic twin), :mod:`.martingale`
(martingale controls and their coverage), :mod:`.policy` (time-step policy and its
coverage), :mod:`.boundary` (end-of-window terms), :mod:`.kink_dt` (the kink's time-step
law). The solver's error against wall time beside the baselines is the work-precision study
(:mod:`validation.studies.work_precision`).

``python -m validation.studies.mc.bench [--quick] [--out DIR]`` writes ``bench_montecarlo.json``
and ``bench_montecarlo.png``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from fpe_harvester.parallel import default_threads
from validation.studies.cli import bench_main, save_benchmark
from validation.studies.mc import (bias, boundary, controls, equal_error, kink_dt, martingale, policy, rng, steep,
                                   tau, throughput)

__all__ = ["STEM", "STUDIES", "REPORT_STUDIES", "REPORT_KW", "run", "report_checks"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo"

_FULL_ONLY = "full mode only; CI smoke test: tests/montecarlo/test_martingale.py"

#: The studies of :func:`run`, in order: name -> function of ``quick`` giving its result.
STUDIES: dict[str, Callable[[bool], Any]] = {
    "rng": rng.study,
    "throughput": throughput.throughput,
    "equal_error": equal_error.equal_error,
    "bias": bias.bias_study,
    "noise_correlation_time": tau.tau_study,
    "steep_walls": steep.steep_study,
    "control_variates": controls.control_variates,
    "martingale": martingale.martingale_rows,
    # the coverage studies take minutes: full mode only (quick runs feed `harvester validate`)
    "martingale_coverage": lambda quick: martingale.martingale_coverage(quick) if not quick else {
        "note": _FULL_ONLY},
    "time_step_policy": policy.policy_rows,
    "end_of_window_terms": boundary.boundary_rows,
    "time_step_policy_coverage": lambda quick: policy.policy_coverage(quick) if not quick else {
        "note": "full mode only (~8 min); CI checks: tests/montecarlo/test_extrapolate.py"},
    "kink_dt": kink_dt.kink_dt_study,
}
#: The studies the validation report's benchmark section runs (:mod:`validation.sections.benchmarks`): throughput,
#: error against time, and what its combined figure needs (the kink's time-step study and the
#: ring's run at 1e-4 give the references of the Monte Carlo curves). The design studies (bias
#: against dt, noise correlation time, steep walls, the martingale terms, the time-step policy,
#: 35 s of the quick run's 66 s) run with ``python -m validation.studies.mc.bench [--quick]``.
REPORT_STUDIES = ("rng", "throughput", "equal_error", "control_variates", "kink_dt")
#: Keyword arguments the report's benchmark section passes to :func:`run`.
REPORT_KW = {"studies": REPORT_STUDIES}


def run(quick: bool = False, out: Path | None = None, studies: tuple[str, ...] | None = None) -> dict[str, Any]:
    """Run the benchmark; returns (and writes, when ``out`` is given) the measurements.

    ``studies``: the subset of :data:`STUDIES` to run (default all); the others are listed as
    not run.
    """
    names = tuple(STUDIES)
    chosen = names if studies is None else tuple(studies)
    unknown = set(chosen) - set(names)
    if unknown:
        raise ValueError(f"studies must be among {names}, got {sorted(unknown)}")
    res: dict[str, Any] = {"quick": quick, "threads": default_threads(), "target_path_steps_per_s": 1e8,
                           "target_speedup_vs_numpy_em": 10.0}
    for name in names:
        key = "rng_ns_per_normal" if name == "rng" else name
        if name not in chosen:
            res[key] = {"note": "not run here: python -m validation.studies.mc.bench [--quick] runs every study"}
        else:
            res[key] = STUDIES[name](quick)
    save_benchmark(res, out, STEM, _plot)
    return res


def report_checks(res: dict[str, Any]) -> list[tuple[str, bool, str]]:
    """What the report's short run compared: nothing (it measures speed and cost; the Monte Carlo
    accuracy checks are the report's cross-checks and coverage), so no check is counted."""
    return []


def _plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2, ax3, ax4) = plt.subplots(1, 4, figsize=(20, 3.8))
    equal_error.draw(res["equal_error"], ax1)
    bias.draw(res["bias"], ax2)
    controls.draw(res.get("control_variates", {}), ax3)
    kink_dt.draw(res.get("kink_dt", {}), ax4)
    thr = {k: v for k, v in res["throughput"].items() if isinstance(v, dict)}
    fig.suptitle("Monte Carlo: " + ", ".join(f"{k} {v['path_steps_per_s']:.2g}/s" for k, v in thr.items()),
                 fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
