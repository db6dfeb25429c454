"""Figures of scene runs (matplotlib, imported only when a figure is drawn).

Each figure has one panel per requested ``y`` and one curve per value of the ``series``
field. Points are drawn by status so that nothing is hidden or silently dropped:

* stable: filled markers joined by a line, with error bars when the method has them;
* marginal (at the threshold, finite limit): filled diamond;
* metastable (no path escaped) or not converged (values with a caveat): open markers with
  error bars;
* unstable, failed, not available (no value) or metastable with escaped paths (averages
  over the time before escape, not stationary values): a marker on the bottom edge of the
  panel, counted in a note under the figure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..exact import k_di
from .result import SceneRow
from .spec import AXIS_NAMES, FigureSpec, Scene

__all__ = ["draw_figure", "LABELS"]

#: Axis labels by field name.
LABELS = {
    "eta": r"efficiency $\eta$", "V2": r"$\langle V^2\rangle$", "Vrms": r"$V_{rms}$",
    "Pin": r"$P_{in}$", "v2": r"$\langle v^2\rangle$", "vV": r"$\langle vV\rangle$",
    "x2": r"$\langle x^2\rangle$", "k_di": r"threshold $k_{di}$", "k": "coupling $k$",
    "a": "potential strength $a$", "n": "exponent $n$", "N": "number of units $N$",
}
_OPEN = ("metastable", "not_converged")
_EDGE = {"unstable": ("v", "no stationary state"), "escaped": ("^", "escaped (metastable, paths left)"),
         "error": ("x", "solver failed"), "not_available": ("s", "solver not available")}


def _escaped(row: SceneRow) -> bool:
    """Metastable point where some paths escaped: its averages are not stationary values."""
    return row.status == "metastable" and (row.info.get("escape_fraction") or 0.0) > 0.0


def _edge_status(row: SceneRow) -> str:
    return "escaped" if _escaped(row) else row.status


def _selected(rows: Sequence[SceneRow], spec: FigureSpec) -> list[SceneRow]:
    def keep(row: SceneRow) -> bool:
        return all(row.point.get(key) is not None and math.isclose(row.point[key], val, rel_tol=1e-9,
                                                                   abs_tol=1e-12)
                   for key, val in spec.select.items())
    return [row for row in rows if keep(row)]


def _series(rows: Sequence[SceneRow], spec: FigureSpec) -> dict[Any, list[SceneRow]]:
    groups: dict[Any, list[SceneRow]] = {}
    for row in rows:
        groups.setdefault(row.point.get(spec.series) if spec.series else None, []).append(row)
    for key in groups:
        groups[key] = sorted(groups[key],
                             key=lambda r: (r.point.get(spec.x) is None, r.point.get(spec.x) or 0))
    return groups


def _threshold(scene: Scene, row: SceneRow) -> float | None:
    fixed = {k: v for k, v in row.point.items() if k in AXIS_NAMES and k != "k" and v is not None}
    h = scene.harvester(fixed)
    return k_di(h.N, h.a, h.k4)


def _normalized(scene: Scene, row: SceneRow, x: str) -> SceneRow:
    from dataclasses import replace

    kd = _threshold(scene, row)
    value = row.point.get(x)
    scaled = None if kd is None or value is None else value / abs(kd)
    return replace(row, point={**row.point, x: scaled})


def draw_figure(scene: Scene, spec: FigureSpec, rows: Sequence[SceneRow], path: Path) -> Path:
    """Draw one figure of a scene run to ``path`` (PNG); return the path.

    Parameters
    ----------
    scene : Scene
        The scene that was run (for labels and thresholds).
    spec : FigureSpec
        What to draw.
    rows : sequence of SceneRow
        The run's points.
    path : Path
        Output file.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.transforms import blended_transform_factory

    if spec.kind == "map":
        return _draw_map(scene, spec, _selected(rows, spec), path)
    rows = _selected(rows, spec)
    if spec.xnorm:
        rows = [_normalized(scene, row, spec.x) for row in rows]
    groups = _series(rows, spec)
    ncol = len(spec.y)
    fig, axes = plt.subplots(1, ncol, figsize=(4.8 * ncol, 3.9), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    counts: dict[str, int] = {}
    for panel, (ax, y) in enumerate(zip(axes[0], spec.y)):
        edge = blended_transform_factory(ax.transData, ax.transAxes)
        for s, (sval, srows) in enumerate(groups.items()):
            color = colors[s % len(colors)]
            label = f"{spec.series} = {sval:g}" if spec.series else None
            ok = [(r.point[spec.x], r.get(y), r.values.get(y + "_err"), r.status) for r in srows
                  if r.ok and r.get(y) is not None and r.point.get(spec.x) is not None]
            caveat = [(r.point[spec.x], r.get(y), r.values.get(y + "_err")) for r in srows
                      if r.status in _OPEN and r.get(y) is not None and not _escaped(r)]
            if ok:
                xs, ys, es, st = zip(*ok)
                ax.plot(xs, ys, "-o", color=color, ms=3.5, label=label)
                label = None
                if spec.errorbars and any(e for e in es):
                    ax.errorbar(xs, ys, yerr=[e or 0.0 for e in es], fmt="none", ecolor=color, capsize=2)
                marg = [(x, v) for x, v, _, t in ok if t == "marginal"]
                if marg:
                    ax.plot(*zip(*marg), "D", color=color, ms=6, mfc="none")
            if caveat:
                xs, ys, es = zip(*caveat)
                ax.errorbar(xs, ys, yerr=[e or 0.0 for e in es] if spec.errorbars else None, fmt="o",
                            mfc="none", color=color, capsize=2, label=label)
            for status, (marker, _) in _EDGE.items():
                bad = [r.point[spec.x] for r in srows
                       if _edge_status(r) == status and r.point.get(spec.x) is not None]
                if bad:
                    # one row per series so that coinciding x values stay visible
                    ax.plot(bad, [0.02 + 0.03 * s] * len(bad), marker, color=color, mfc="none", ms=5,
                            transform=edge, clip_on=False)
                    if panel == 0:
                        counts[status] = counts.get(status, 0) + len(bad)
            for ref in spec.refs:
                if ref.kind == "vline" and ref.x == "k_di" and spec.x == "k" and srows:
                    kd = _threshold(scene, srows[0])
                    if kd is not None and spec.xnorm:
                        kd = -1.0
                    if kd is not None:
                        ax.axvline(kd, ls="--", lw=0.9, color=color,
                                   label=(ref.label or "$k_{di}$") if s == 0 and panel == 0 else None)
        for ref in spec.refs:
            on_panel = ref.panel == y or (ref.panel is None and (ref.kind != "point" or y == "eta"
                                                                  or "eta" not in spec.y))
            if not on_panel or ref.x == "k_di":
                continue
            if ref.kind == "vline":
                ax.axvline(ref.x, ls=":", color="k", lw=0.9, label=ref.label or None)
            elif ref.kind == "hline":
                ax.axhline(ref.y, ls=":", color="k", lw=0.9, label=ref.label or None)
            else:
                ax.plot([ref.x], [ref.y], "*", color="k", ms=11, label=ref.label or None, zorder=5)
        ax.set_xlabel(r"$k/|k_{di}|$" if spec.xnorm else LABELS.get(spec.x, spec.x))
        ax.set_ylabel(LABELS.get(y, y))
        if spec.logx:
            ax.set_xscale("log")
        if spec.logy:
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    notes = [f"{n} point(s) {_EDGE[s][1]} ({_EDGE[s][0]!r} on the bottom edge)" for s, n in counts.items()]
    title = spec.title or scene.title or scene.name
    fig.suptitle(title, fontsize=10)
    if notes:
        fig.text(0.01, 0.01, "; ".join(notes), fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.04 if notes else 0, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _edges(values: Sequence[float], log: bool) -> list[float]:
    """Cell edges around sorted centres (geometric midpoints on a log axis)."""
    import numpy as np

    v = np.log(values) if log else np.asarray(values, dtype=float)
    if len(v) == 1:
        mid, half = float(v[0]), 0.5 if not log else 0.1
        e = np.array([mid - half, mid + half])
    else:
        inner = 0.5 * (v[1:] + v[:-1])
        e = np.concatenate([[2 * v[0] - inner[0]], inner, [2 * v[-1] - inner[-1]]])
    return list(np.exp(e) if log else e)


def _draw_map(scene: Scene, spec: FigureSpec, rows: Sequence[SceneRow], path: Path) -> Path:
    """Colour maps of ``spec.y`` over (``x``, ``series``); cells without a value are grey."""
    import matplotlib.pyplot as plt
    import numpy as np

    xs = sorted({r.point[spec.x] for r in rows if r.point.get(spec.x) is not None})
    ys = sorted({r.point[spec.series] for r in rows if r.point.get(spec.series) is not None})
    ncol = len(spec.y)
    fig, axes = plt.subplots(1, ncol, figsize=(5.2 * ncol, 4.0), squeeze=False)
    missing = 0
    for ax, obs in zip(axes[0], spec.y):
        z = np.ma.masked_all((len(ys), len(xs)))
        for r in rows:
            val = r.get(obs)
            if r.ok and val is not None and r.point.get(spec.x) in xs and r.point.get(spec.series) in ys:
                z[ys.index(r.point[spec.series]), xs.index(r.point[spec.x])] = val
        missing = max(missing, int(np.ma.count_masked(z)))
        ax.set_facecolor("0.85")
        mesh = ax.pcolormesh(_edges(xs, spec.logx), _edges(ys, spec.logy), z, shading="flat")
        fig.colorbar(mesh, ax=ax, label=LABELS.get(obs, obs))
        ax.set_xlabel(LABELS.get(spec.x, spec.x))
        ax.set_ylabel(LABELS.get(spec.series or "", spec.series))
        if spec.logx:
            ax.set_xscale("log")
        if spec.logy:
            ax.set_yscale("log")
    fig.suptitle(spec.title or scene.title or scene.name, fontsize=10)
    if missing:
        fig.text(0.01, 0.01, f"{missing} cell(s) without a value (grey): unstable, failed or not "
                 "available; see the table", fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.04 if missing else 0, 1, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
