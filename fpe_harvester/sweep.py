"""A sweep over parameter grids in one call, returning a table with the parameters beside the
results: ``sweep(h, {"k": ks, "a": [0.5, 1.0]}, tol=1e-3).to_frame()``.

Points are the outer product of the axes (the first outermost), each the base harvester with the
axis values substituted; they are solved by :func:`~fpe_harvester.solve.solve_many` (so the
exact points of a sweep are one vectorized call, and every setting of :func:`solve` applies).
For sweeps that must survive an interruption, draw figures or run on a cluster, use a scene
(:func:`~fpe_harvester.scenes.run_scene`).
"""

from __future__ import annotations

import itertools
import json
import sys
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from .errors import ParameterError
from .model import Harvester, Params
from .result import QUANTITIES, Stats, jsonable, to_frame
from .solve import FALLBACK_SECONDS, Solver, solve_many

__all__ = ["AXES", "Sweep", "sweep"]

#: Names a sweep may vary: the potential, the ring and its couplings, every physical parameter.
AXES = ("a", "n", "N", "k", "k4", "k3", *(f for f in Params.__dataclass_fields__))


@dataclass(frozen=True)
class Sweep:
    """The results of :func:`sweep`: one :class:`~fpe_harvester.result.Stats` per point.

    Attributes
    ----------
    axes : tuple of str
        The varied parameters, in sweep order.
    points : tuple of Mapping
        The axis values of each point.
    results : tuple of Stats
        The result of each point (its ``harvester`` is the point's system).
    """

    axes: tuple[str, ...]
    points: tuple[Mapping[str, float], ...]
    results: tuple[Stats, ...]

    def __len__(self) -> int:
        return len(self.results)

    def __iter__(self) -> Iterator[tuple[Mapping[str, float], Stats]]:
        return iter(zip(self.points, self.results))

    def records(self) -> list[dict[str, Any]]:
        """One flat dict per point: the varied parameters, the other parameters, each quantity
        and its error, ``status``, ``method`` and ``message``."""
        out = []
        for point, res in self:
            rec = res.to_record()
            out.append({**point, **{k: v for k, v in rec.items() if k not in point}})
        return out

    def column(self, name: str) -> np.ma.MaskedArray:
        """A parameter or quantity over the points, masked where a point has no value (e.g.
        ``eta`` beyond the stability threshold)."""
        if name not in (*AXES, *QUANTITIES, *(q + "_err" for q in QUANTITIES)):
            raise ParameterError(f"column must be a parameter or a quantity (or its _err), got {name!r}")
        values = [rec[name] for rec in self.records()]
        return np.ma.masked_invalid(np.array([np.nan if v is None else v for v in values], dtype=float))

    def to_frame(self) -> Any:
        """The :meth:`records` as a ``pandas.DataFrame``, the varied parameters first (needs the
        optional pandas: ``pip install "fpe-harvester[pandas]"``)."""
        return to_frame(self.records())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the axes and one row per point (its record and the solver's ``info``)."""
        rows = [{**rec, "info": jsonable(dict(res.info))} for rec, res in zip(self.records(), self.results)]
        return {"axes": list(self.axes), "rows": rows}

    def table(self) -> str:
        """Readable table: the varied parameters, eta with its error, the status and the solver."""
        header = [*self.axes, "eta", "status", "method"]
        lines = []
        for point, res in self:
            eta = "-" if res.eta is None else f"{res.eta:.6g}" + ("" if not res.eta_err else f" ± {res.eta_err:.2g}")
            lines.append([*(f"{point[a]:.6g}" for a in self.axes), eta, res.status.value, res.method])
        widths = [max(len(r[i]) for r in (header, *lines)) for i in range(len(header))]
        out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)), "  ".join("-" * w for w in widths)]
        return "\n".join(out + ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in lines])

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text."""
        return json.dumps(self.to_dict(), indent=1)


def _axes(grid: Mapping[str, Any]) -> dict[str, tuple[float, ...]]:
    if not isinstance(grid, Mapping) or not grid:
        raise ParameterError(f"grid must map parameter names to lists of values, got {grid!r}")
    out = {}
    for name, values in grid.items():
        if name not in AXES:
            raise ParameterError(f"grid: {name!r} is not a parameter; valid: {', '.join(AXES)}")
        vals = np.atleast_1d(np.asarray(values, dtype=object))
        if vals.ndim != 1 or vals.size == 0:
            raise ParameterError(f"grid[{name!r}] must be a non-empty list of numbers, got {values!r}")
        out[name] = tuple(vals.tolist())
    return out


def sweep(h: Harvester, grid: Mapping[str, Sequence[float]], method: str | Solver = "auto", *,
          progress: bool | None = None, fallback_time: float | None = FALLBACK_SECONDS,
          solver_options: Mapping[str, Mapping[str, Any]] | None = None, **settings: Any) -> Sweep:
    """Solve ``h`` at every point of a parameter grid; a table with the parameters beside the results.

    Parameters
    ----------
    h : Harvester
        The base system; each point replaces the fields named in ``grid``.
    grid : mapping of parameter name to values
        The axes (names from :data:`AXES`: ``a, n, N, k, k4, k3`` or a :class:`Params` field),
        combined as an outer product, the first axis outermost.
    method : str or solver object
        As :func:`~fpe_harvester.solve.solve` (default ``"auto"``: per point).
    progress : bool or None
        A bar over points on stderr (``None``: only on a terminal); the points' own solvers
        draw none.
    fallback_time, solver_options, **settings
        As :func:`~fpe_harvester.solve.solve` (``tol``, ``seed``, ``max_time``, solver options).

    Returns
    -------
    Sweep
        ``to_frame()`` gives a ``pandas.DataFrame``, ``records()`` the rows as dicts,
        ``column(name)`` one column as an array.

    Raises
    ------
    ParameterError
        An unknown axis, an invalid point (named with its values) or setting, before any point
        is computed.

    Examples
    --------
    >>> s = sweep(Harvester.build(a=0.5, n=2, N=3), {"a": [0.5, 1.0], "k": [-0.3, 0.0]})
    >>> [round(float(e), 6) for e in s.column("eta")]
    [0.655421, 0.512821, 0.467219, 0.392157]
    >>> s.records()[0]["a"], s.records()[0]["k"], s.records()[0]["status"]
    (0.5, -0.3, 'stable')
    """
    if not isinstance(h, Harvester):
        raise ParameterError(f"h must be a Harvester, got {h!r} (type {type(h).__name__})")
    axes = _axes(grid)
    points = [dict(zip(axes, combo)) for combo in itertools.product(*axes.values())]
    hs = []
    for point in points:
        try:
            hs.append(h.replace(**point))
        except ParameterError as exc:
            where = ", ".join(f"{k} = {v!r}" for k, v in point.items())
            raise ParameterError(f"sweep point ({where}): {exc}") from None
    from tqdm import tqdm

    with tqdm(total=len(hs), desc="sweep", unit="pt", file=sys.stderr, leave=False,
              disable=None if progress is None else not progress) as bar:
        results = solve_many(hs, method, fallback_time=fallback_time, solver_options=solver_options,
                             on_result=lambda i, r: bar.update(1), progress=False, **settings)
    return Sweep(tuple(axes), tuple(MappingProxyType({k: _plain(v) for k, v in p.items()}) for p in points),
                 tuple(results))


def _plain(value: Any) -> Any:
    return value.item() if hasattr(value, "item") else value

