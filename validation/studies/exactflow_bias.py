"""Study: the bias of the exact-flow Monte Carlo (:mod:`validation.references.exactflow`) against
its step and its trap threshold, on common noise.

The construction is exact between force events; what remains is the step's bias: for n = 1 the
crossing times (located on the conditional-mean path), the trap threshold ``w_trap`` (units held
at rest below it) and the release from rest at a step's end; for n = 1.25 the discrete-gradient
force. Every variant of a system runs on the same Brownian path (:func:`~validation.references.
exactflow.coupled`), so the paired differences from the finest variant measure the bias at a small
fraction of the cost of independent runs.

A setting's **bias bound** per quantity, relative to its value, is
:math:`|d| + 2\\,\\mathrm{se}(d) + r`, with :math:`d` its difference from the finest variant and
:math:`r` the finest variant's own remaining bias, taken as large as the difference it has from
its next-coarser neighbour in each knob (step; ``w_trap`` for n = 1), plus two standard errors of
each: first-order biases halve when the knob halves, so the neighbour's difference is at least the
finest's own. :func:`validation.references.exactflow.solve_flow` adds the bound of its setting to
its errors.

``python -m validation.studies.exactflow_bias [--quick] [--out validation/data]`` writes
``exactflow_bias.json`` and ``exactflow_bias.png``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from fpe_harvester import Harvester
from validation.references.exactflow import Variant, coupled, difference
from validation.studies.cli import bench_main, save_benchmark

__all__ = ["STEM", "COMMAND", "PLANS", "bias_study", "bounds", "run"]

#: Name of the written ``.json`` and ``.png``.
STEM = "exactflow_bias"
#: The command that writes ``validation/data/exactflow_bias.json``.
COMMAND = "python -m validation.studies.exactflow_bias --out validation/data"

#: Per system: (n, a), the fine step, the variants (the finest first), and the neighbours of the
#: finest in each knob (indices into the variants: (coarser, its base) pairs whose difference
#: bounds the finest's own remaining bias).
PLANS: dict[str, dict[str, Any]] = {
    "n1_a2": {"n": 1.0, "a": 2.0, "fine": 0.0025,
              "variants": (Variant(1, 0.001), Variant(2, 0.001), Variant(4, 0.001), Variant(8, 0.001),
                           Variant(4, 0.003), Variant(4, 0.01), Variant(8, 0.003)),
              "neighbours": ((1, 0), (4, 2))},
    "n1.25_a2": {"n": 1.25, "a": 2.0, "fine": 0.0025,
                 "variants": (Variant(1, 0.0), Variant(2, 0.0), Variant(4, 0.0), Variant(8, 0.0), Variant(16, 0.0)),
                 "neighbours": ((1, 0),)},
}

_QUANTITIES = ("eta", "V2", "Pin", "v2", "vV")


def bounds(res: dict[str, Any], plan: dict[str, Any]) -> list[dict[str, Any]]:
    """The bias bound of every variant's setting (see the module docstring), per quantity, relative."""
    rows = []
    ref = res["variants"][0]["estimates"]
    resid = {q: sum(abs(d) + 2.0 * se for d, se in (difference(res, j, k, q) for j, k in plan["neighbours"]))
             for q in _QUANTITIES}
    for j, v in enumerate(res["variants"]):
        rel, measured = {}, {}
        for q in _QUANTITIES:
            d, se = difference(res, j, 0, q) if j else (0.0, 0.0)
            scale = abs(ref[q][0])
            rel[q] = (abs(d) + 2.0 * se + resid[q]) / scale
            measured[q] = {"minus_finest": d / scale, "se": se / scale}
        rows.append({"system": dict(res["system"]), "step": v["step"], "w_trap": v["w_trap"],
                     "relative_bias_bound": rel, "relative_difference_from_finest": measured})
    return rows


def bias_study(quick: bool) -> dict[str, Any]:
    """Every system of :data:`PLANS`: the coupled variants, their differences and the bounds."""
    paths, t_run = (16, 300.0) if quick else (128, 8000.0)
    out: dict[str, Any] = {"systems": {}, "bounds": [], "paths": paths, "t_run": t_run,
                           "bound_rule": "|d| + 2 se(d) + the finest variant's neighbour differences (+ 2 se each), "
                                         "relative to the finest variant's value"}
    for i, (key, plan) in enumerate(PLANS.items()):
        h = Harvester.build(a=plan["a"], n=plan["n"])
        res = coupled(h, plan["fine"], plan["variants"], paths=paths, t_run=t_run, seed=4700 + i)
        rows = bounds(res, plan)
        out["bounds"] += rows
        out["systems"][key] = {k: v for k, v in res.items() if k != "per_path"}
        out["systems"][key]["neighbours"] = [list(p) for p in plan["neighbours"]]
    return out


def draw(res: dict[str, Any], axes: Any) -> None:
    """Relative difference from the finest variant against the step, per system and quantity."""
    for ax, (key, sysres) in zip(axes, res["systems"].items()):
        rows = [b for b in res["bounds"] if b["system"] == sysres["system"]]
        for q, mk in (("eta", "o"), ("V2", "s"), ("Pin", "^")):
            for w in sorted({b["w_trap"] for b in rows}):
                pts = [(b["step"], b["relative_difference_from_finest"][q]) for b in rows if b["w_trap"] == w]
                if len(pts) < 2:
                    continue
                ax.errorbar([p[0] for p in pts], [p[1]["minus_finest"] for p in pts],
                            yerr=[2 * p[1]["se"] for p in pts], fmt=mk + "-", ms=4, capsize=2,
                            label=f"{q}" + (f", w_trap {w:g}" if sysres["system"]["n"] == 1.0 else ""))
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("step h")
        ax.set_ylabel("relative difference from the finest variant (2 se bars)")
        ax.set_title(f"exact-flow Monte Carlo, n = {sysres['system']['n']:g}, a = {sysres['system']['a']:g}",
                     fontsize=9)
        ax.legend(fontsize=6)


def _plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(res["systems"]), figsize=(6 * len(res["systems"]), 4.2))
    draw(res, np.atleast_1d(axes))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
    """Run :func:`bias_study`; write ``exactflow_bias.json`` and ``.png`` into ``out``."""
    t0 = time.perf_counter()
    res = {"quick": quick, "command": COMMAND, **bias_study(quick)}
    res["wall_s"] = time.perf_counter() - t0
    save_benchmark(res, out, STEM, _plot)
    return res


if __name__ == "__main__":  # pragma: no cover
    bench_main(run, __doc__, drop=("systems",))
