"""The stationary identities (docs/model.md §2) on every result computed in the run.

Every solver's result for a stationary state must satisfy

.. math::

    \\langle V^2\\rangle = K_c\\tau_p\\langle vV\\rangle,\\qquad
    P_{in} = m\\gamma\\langle v^2\\rangle + K_v\\langle vV\\rangle

(:math:`d\\langle V^2\\rangle/dt = 0` and the power balance) within its own errors. The section
runs last (:data:`validation.sections.SECTIONS`): it checks what the other sections solved,
read from the run's solve cache, and lists every result in one table.
"""

from __future__ import annotations

import math

from fpe_harvester.model import Harvester, Params
from fpe_harvester.result import Stats, Status
from fpe_harvester.solve import METHODS

from ..harness.checks import CheckResult, Context, agree, expect, guarded, skipped
from ..harness.report import Section, Table

__all__ = ["run", "identity_checks", "describe", "results_table"]

_SECTION = "Stationary identities"


def identity_checks(label: str, r: Stats, h: Harvester, section: str = _SECTION) -> list[CheckResult]:
    """The two stationary identities (docs/model.md §2) on one result, within its errors.

    A result that lacks ``vV`` or ``v2`` fails: the identities are every solver's self-check.
    """
    p = h.params
    floor = 1e-12 if r.method == "exact" else 0.0
    if r.vV is None or r.v2 is None or r.V2 is None or r.Pin is None:
        return [expect(f"identities [{r.method}] {label}", section, False,
                       f"result lacks V2/Pin/vV/v2 (V2={r.V2}, Pin={r.Pin}, vV={r.vV}, v2={r.v2}); "
                       f"status {r.status.value}")]
    e = lambda x: 0.0 if x is None else x  # noqa: E731
    rhs1 = p.Kc * p.tau_p * r.vV
    rhs1_err = p.Kc * p.tau_p * e(r.vV_err)
    rhs2 = p.m * p.gamma * r.v2 + p.Kv * r.vV
    rhs2_err = math.hypot(p.m * p.gamma * e(r.v2_err), p.Kv * e(r.vV_err))
    return [
        agree(f"identities [{r.method}] {label}: V2 = Kc tau_p vV", section, r.V2, r.V2_err, rhs1, rhs1_err,
              rel_floor=floor),
        agree(f"identities [{r.method}] {label}: Pin = m gamma v2 + Kv vV", section, r.Pin, r.Pin_err, rhs2,
              rhs2_err, rel_floor=floor),
    ]


def run(ctx: Context) -> Section:
    """The identities on every result of the run that describes a stationary state, and the
    table of every result; a solver that produced no result is a skipped check."""
    sec = Section("identities", "Stationary identities, docs/model.md §2 (every solver, every result of this run)")
    sec.text.append(
        "For every result computed in this run that describes a stationary state (stable, marginal, "
        "not converged with its best estimate and error, or metastable with no escaped path): V2 = Kc tau_p vV (d<V^2>/dt = 0) and "
        "Pin = m gamma v2 + Kv vV (power balance), each within 4 combined error bars of the "
        "result's own errors (exact: relative floor 1e-12)."
    )
    excluded = []
    for h, method, r in ctx.cache.results():
        escaped = r.info.get("escape_fraction") != 0
        if r.status is Status.UNSTABLE or (r.status is Status.METASTABLE and escaped) or r.V2 is None:
            # No stationary state (a metastable one that no path left counts as quasi-stationary):
            # the identities are properties of a stationary state, so they do not apply.
            excluded.append(f"{method} at {describe(h)} ({r.status.value})")
            continue
        label = describe(h) + (f", {r.status.value}" if not r.ok else "")
        sec.checks += guarded(f"identities [{method}] {label}", sec.title,
                              lambda h=h, r=r, label=label: identity_checks(label, r, h, sec.title))
    if excluded:
        sec.text.append("Not checked (no stationary state, so the identities do not apply): "
                        + "; ".join(excluded) + ".")
    sec.tables.append(results_table(ctx))
    methods = {m for _, m, _ in ctx.cache.results()}
    sec.checks += [skipped(f"identities [{m}]", sec.title, f"no {m!r} result was computed in this run "
                           "(solver not available)") for m in METHODS if m not in methods]
    return sec


def _fmt(v: float | None, e: float | None) -> str:
    if v is None:
        return "-"
    return f"{v:.6g}" if not e else f"{v:.6g} +- {e:.2g}"


def describe(h: Harvester) -> str:
    """Short label of a harvester: a, n, N, k and the parameters that differ from the defaults."""
    base = Params().to_dict()
    extra = ", ".join(f"{k}={v:g}" for k, v in h.params.to_dict().items() if v != base[k])
    return f"a={h.a:g}, n={h.n:g}, N={h.N}, k={h.k:.6g}" + (f", {extra}" if extra else "")


def results_table(ctx: Context) -> Table:
    """Every result solved in this run, with its status, errors and solver time."""
    rows = []
    for h, method, r in ctx.cache.results():
        t = r.info.get("wall_time", r.info.get("seconds"))
        rows.append((describe(h), method, r.status.value, _fmt(*r.value("eta")), _fmt(*r.value("V2")),
                     _fmt(*r.value("Pin")), f"{t:.3g}" if isinstance(t, (int, float)) else "-"))
    return Table("Every result computed in this run", ("system", "method", "status", "eta", "V2", "Pin",
                                                       "solver time [s]"), rows)
