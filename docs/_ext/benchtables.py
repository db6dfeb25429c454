"""Sphinx extension: accuracy and speed tables read from the benchmark data at build time.

``.. bench-table:: NAME`` (in Markdown: a ``{bench-table}`` fence) renders one table from the
JSON the benchmarks and the reference table write (``validation/data/*.json``), with the file
and the command that regenerates it under the table. Numbers are never copied by hand: rerun
the command, rebuild, and the page follows.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

#: A table: header, rows (cells are reStructuredText), data file, command that writes it.
Table = tuple[list[str], list[list[str]], str, str]


def _num(x: float | None, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}g}"


def _vrf(entry: dict[str, Any] | None) -> str:
    """The variance reduction of eta of one control set; "-" where the set does not apply."""
    return _num((entry or {}).get("vrf_eta"))


def _pm(value: float | None, err: float | None) -> str:
    if value is None:
        return "-"
    return f"{value:.7g} ± {err:.2g}" if err is not None else f"{value:.7g}"


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _references(d: dict[str, Any]) -> Table:
    from validation.references import reftable

    def state(name: str, e: dict[str, Any]) -> str:
        case = next((c for c in reftable.CASES if c.label == name), None)
        try:
            why = reftable.staleness(e, e["method"], case)
        except (RuntimeError, OSError):
            return "unknown (no git history)"
        return "current" if why is None else f"stale: {why}"

    rows = [[f"``{name}``", _pm(e["eta"], e["eta_err"]), e["status"], _num(e["seconds"]), f"``{e['commit']}``",
             state(name, e), f"``{e['command']}``"] for name, e in d.items()]
    return (["entry", "eta ± error", "status", "s", "commit", "state", "command"], rows,
            "validation/references/data/reference_values.json", "python -m validation.references.reftable")


def _exactflow_bias(d: dict[str, Any]) -> Table:
    rows = []
    for b in d["bounds"]:
        diff, bound = b["relative_difference_from_finest"], b["relative_bias_bound"]
        rows.append([f"n = {b['system']['n']:g}, a = {b['system']['a']:g}", f"{b['step']:g}",
                     f"{b['w_trap']:g}" if b["system"]["n"] == 1.0 else "-",
                     *(f"{diff[q]['minus_finest']:+.1e} ± {diff[q]['se']:.0e}" for q in ("eta", "V2", "Pin")),
                     *(f"{bound[q]:.1e}" for q in ("eta", "V2", "Pin"))])
    head = ["system", "step h", "w_trap", "eta minus finest", "V2 minus finest", "Pin minus finest",
            "bias bound eta", "V2", "Pin"]
    return head, rows, "exactflow_bias.json", "python -m validation.studies.kink.exactflow_bias --out validation/data"


def _fpe_time(d: dict[str, Any]) -> Table:
    rows = []
    for name, case in d["cases"].items():
        for tol, run in case["runs"].items():
            alg, ada = run["algebraic"], run["adaptive"]
            rows.append([name, tol, f"{alg['seconds']:.3g} ({alg['status']})", _num(alg["eta_err"], 2),
                         _num(alg.get("actual_err"), 2), _yes(alg.get("bounds_actual")),
                         f"{ada['seconds']:.3g} ({ada['status']})"])
    head = ["case", "tol", "s, default mesh", "reported error", "actual error", "bar holds",
            "s, adaptive mesh"]
    return head, rows, "bench_fpe_meshes.json", "python -m validation.studies.fpe.bench --meshes"


def _yes(flag: bool | None) -> str:
    return "-" if flag is None else ("yes" if flag else "**no**")


def _fpe_schemes(d: dict[str, Any]) -> Table:
    rows = []
    for name, c in d["cases"].items():
        mc = c.get("monte_carlo")
        rows.append([name, _num(c["tol"]), f"{c['x']['seconds']:.3g} ({c['x']['status']})",
                     _pm(c["x"]["eta"], c["x"]["eta_err"]), f"{c['xv']['seconds']:.3g} ({c['xv']['status']})",
                     _pm(c["xv"]["eta"], c["xv"]["eta_err"]), _yes(c["within_error_bars"]),
                     _pm(mc["eta"], mc["eta_err"]) if mc else "-"])
    head = ["case", "tol", "s, DG in x", "eta, DG in x", "s, DG in (x, v)", "eta, DG in (x, v)",
            "agree within bars", "eta, Monte Carlo"]
    return head, rows, "bench_fpe_schemes.json", "python -m validation.studies.fpe.bench --schemes"


def _mc_policy(d: dict[str, Any]) -> Table:
    rows = []
    for name, r in d["rows"].items():
        if not isinstance(r, dict):
            continue
        ex, ha = r["extrapolate"], r["halve"]
        rows.append([name, _pm(ex["eta"], ex["eta_err"]), _num(ex["cpu_s"]), _pm(ha["eta"], ha["eta_err"]),
                     _num(ha["cpu_s"]), _num(ha["dt"])])
    head = [f"case (tol {d['rows']['tol']:g})", "eta, extrapolation (opt-in)", "CPU s",
            "eta, halving rule (default)", "CPU s", "final dt"]
    return head, rows, "bench_montecarlo_policy.json", "python -m validation.studies.mc.policy (policy_rows)"


def _mc_policy_coverage(d: dict[str, Any]) -> Table:
    cov = d["coverage"]
    rows = []
    for name, c in cov.items():
        if not isinstance(c, dict) or "reference" not in c:
            continue
        for rule in ("extrapolate", "halve"):
            r = c[rule]
            rows.append([name, rule, _pm(c["reference"], c["reference_err"]), str(cov["seeds"]),
                         _pct(r["within_1"]), _pct(r["within_2"]), _num(r["max_abs_z"]),
                         _num(r["median_cpu_s"])])
    head = [f"case (tol {cov['tol']:g})", "time-step rule", "reference", "seeds", "within 1 error",
            "within 2 errors", "max abs z", "median CPU s"]
    return head, rows, "bench_montecarlo_policy.json", "python -m validation.studies.mc.policy (policy_coverage)"


def _mc_coverage(d: dict[str, Any]) -> Table:
    labels = {"harmonic_N2_vs_exact": "harmonic pair against the exact solver",
              "n3_N1_vs_fpe_extrapolated": "one n = 3 unit (extrapolated) against Fokker-Planck",
              "n3_N1_vs_fpe_solver_error": "one n = 3 unit (the solver's error) against Fokker-Planck"}
    rows = [[labels.get(k, k), str(c["seeds"]), _pct(c["within_1"]), _pct(c["within_2"]), _num(c["max_abs_z"])]
            for k, c in d.items() if isinstance(c, dict) and "seeds" in c]
    nominal = d["nominal"]
    rows.append(["nominal (Gaussian)", "-", _pct(nominal["within_1"]), _pct(nominal["within_2"]), "-"])
    return (["check", "seeds", "within 1 error", "within 2 errors", "max abs z"], rows,
            "bench_montecarlo_martingale_coverage.json",
            "python -m validation.studies.mc.martingale (martingale_coverage)")


_CONTROL_SETS = ("plain", "twin", "martingale", "both")


def _mc_controls(d: dict[str, Any]) -> Table:
    rows = []
    for name, r in d["rows"].items():
        cells = [name, r["confinement"]]
        cells += [_vrf(r.get(s)) for s in _CONTROL_SETS[1:]]
        cells += [_num(r.get(s, {}).get("time_to_1e-4_s")) for s in _CONTROL_SETS]
        rows.append(cells)
    head = ["case", "confinement", "variance reduction: twin", "martingale", "both",
            "s to 1e-4: plain", "twin", "martingale", "both"]
    return head, rows, "bench_montecarlo_martingale_rows.json", \
        "python -m validation.studies.mc.martingale (martingale_rows)"


def _mc_boundary(d: dict[str, Any]) -> Table:
    sets = ("twin", "martingale", "martingale+twin", "martingale+boundary", "martingale+boundary+twin")
    rows = [[name] + [_vrf(r.get(s)) for s in sets] + [_num(r["cpu_s"])]
            for name, r in d.items() if isinstance(r, dict)]
    return (["case"] + [f"variance reduction: {s}" for s in sets] + ["CPU s"], rows,
            "bench_montecarlo_boundary_rows.json", "python -m validation.studies.mc.boundary (boundary_rows)")


def _work_precision(d: dict[str, Any]) -> Table:
    from validation.studies import work_precision as wp

    head, rows = wp.summary_rows(d)
    return head, rows, f"{wp.STEM}.json", wp.COMMAND


#: Table name -> (JSON file, relative to the data folder, builder).
TABLES: dict[str, tuple[str, Callable[[dict[str, Any]], Table]]] = {
    "references": ("../references/data/reference_values.json", _references),
    "work-precision": ("work_precision.json", _work_precision),
    "fpe-time": ("bench_fpe_meshes.json", _fpe_time),
    "fpe-schemes": ("bench_fpe_schemes.json", _fpe_schemes),
    "mc-policy": ("bench_montecarlo_policy.json", _mc_policy),
    "mc-policy-coverage": ("bench_montecarlo_policy.json", _mc_policy_coverage),
    "mc-coverage": ("bench_montecarlo_martingale_coverage.json", _mc_coverage),
    "mc-controls": ("bench_montecarlo_martingale_rows.json", _mc_controls),
    "mc-boundary": ("bench_montecarlo_boundary_rows.json", _mc_boundary),
    "exactflow-bias": ("exactflow_bias.json", _exactflow_bias),
}


def _cell(text: str) -> nodes.Node:
    """One cell: ``code`` as a literal, **text** as strong, anything else as text."""
    if len(text) > 4 and text.startswith("``") and text.endswith("``"):
        return nodes.literal(text=text[2:-2])
    if len(text) > 4 and text.startswith("**") and text.endswith("**"):
        return nodes.strong(text=text[2:-2])
    return nodes.Text(text)


def _row(cells: list[str]) -> nodes.row:
    row = nodes.row()
    for cell in cells:
        row += nodes.entry("", nodes.paragraph("", "", _cell(cell)))
    return row


def table_node(head: list[str], rows: Iterable[list[str]]) -> nodes.table:
    """A docutils table (built as nodes, so it renders the same from Markdown and reST)."""
    group = nodes.tgroup(cols=len(head))
    group += [nodes.colspec(colwidth=1) for _ in head]
    group += nodes.thead("", _row(head))
    group += nodes.tbody("", *(_row(r) for r in rows))
    return nodes.table("", group)


class BenchTable(SphinxDirective):
    """``.. bench-table:: NAME``: one of :data:`TABLES`, from the current data."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        name = self.arguments[0]
        if name not in TABLES:
            raise self.error(f"unknown bench-table {name!r}; valid: {sorted(TABLES)}")
        filename, build = TABLES[name]
        path = Path(self.config.bench_data_dir) / filename
        self.env.note_dependency(str(path))
        head, rows, source, command = build(json.loads(path.read_text()))
        note = nodes.paragraph("", "", nodes.emphasis(text="Data: "), nodes.literal(text=source),
                               nodes.Text("; "), nodes.emphasis(text="regenerate: "), nodes.literal(text=command))
        return [nodes.container("", table_node(head, rows), note, classes=["bench-table"])]


class WorkPrecisionFigure(SphinxDirective):
    """``.. work-precision-figure::``: the work-precision diagrams drawn from the recorded data
    (:func:`validation.studies.work_precision.plot`) into ``_generated/`` at build time."""

    def run(self) -> list[nodes.Node]:
        from validation.studies import work_precision as wp

        data = Path(self.config.bench_data_dir) / f"{wp.STEM}.json"
        self.env.note_dependency(str(data))
        png = Path(self.env.srcdir) / "_generated" / f"{wp.STEM}.png"
        png.parent.mkdir(exist_ok=True)
        wp.plot(json.loads(data.read_text()), png)
        figure = nodes.figure("", nodes.image(uri=f"/_generated/{png.name}", alt="work-precision diagrams"),
                              nodes.caption(text=wp.CAPTION))
        return [figure]


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_config_value("bench_data_dir", "", "env")
    app.add_directive("bench-table", BenchTable)
    app.add_directive("work-precision-figure", WorkPrecisionFigure)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
