"""Monte Carlo design study: the time-step bias.

Coupled (common-noise) differences eta(dt/2) - eta(dt) for the harmonic unit, the kink at
a = 2 and the steep n = 1.1 potential, and the naive scheme's error at a = 2;
:func:`coupled_diff` is the coupled difference the other studies use.

``python -m validation.studies.mc.bias [--quick] [--out DIR]`` writes ``bench_montecarlo_bias.json`` and
``bench_montecarlo_bias.png``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from montecarlo import estimate, simulate, simulate_naive
from validation.studies.cli import bench_main, study_runner

__all__ = ["STEM", "bias_study", "coupled_diff", "draw", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "bench_montecarlo_bias"


def bias_study(quick: bool) -> dict[str, Any]:
    """Coupled differences eta(dt/2) - eta(dt) and the naive scheme's error at the kink."""
    out: dict[str, Any] = {}
    cases = {
        "harmonic_a0.5": (Harvester.build(a=0.5), (0.4, 0.2, 0.1), 64),
        "kink_a2_n1": (Harvester.build(a=2.0, n=1), (0.04, 0.02) if quick else (0.08, 0.04, 0.02, 0.01),
                       64 if quick else 128),
        "steep_a0.5_n1.1": (Harvester.build(a=0.5, n=1.1), (0.04, 0.02) if quick else (0.08, 0.04, 0.02), 128),
    }
    for name, (h, dts, paths) in cases.items():
        rows = []
        for dt in dts:
            e = simulate(h, dt=dt, paths=paths if quick else 2 * paths, replicas=6 if quick else 12,
                         t_burn=20.0, t_run=40.0 if quick else 100.0, seed=17, richardson=True)
            m0, m1 = e.moments(0), e.moments(1)
            d = m0["V2"] / m0["vxi"] - m1["V2"] / m1["vxi"]
            eta = float((m0["V2"] / m0["vxi"]).mean())
            rows.append({"dt": dt, "eta_fine": eta, "diff": float(d.mean()),
                         "diff_se": float(d.std(ddof=1) / math.sqrt(d.size)),
                         "rel_diff": float(d.mean()) / eta, "wall_s": e.wall_time})
        fit = None
        good = [r for r in rows if abs(r["diff"]) > 3 * r["diff_se"]]
        if len(good) >= 2:
            logs = np.log([[r["dt"], abs(r["diff"])] for r in good])
            fit = float(np.polyfit(logs[:, 0], logs[:, 1], 1)[0])
        out[name] = {"rows": rows, "fitted_order_from_resolved_points": fit}
    h = Harvester.build(a=2.0, n=1)
    kw = dict(paths=128 if quick else 1024, replicas=6 if quick else 12, t_burn=20.0,
              t_run=40.0 if quick else 100.0)
    naive = estimate(simulate_naive(h, dt=0.01, seed=31, **kw), h)
    ours = estimate(simulate(h, dt=0.02, seed=32, richardson=True, **kw), h)
    out["kink_a2_naive_vs_engine_dt_0.01"] = {
        "naive_eta": naive.mean["eta"], "naive_se": naive.se["eta"],
        "engine_eta": ours.mean["eta"], "engine_se": ours.se["eta"],
        "engine_bias_estimate": ours.bias["eta"], "engine_bias_se": ours.bias_se["eta"],
        "naive_rel_error": naive.mean["eta"] / ours.mean["eta"] - 1.0,
        "naive_V2_ratio": naive.mean["V2"] / ours.mean["V2"], "naive_Pin_ratio": naive.mean["Pin"] / ours.mean["Pin"],
    }
    return out


def coupled_diff(h: Harvester, quick: bool, seed: int, step: str = "auto") -> dict[str, Any]:
    """eta(0.01) - eta(0.02) on common noise (``step`` as in :func:`montecarlo.simulate`)."""
    e = simulate(h, dt=0.02, paths=64, replicas=6 if quick else 16, t_burn=20.0, t_run=50.0, seed=seed,
                 richardson=True, step=step)
    m0, m1 = e.moments(0), e.moments(1)
    d = m0["V2"] / m0["vxi"] - m1["V2"] / m1["vxi"]
    # V2 too: with xi frozen at tau << dt the plain v xi has the variance D/tau and eta per
    # replica is meaningless
    dv = m0["V2"] - m1["V2"]
    return {"step": e.notes["step"], "dt": 0.02, "diff": float(d.mean()),
            "diff_se": float(d.std(ddof=1) / math.sqrt(d.size)),
            "rel_diff": float(d.mean() / (m0["V2"] / m0["vxi"]).mean()),
            "rel_diff_V2": float(dv.mean() / m0["V2"].mean()),
            "rel_diff_V2_se": float(dv.std(ddof=1) / math.sqrt(dv.size) / m0["V2"].mean()),
            "wall_s": e.wall_time}


def draw(res: dict[str, Any], ax: Any) -> None:
    """|eta(dt/2) - eta(dt)| / eta against dt per system, with a slope-2 guide."""
    for name, st in res.items():
        if not isinstance(st, dict) or "rows" not in st:
            continue
        rows = st["rows"]
        ax.errorbar([r["dt"] for r in rows], [abs(r["rel_diff"]) for r in rows],
                    yerr=[r["diff_se"] / r["eta_fine"] for r in rows], fmt="o-", capsize=3, label=name)
    dts = np.array([0.01, 0.4])
    ax.loglog(dts, 0.05 * (dts / 0.4) ** 2, "k--", lw=0.8, label="slope 2")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("dt")
    ax.set_ylabel("|eta(dt/2) - eta(dt)| / eta")
    ax.legend(fontsize=7)


#: The time-step bias (:func:`bias_study`), written as ``{STEM}.json`` and ``.png`` into ``out`` when given.
run = study_runner(bias_study, STEM, draw)


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__)
