"""Study: the bias of the exact-flow Monte Carlo (:mod:`validation.references.exactflow`) against
its step and its trap threshold, on common noise.

The construction is exact between force events; what remains is the step's bias: for n = 1 the
crossing times (located on the conditional-mean path), the trap threshold ``w_trap`` (units held
at rest below it) and the release from rest at a step's end; for n = 1.25 the discrete-gradient
force. Every variant of a system runs on the same Brownian path (:func:`~validation.references.
exactflow.coupled`), so the paired differences from the finest variant measure the bias at a small
fraction of the cost of independent runs.

A setting's **bias bound** per quantity, relative to its value, comes from a model of the bias
that vanishes with the knobs, fitted to all the paired differences at once: for n = 1,
:math:`b(h, w) = c_h h + c_w w` (first order in the step and in ``w_trap``, the slowest a bias of
either can vanish), for n > 1 :math:`b(h) = c_1 h + c_2 h^2`. The coefficients are fitted by
generalised least squares to the variants' differences from the finest, with their covariance over
the paths (they share the finest variant); a fit worse than its degrees of freedom inflates the
covariance by :math:`\\chi^2/\\mathrm{dof}`. The bound at a setting is
:math:`|\\hat b| + 2\\,\\mathrm{se}(\\hat b)`: the fitted bias and two of its standard errors,
the finest variant's own bias included (the model extrapolates to zero knobs).
:func:`validation.references.exactflow.solve_flow` adds the bound of its setting to its errors.

``python -m validation.studies.kink.exactflow_bias [--quick] [--out validation/data]`` writes
``exactflow_bias.json`` and ``exactflow_bias.png``.
"""

from __future__ import annotations

import math
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
COMMAND = "python -m validation.studies.kink.exactflow_bias --out validation/data"

#: Per system: (n, a), the fine step and the variants (the finest first).
PLANS: dict[str, dict[str, Any]] = {
    "n1_a2": {"n": 1.0, "a": 2.0, "fine": 0.0025,
              "variants": (Variant(1, 0.001), Variant(2, 0.001), Variant(4, 0.001), Variant(8, 0.001),
                           Variant(4, 0.003), Variant(4, 0.01), Variant(8, 0.003), Variant(8, 0.01))},
    "n1.25_a2": {"n": 1.25, "a": 2.0, "fine": 0.0025,
                 "variants": (Variant(1, 0.0), Variant(2, 0.0), Variant(4, 0.0), Variant(8, 0.0),
                              Variant(16, 0.0))},
}

_QUANTITIES = ("eta", "V2", "Pin", "v2", "vV")


def _features(n: float, step: float, w_trap: float) -> np.ndarray:
    """The bias model's terms at a setting (see the module docstring)."""
    return np.array([step, w_trap]) if n == 1.0 else np.array([step, step * step])


def bounds(res: dict[str, Any]) -> list[dict[str, Any]]:
    """The bias bound of every variant's setting (see the module docstring), per quantity, relative
    to the finest variant's value, with the fitted model and the measured differences."""
    n = res["system"]["n"]
    X = np.array([_features(n, v["step"], v["w_trap"]) for v in res["variants"]])
    A = X[1:] - X[0]                                            # differences from the finest
    fits = {}
    for q in _QUANTITIES:
        paths = res["per_path"][q]
        D = paths[:, 1:] - paths[:, :1]                         # (paths, variants - 1)
        d, S = D.mean(axis=0), np.cov(D, rowvar=False) / D.shape[0]
        Si = np.linalg.inv(S)
        cov = np.linalg.inv(A.T @ Si @ A)
        c = cov @ A.T @ Si @ d
        chi2 = float((d - A @ c) @ Si @ (d - A @ c))
        dof = max(A.shape[0] - A.shape[1], 1)
        cov = cov * max(1.0, chi2 / dof)
        fits[q] = (c, cov, chi2, dof, abs(res["variants"][0]["estimates"][q][0]))
    rows = []
    for j, v in enumerate(res["variants"]):
        x = X[j]
        rel, measured, model = {}, {}, {}
        for q, (c, cov, chi2, dof, scale) in fits.items():
            b, se = float(x @ c), float(math.sqrt(x @ cov @ x))
            rel[q] = (abs(b) + 2.0 * se) / scale
            dq, dse = difference(res, j, 0, q) if j else (0.0, 0.0)
            measured[q] = {"minus_finest": dq / scale, "se": dse / scale}
            model[q] = {"bias": b / scale, "se": se / scale, "chi2": chi2, "dof": dof}
        rows.append({"system": dict(res["system"]), "step": v["step"], "w_trap": v["w_trap"],
                     "relative_bias_bound": rel, "relative_difference_from_finest": measured,
                     "model": model})
    return rows


def bias_study(quick: bool) -> dict[str, Any]:
    """Every system of :data:`PLANS`: the coupled variants, their differences and the bounds."""
    paths, t_run = (16, 300.0) if quick else (128, 8000.0)
    out: dict[str, Any] = {"systems": {}, "bounds": [], "paths": paths, "t_run": t_run,
                           "bound_rule": "|b| + 2 se(b), b the bias fitted (GLS over the paired differences, "
                                         "covariance inflated by chi2/dof when above 1) by c_h h + c_w w_trap "
                                         "(n = 1) or c_1 h + c_2 h^2 (n > 1), relative to the finest "
                                         "variant's value"}
    for i, (key, plan) in enumerate(PLANS.items()):
        h = Harvester.build(a=plan["a"], n=plan["n"])
        res = coupled(h, plan["fine"], plan["variants"], paths=paths, t_run=t_run, seed=4700 + i)
        rows = bounds(res)
        out["bounds"] += rows
        out["systems"][key] = {k: v for k, v in res.items() if k != "per_path"}
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
