"""What a scene run produces: one :class:`SceneRow` per point and the :class:`SceneResult`
that holds them, with the readable table and the CSV writer.

Rows are plain values (point, status, method, message, requested observables with their
errors), so the figures (:mod:`.plotting`) and the runner (:mod:`.run`) both use them
without depending on each other.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..result import Status, to_frame
from .cache import atomic_path
from .spec import DERIVED, Scene

__all__ = ["ERROR", "NOT_AVAILABLE", "SceneResult", "SceneRow", "write_csv"]

#: Row statuses besides :class:`Status` values.
NOT_AVAILABLE = "not_available"
ERROR = "error"


@dataclass(frozen=True)
class SceneRow:
    """One point of a scene run.

    Attributes
    ----------
    index : int
        Position in the sweep.
    point : Mapping
        Values of the varied fields (sweep axes and, with ``optimize``, the optimum found).
    status : str
        A :class:`Status` value, or ``"not_available"`` (solver missing or unable) or
        ``"error"`` (solver failed); ``message`` says what happened.
    method : str
        Solver used (``"exact"``, ``"fpe"``, ``"mc"``; ``""`` when no solver was needed).
    values : Mapping
        Requested observables and their errors (``name`` and ``name_err``); ``None`` where
        the point has no value.
    info : Mapping
        Bookkeeping: cache key, seed, whether the point was reused, optimization details.
    """

    index: int
    point: Mapping[str, float]
    status: str
    method: str
    message: str
    values: Mapping[str, float | None]
    info: Mapping[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the values describe a stationary state (stable or marginal)."""
        return self.status in (Status.STABLE.value, Status.MARGINAL.value)

    def get(self, name: str) -> float | None:
        """Value of a varied field or an observable."""
        if name in self.point:
            return self.point[name]
        return self.values.get(name)

    def to_dict(self) -> dict[str, Any]:
        """Flat JSON-ready dict (point, values, status, method, message, info)."""
        return {"index": self.index, **self.point, **self.values, "status": self.status,
                "method": self.method, "message": self.message, "info": dict(self.info)}


@dataclass(frozen=True)
class SceneResult:
    """What :func:`run_scene` produced.

    Attributes
    ----------
    scene : Scene
        The scene actually run (the quick variant in quick mode).
    rows : tuple of SceneRow
    out_dir : Path
    figures : Mapping of figure name to PNG path
    csv_path, json_path, table_path : Path or None
        Written outputs (``None`` when not requested).
    computed, reused : int
        Solver results computed in this run / taken from the cache.
    elapsed : float
        Wall time in seconds.
    cache_skipped : int
        Lines of the point cache that could not be used (partial, garbled or invalid; see
        :mod:`.cache`): their points were computed again.
    """

    scene: Scene
    rows: tuple[SceneRow, ...]
    out_dir: Path
    figures: Mapping[str, Path]
    csv_path: Path | None
    json_path: Path | None
    table_path: Path | None
    computed: int
    reused: int
    elapsed: float
    cache_skipped: int = 0

    @property
    def columns(self) -> list[str]:
        varied = list(dict.fromkeys(key for row in self.rows for key in row.point))
        return varied + list(self.scene.observables)

    def table(self) -> str:
        """Readable fixed-width table of the points (value ± error, status, method)."""
        header = [*self.columns, "status", "method"]
        lines = []
        for row in self.rows:
            cells = [_fmt(row.point.get(c)) for c in self.columns if c in row.point]
            for obs in self.scene.observables:
                val, err = row.values.get(obs), row.values.get(obs + "_err")
                cells.append(_fmt(val) + (f" ± {err:.2g}" if val is not None and err else ""))
            lines.append([*cells, row.status, row.method or "-"])
        widths = [max(len(r[i]) for r in (header, *lines)) for i in range(len(header))]
        out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)),
               "  ".join("-" * w for w in widths)]
        out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in lines]
        by_message: dict[tuple[str, str], list[str]] = {}
        for row in self.rows:
            if not row.ok:
                by_message.setdefault((row.status, row.message), []).append(str(row.index))
        notes = [f"points {', '.join(idx)}: " + (msg if msg.startswith(status) else f"{status}: {msg}")
                 for (status, msg), idx in by_message.items()]
        return "\n".join(out + (["", "notes:", *notes] if notes else []))

    def records(self) -> list[dict[str, Any]]:
        """One flat dict per row: ``index``, the varied fields, the observables and their errors,
        ``status``, ``method`` and ``message`` (what the CSV holds)."""
        return [{key: value for key, value in row.to_dict().items() if key != "info"} for row in self.rows]

    def to_frame(self) -> Any:
        """The :meth:`records` as a ``pandas.DataFrame`` (needs the optional pandas: ``pip install
        "fpe-harvester[pandas]"``); missing values are NaN there."""
        return to_frame(self.records())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary with every row."""
        return {
            "scene": self.scene.name, "title": self.scene.title,
            "description": self.scene.description, "rtol": self.scene.rtol,
            "method": self.scene.method, "observables": list(self.scene.observables),
            "system": self.scene.system.to_dict(), "spec": self.scene.to_dict(),
            "computed": self.computed, "reused": self.reused, "elapsed_s": self.elapsed,
            "cache_skipped": self.cache_skipped,
            "figures": {k: str(v) for k, v in self.figures.items()},
            "rows": [row.to_dict() for row in self.rows],
        }


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, (int, np.integer)):
        return str(value)
    return f"{value:.6g}"


def write_csv(result: SceneResult, path: Path) -> Path:
    """Write the rows of ``result`` to ``path`` as CSV (each observable with its error column).

    The file is replaced atomically (:func:`.cache.atomic_path`): a concurrent reader never
    sees a partial table."""
    cols = result.columns
    obs = [c for c in cols if c in result.scene.observables]
    header = [c for c in cols if c not in obs]
    for o in obs:
        header += [o] if o in DERIVED else [o, o + "_err"]
    header += ["status", "method", "message"]
    with atomic_path(path) as tmp, tmp.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(header)
        for row in result.rows:
            d = row.to_dict()
            writer.writerow(["" if d.get(c) is None else d.get(c) for c in header])
    return path
