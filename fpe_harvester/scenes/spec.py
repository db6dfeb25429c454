"""Scenes: declarative studies (systems, sweep axes, observables, accuracy, outputs).

A scene says *what* to compute and draw; :mod:`.run` decides *how* (cheapest
adequate solver per point, cache, resume). Scenes come from TOML files or are built in
Python from the frozen dataclasses below. A minimal TOML scene::

    name = "eta_vs_k"
    observables = ["eta", "Vrms"]
    rtol = 1e-3                      # wanted relative accuracy on eta
    method = "auto"                  # or "exact", "fpe", "mc"

    [system]                         # the base harvester; axes vary its fields
    a = 0.5
    n = 2
    N = 3
    params = { tau_p = 2.0 }

    [axes]                           # outer product, first axis outermost
    a = [0.5, 1.0]
    k = { linspace = [1.0, 0.0, 21], unit = "k_di" }   # multiples of k_di(N, a)

    [[figures]]
    name = "eta_vs_k"
    x = "k"
    y = ["eta"]
    series = "a"
    refs = [{ vline = "k_di" }, { point = [-0.33, 0.677], label = "paper" }]

    [quick]                          # reduced variant for run_scene(..., quick=True)
    rtol = 0.05
    axes = { k = { linspace = [1.0, 0.0, 5], unit = "k_di" } }

Optional tables: ``[options.fpe]`` / ``[options.mc]`` (solver settings), ``[optimize]``
(``maximize = "eta"``, ``over = "k"``, ``bounds = ["k_di", 0.0]``, ``points = 41``:
each point of the other axes becomes the optimum over ``over``), ``outputs = ["table",
"csv", "json"]``. ``[system]`` is required and not empty. Every table, key, type and default:
the docs page ``scene-format`` (docs/scene-format.md).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ..errors import MethodNotAvailableError, ParameterError, check_choice, check_int, check_real
from ..exact import k_di
from ..model import Harvester, Params
from ..result import QUANTITIES
from ..solve import get_solver
from ..solvers import METHODS

__all__ = [
    "DERIVED",
    "AXIS_NAMES",
    "Axis",
    "Optimize",
    "Ref",
    "FigureSpec",
    "Scene",
    "load_scene",
    "list_scenes",
    "scene_from_dict",
    "SCENE_DIR",
]

#: Quantities computed in closed form without a solver.
DERIVED = ("k_di",)
_PARAMS = tuple(f.name for f in dataclasses.fields(Params))
#: Names a sweep axis (or the optimization variable) may vary.
AXIS_NAMES = ("a", "n", "N", "k", *_PARAMS)
OUTPUTS = ("table", "csv", "json")
#: Folder of the shipped scene files.
SCENE_DIR = Path(__file__).with_name("data")

_SPACINGS = ("values", "linspace", "logspace", "integers")


def _bad(where: str, value: Any, valid: str) -> ParameterError:
    return ParameterError(f"{where}: invalid value {value!r} (type {type(value).__name__}); {valid}")


def _keys(where: str, table: Any, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    if not isinstance(table, Mapping):
        raise _bad(where, table, "expected a table")
    unknown = [key for key in table if key not in allowed]
    if unknown:
        raise ParameterError(
            f"{where}: unknown key {unknown[0]!r}; valid keys: {', '.join(allowed)}"
        )
    missing = [key for key in required if key not in table]
    if missing:
        raise ParameterError(f"{where}: missing required key {missing[0]!r}")
    return dict(table)


def _axis_value(name: str, value: Any, where: str) -> float | int:
    if name == "N":
        return check_int(where, value, low=1)
    return check_real(where, value)


@dataclass(frozen=True)
class Axis:
    """One sweep axis: a field of the harvester and its values.

    Parameters
    ----------
    name : str
        One of :data:`AXIS_NAMES` (``a``, ``n``, ``N``, ``k`` or a :class:`Params` field).
    values : tuple of float
        The values, in sweep order (ints for ``N``).
    unit : {"", "k_di"}
        ``"k_di"`` (axis ``k`` only): the values are multiples of the harmonic threshold
        :math:`k_{di}(N, a)` of each point, so ``1.0`` is the threshold and ``0.5`` half of it.

    Examples
    --------
    >>> Axis.from_spec("k", {"linspace": [0, -0.2, 3]}).values
    (0.0, -0.1, -0.2)
    """

    name: str
    values: tuple[float, ...]
    unit: str = ""

    def __post_init__(self) -> None:
        check_choice("axis name", self.name, AXIS_NAMES)
        check_choice(f"axes.{self.name}.unit", self.unit, ("", "k_di"))
        if self.unit and self.name != "k":
            raise ParameterError(f"axes.{self.name}.unit: unit 'k_di' is valid only for axis 'k'")
        if not isinstance(self.values, (tuple, list)) or len(self.values) == 0:
            raise _bad(f"axes.{self.name}", self.values, "expected a non-empty list of numbers")
        vals = tuple(_axis_value(self.name, v, f"axes.{self.name} value") for v in self.values)
        object.__setattr__(self, "values", vals)

    @classmethod
    def from_spec(cls, name: str, spec: Any) -> Axis:
        """Build from a TOML value: a list, or a table with one of ``values``, ``linspace =
        [start, stop, num]``, ``logspace = [start_exp, stop_exp, num]`` (base 10) or
        ``integers = [first, last]`` (inclusive), and optionally ``unit``."""
        where = f"axes.{name}"
        if name not in AXIS_NAMES:
            raise ParameterError(f"axes: unknown axis {name!r}; valid axes: {', '.join(AXIS_NAMES)}")
        if isinstance(spec, list):
            spec = {"values": spec}
        table = _keys(where, spec, (*_SPACINGS, "unit"))
        kinds = [key for key in _SPACINGS if key in table]
        if len(kinds) != 1:
            raise ParameterError(
                f"{where}: give exactly one of {', '.join(_SPACINGS)}; got {kinds or 'none'}"
            )
        kind, arg = kinds[0], table[kinds[0]]
        if kind == "values":
            values: Any = arg
        elif kind == "integers":
            if not (isinstance(arg, list) and len(arg) == 2):
                raise _bad(f"{where}.integers", arg, "expected [first, last] (inclusive)")
            lo, hi = (check_int(f"{where}.integers", v) for v in arg)
            values = list(range(lo, hi + 1))
        else:
            if not (isinstance(arg, list) and len(arg) == 3):
                raise _bad(f"{where}.{kind}", arg, "expected [start, stop, num]")
            start = check_real(f"{where}.{kind} start", arg[0])
            stop = check_real(f"{where}.{kind} stop", arg[1])
            num = check_int(f"{where}.{kind} num", arg[2], low=1)
            fn = np.linspace if kind == "linspace" else np.logspace
            values = [float(np.round(v, 14)) for v in fn(start, stop, num)]
        if not isinstance(values, list) or not values:
            raise _bad(where, values, "expected a non-empty list of numbers")
        return cls(name, tuple(values), table.get("unit", ""))


@dataclass(frozen=True)
class Optimize:
    """Replace a sweep over ``over`` by its optimum: per point of the other axes, maximize
    ``maximize`` for ``over`` in ``bounds``.

    Parameters
    ----------
    maximize : str
        Observable to maximize (one of :data:`~fpe_harvester.result.QUANTITIES`).
    over : str
        Field varied (one of :data:`AXIS_NAMES` except ``N``); must not also be a sweep axis.
    bounds : (float or "k_di", float or "k_di")
        Closed search interval. ``"k_di"`` (for ``over = "k"``) is the harmonic threshold of
        each point, where eta reaches its finite marginal limit.
    points : int
        Size of the uniform grid scanned first, >= 3. For exact (harmonic) points an interior
        best grid point is then refined with a bounded scalar optimizer (scipy); for Fokker--Planck
        points the result is the best grid point, the neighbouring grid points its bracket. Monte
        Carlo points use :func:`~fpe_harvester.optimum.optimize` instead (common random numbers,
        local quadratic fit, error bars on the position in ``info["optimize"]``).
        A maximum on a bound is reported as such in the row's message (harmonic eta(k) on
        [k_di, 0] is monotone decreasing, so its optimum is the marginal limit at k_di).
    """

    maximize: str = "eta"
    over: str = "k"
    bounds: tuple[float | str, float | str] = ("k_di", 0.0)
    points: int = 41

    def __post_init__(self) -> None:
        check_choice("optimize.maximize", self.maximize, QUANTITIES)
        check_choice("optimize.over", self.over, tuple(n for n in AXIS_NAMES if n != "N"))
        if not isinstance(self.bounds, (tuple, list)) or len(self.bounds) != 2:
            raise _bad("optimize.bounds", self.bounds, "expected [low, high]")
        bounds = []
        for b in self.bounds:
            if isinstance(b, str):
                if b != "k_di" or self.over != "k":
                    raise _bad("optimize.bounds", b, "expected numbers, or 'k_di' when over = 'k'")
                bounds.append(b)
            else:
                bounds.append(check_real("optimize.bounds", b))
        object.__setattr__(self, "bounds", tuple(bounds))
        object.__setattr__(self, "points", check_int("optimize.points", self.points, low=3))

    def interval(self, h: Harvester) -> tuple[float, float]:
        """Numeric bounds for the point ``h`` (``"k_di"`` resolved; N = 1 gives (0, 0))."""
        if self.over == "k" and h.N == 1:
            return 0.0, 0.0
        kd = k_di(h.N, h.a, h.k4)
        lo, hi = (kd if b == "k_di" else float(b) for b in self.bounds)
        return (lo, hi) if lo <= hi else (hi, lo)


@dataclass(frozen=True)
class Ref:
    """A reference mark on a figure.

    Parameters
    ----------
    kind : {"vline", "hline", "point"}
        Vertical line at ``x``, horizontal line at ``y``, or a marker at ``(x, y)``.
    x, y : float or "k_di" or None
        Position; ``x = "k_di"`` draws the threshold of every series (harmonic formula).
    label : str
        Legend text (e.g. ``"paper: 0.677"``).
    panel : str or None
        Observable panel to draw on; ``None`` draws on every panel (lines) or on ``eta``.
    """

    kind: str
    x: float | str | None = None
    y: float | None = None
    label: str = ""
    panel: str | None = None

    def __post_init__(self) -> None:
        check_choice("refs.kind", self.kind, ("vline", "hline", "point"))
        if self.kind in ("vline", "point"):
            if self.x != "k_di":
                object.__setattr__(self, "x", check_real(f"refs.{self.kind} x", self.x))
        if self.kind in ("hline", "point"):
            object.__setattr__(self, "y", check_real(f"refs.{self.kind} y", self.y))
        if self.panel is not None:
            check_choice("refs.panel", self.panel, (*QUANTITIES, *DERIVED))

    @classmethod
    def from_spec(cls, spec: Any, where: str) -> Ref:
        table = _keys(where, spec, ("vline", "hline", "point", "label", "panel"))
        kinds = [key for key in ("vline", "hline", "point") if key in table]
        if len(kinds) != 1:
            raise ParameterError(f"{where}: give exactly one of vline, hline, point; got {kinds or 'none'}")
        kind, arg = kinds[0], table[kinds[0]]
        label, panel = str(table.get("label", "")), table.get("panel")
        if kind == "vline":
            return cls("vline", x=arg, label=label, panel=panel)
        if kind == "hline":
            return cls("hline", y=arg, label=label, panel=panel)
        if not (isinstance(arg, list) and len(arg) == 2):
            raise _bad(f"{where}.point", arg, "expected [x, y]")
        return cls("point", x=arg[0], y=arg[1], label=label, panel=panel)


@dataclass(frozen=True)
class FigureSpec:
    """One figure: ``y`` observables (one panel each) against axis ``x``, one curve per
    value of ``series``, other axes fixed by ``select``. ``xnorm = "k_di"`` (with ``x = "k"``)
    plots :math:`k/|k_{di}|` so that curves of different ``a`` or ``N`` share one axis.
    ``kind = "map"`` draws each ``y`` as a colour map over ``x`` (horizontal) and ``series``
    (vertical, required) instead of curves.

    Points without a stationary state (unstable), failed points and points whose solver is
    not available are drawn as markers on the bottom edge and counted in a note; metastable
    and not-converged points get open markers. ``errorbars`` draws each value's error.
    """

    name: str
    x: str
    y: tuple[str, ...] = ("eta",)
    series: str | None = None
    select: Mapping[str, float] = field(default_factory=dict)
    logx: bool = False
    logy: bool = False
    errorbars: bool = True
    refs: tuple[Ref, ...] = ()
    title: str = ""
    xnorm: str = ""
    kind: str = "lines"

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise _bad("figures.name", self.name, "expected an identifier such as 'eta_vs_k'")
        check_choice(f"figures.{self.name}.kind", self.kind, ("lines", "map"))
        if self.kind == "map" and self.series is None:
            raise ParameterError(f"figures.{self.name}: kind = 'map' needs series (the vertical axis)")
        check_choice(f"figures.{self.name}.x", self.x, AXIS_NAMES)
        ys = (self.y,) if isinstance(self.y, str) else tuple(self.y)
        if not ys:
            raise _bad(f"figures.{self.name}.y", self.y, "expected at least one observable")
        for y in ys:
            check_choice(f"figures.{self.name}.y", y, (*QUANTITIES, *DERIVED, *AXIS_NAMES))
        object.__setattr__(self, "y", ys)
        if self.series is not None:
            check_choice(f"figures.{self.name}.series", self.series, AXIS_NAMES)
        for key in self.select:
            check_choice(f"figures.{self.name}.select", key, AXIS_NAMES)
        object.__setattr__(self, "select", MappingProxyType(dict(self.select)))
        check_choice(f"figures.{self.name}.xnorm", self.xnorm, ("", "k_di"))
        if self.xnorm and self.x != "k":
            raise ParameterError(f"figures.{self.name}.xnorm: 'k_di' is valid only with x = 'k'")
        for key in ("logx", "logy", "errorbars"):
            if not isinstance(getattr(self, key), bool):
                raise _bad(f"figures.{self.name}.{key}", getattr(self, key), "expected true or false")
        object.__setattr__(self, "refs", tuple(self.refs))


@dataclass(frozen=True)
class Scene:
    """A declarative study; its TOML form (every table, key, type and default) is the docs page
    ``scene-format`` (docs/scene-format.md).

    Parameters
    ----------
    name : str
        Identifier (file stem of shipped scenes), used for output names and seeds.
    system : Harvester
        Base harvester; axes and the optimization replace its fields.
    axes : tuple of Axis
        Sweep axes, outer product in order (first outermost). Empty: one point.
    observables : tuple of str
        Subset of :data:`~fpe_harvester.result.QUANTITIES` and :data:`DERIVED` to report.
    rtol : float
        Wanted relative accuracy on eta, in (0, 1). Passed as ``tol`` to every solver that
        takes a tolerance (Fokker--Planck, Monte Carlo); the exact solver has none.
    method : {"auto", "exact", "fpe", "mc"}
        ``"auto"``: per point, the first solver that handles it (as
        :func:`~fpe_harvester.solve.solve` chooses); where it misses ``rtol`` (no numbers, or an
        error above it) the next one is tried and kept when it reaches ``rtol`` or has the smaller
        relative error on eta (with its settings from ``options``; its wall-time budget is
        :data:`~fpe_harvester.scenes.run.SCENE_FALLBACK_SECONDS`, 600 s, unless set there).
        A named method must handle every point: the run checks that before it starts.
    options : mapping of method name to mapping
        Extra constructor settings per solver (e.g. ``{"mc": {"dt": 0.01}}``), checked when
        the scene is made: an option the solver does not have, or an invalid value, is an error.
    optimize : Optimize or None
        Turn each point into the optimum over one field.
    figures : tuple of FigureSpec
        Figures to draw (only these).
    outputs : tuple of str
        Subset of ``("table", "csv", "json")`` to write.
    quick : Scene or None
        Reduced variant (fewer points, looser ``rtol``) used by ``run_scene(..., quick=True)``.
    """

    name: str
    system: Harvester = field(default_factory=Harvester)
    axes: tuple[Axis, ...] = ()
    observables: tuple[str, ...] = ("eta",)
    rtol: float = 1e-3
    method: str = "auto"
    options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    optimize: Optimize | None = None
    figures: tuple[FigureSpec, ...] = ()
    outputs: tuple[str, ...] = OUTPUTS
    title: str = ""
    description: str = ""
    quick: Scene | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.replace("-", "_").isidentifier():
            raise _bad("name", self.name, "expected an identifier such as 'fig1_eta_vs_n'")
        if not isinstance(self.system, Harvester):
            raise _bad("system", self.system, "expected a Harvester")
        obs = (self.observables,) if isinstance(self.observables, str) else tuple(self.observables)
        if not obs:
            raise _bad("observables", self.observables, f"choose from {', '.join(QUANTITIES + DERIVED)}")
        for name in obs:
            check_choice("observables", name, (*QUANTITIES, *DERIVED))
        object.__setattr__(self, "observables", tuple(dict.fromkeys(obs)))
        object.__setattr__(self, "rtol", check_real("rtol", self.rtol, low=0.0, high=1.0,
                                                    low_open=True, high_open=True))
        check_choice("method", self.method, ("auto", *METHODS))
        names = [ax.name for ax in self.axes]
        if len(set(names)) != len(names):
            raise ParameterError(f"axes: an axis appears twice in {names}")
        if self.optimize is not None and self.optimize.over in names:
            raise ParameterError(
                f"optimize.over: {self.optimize.over!r} is also a sweep axis; remove one of them"
            )
        for key, opts in self.options.items():
            check_choice("options", key, tuple(METHODS))
            if not isinstance(opts, Mapping):
                raise _bad(f"options.{key}", opts, "expected a table of solver settings")
            _check_solver_options(key, opts)
        object.__setattr__(self, "options", MappingProxyType({k: MappingProxyType(dict(v))
                                                              for k, v in self.options.items()}))
        outs = tuple(self.outputs)
        for out in outs:
            check_choice("outputs", out, OUTPUTS)
        object.__setattr__(self, "outputs", outs)
        varied = set(names) | ({self.optimize.over} if self.optimize else set())
        for fig in self.figures:
            for key in (fig.x, fig.series, *fig.select):
                if key is not None and key not in varied:
                    raise ParameterError(
                        f"figures.{fig.name}: {key!r} is not a sweep axis or optimized field; "
                        f"varied fields: {', '.join(sorted(varied)) or 'none'}"
                    )
        if self.quick is not None and not isinstance(self.quick, Scene):
            raise _bad("quick", self.quick, "expected a Scene")

    def variant(self, quick: bool) -> Scene:
        """The scene to run: its quick variant when asked and declared, else itself."""
        return self.quick if quick and self.quick is not None else self

    def points(self) -> Iterator[dict[str, float]]:
        """Axis values of every point, outer product in axis order (``k_di`` units resolved)."""
        for combo in itertools.product(*(ax.values for ax in self.axes)):
            point = {ax.name: v for ax, v in zip(self.axes, combo)}
            for ax in self.axes:
                if ax.unit == "k_di":
                    h = self.harvester({key: v for key, v in point.items() if key != "k"})
                    kd = k_di(h.N, h.a, h.k4)
                    point["k"] = 0.0 if kd is None else point["k"] * kd
            yield point

    def harvester(self, values: Mapping[str, float]) -> Harvester:
        """The base system with ``values`` (axis name -> value) substituted."""
        values = dict(values)
        if "N" in values and values["N"] == 1 and "k" not in values:
            values["k"] = 0.0
        try:
            return self.system.replace(**values)
        except ParameterError as exc:
            desc = ", ".join(f"{k} = {v:g}" for k, v in values.items())
            raise ParameterError(f"scene {self.name!r}, point ({desc}): {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description of the scene (values resolved, quick variant omitted)."""
        def plain(obj: Any) -> Any:
            if dataclasses.is_dataclass(obj):
                return {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
            if isinstance(obj, Mapping):
                return {str(k): plain(v) for k, v in obj.items()}
            if isinstance(obj, (list, tuple)):
                return [plain(v) for v in obj]
            return obj

        return {
            "name": self.name, "title": self.title, "description": self.description,
            "system": self.system.to_dict(),
            "axes": {ax.name: {"values": list(ax.values), "unit": ax.unit} for ax in self.axes},
            "observables": list(self.observables), "rtol": self.rtol, "method": self.method,
            "options": plain(self.options), "optimize": plain(self.optimize),
            "figures": [plain(f) for f in self.figures], "outputs": list(self.outputs),
        }

    @property
    def n_points(self) -> int:
        return math.prod(len(ax.values) for ax in self.axes)


def _check_solver_options(method: str, opts: Mapping[str, Any]) -> None:
    """``options.<method>``: settings the solver has, with valid values (it is built with them once).
    A solver not installed here is not checked: its points say so when they run."""
    try:
        get_solver(method, **opts)
    except MethodNotAvailableError:
        return
    except ParameterError as exc:
        raise ParameterError(f"options.{method}: {exc}") from None


_TOP_KEYS = ("name", "title", "description", "system", "axes", "observables", "rtol", "method",
             "options", "optimize", "figures", "outputs", "quick")
_QUICK_KEYS = ("rtol", "axes", "options", "optimize", "method", "observables", "figures", "outputs")


def scene_from_dict(data: Mapping[str, Any], name: str | None = None) -> Scene:
    """Build a :class:`Scene` from parsed TOML (``name`` defaults to ``data["name"]``)."""
    data = _keys("scene", data, _TOP_KEYS)
    name = data.get("name", name)
    if name is None:
        raise ParameterError("scene: missing required key 'name'")
    quick = None
    if "quick" in data:
        overrides = _keys("quick", data["quick"], _QUICK_KEYS)
        merged = {key: val for key, val in data.items() if key != "quick"}
        if "axes" in overrides:
            axes = _keys("quick.axes", overrides.pop("axes"), tuple(dict(data.get("axes", {}))))
            merged["axes"] = {**dict(data.get("axes", {})), **axes}
        if "optimize" in overrides:
            merged["optimize"] = {**dict(data.get("optimize", {})), **dict(overrides.pop("optimize"))}
        merged.update(overrides)
        quick = scene_from_dict(merged, name)
    axes_table = data.get("axes", {})
    if not isinstance(axes_table, Mapping):
        raise _bad("axes", axes_table, "expected a table of axis name = values")
    axes = tuple(Axis.from_spec(key, spec) for key, spec in axes_table.items())
    optimize = None
    if "optimize" in data:
        opt = _keys("optimize", data["optimize"], ("maximize", "over", "bounds", "points"),
                    required=("over",))
        optimize = Optimize(**opt)
    fig_list = data.get("figures", [])
    if not isinstance(fig_list, list):
        raise _bad("figures", fig_list, "expected an array of tables [[figures]]")
    scene = Scene(
        name=name,
        title=str(data.get("title", "")),
        description=str(data.get("description", "")),
        system=_system(data.get("system")),
        axes=axes,
        observables=_as_tuple(data.get("observables", ("eta",)), "observables"),
        rtol=data.get("rtol", 1e-3),
        method=data.get("method", "auto"),
        options=_keys("options", data.get("options", {}), tuple(METHODS)),
        optimize=optimize,
        figures=_figures(fig_list),
        outputs=_as_tuple(data.get("outputs", OUTPUTS), "outputs"),
        quick=quick,
    )
    if not data.get("system"):
        raise ParameterError(
            f"system: {'the table is empty' if 'system' in data else 'missing required table'}; a scene states "
            "its base harvester, e.g. [system] with a = 0.5, n = 2, N = 3 (keys: a, n, N, k, k4, k3, params, "
            f"{', '.join(_PARAMS)})")
    return scene


def _figures(fig_list: list[Any]) -> tuple[FigureSpec, ...]:
    """The ``[[figures]]`` tables as :class:`FigureSpec` objects."""
    figures = []
    for i, spec in enumerate(fig_list):
        where = f"figures[{i}]"
        table = _keys(where, spec, ("name", "x", "y", "series", "select", "logx", "logy",
                                    "errorbars", "refs", "title", "xnorm", "kind"),
                      required=("name", "x"))
        refs = table.pop("refs", [])
        if not isinstance(refs, list):
            raise _bad(f"{where}.refs", refs, "expected an array of tables")
        table["refs"] = tuple(Ref.from_spec(r, f"{where}.refs[{j}]") for j, r in enumerate(refs))
        if "select" in table:
            table["select"] = _keys(f"{where}.select", table["select"], AXIS_NAMES)
        figures.append(FigureSpec(**table))
    return tuple(figures)


def _system(table: Any) -> Harvester:
    """The ``[system]`` table as the base harvester (the defaults when it is missing or empty: the
    caller refuses those once the rest of the scene is checked)."""
    sys_table = _keys("system", {} if table is None else table,
                      ("a", "n", "N", "k", "k4", "k3", "params", *_PARAMS))
    params = dict(_keys("system.params", sys_table.pop("params", {}), _PARAMS))
    params.update({key: sys_table.pop(key) for key in _PARAMS if key in sys_table})
    try:
        return Harvester.build(**{**sys_table, **params})
    except TypeError as exc:
        raise ParameterError(f"system: {exc}") from None


def _as_tuple(value: Any, where: str) -> tuple:
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, (list, tuple)):
        raise _bad(where, value, "expected a list of names")
    return tuple(value)


def list_scenes() -> list[str]:
    """Names of the shipped scenes (one per figure of the paper, plus extensions)."""
    return sorted(p.stem for p in SCENE_DIR.glob("*.toml"))


def load_scene(path_or_name: str | Path) -> Scene:
    """Load a scene from a TOML file, or a shipped scene by name (see :func:`list_scenes`).

    Raises
    ------
    ParameterError
        Unknown name, unreadable file, TOML syntax error, or an invalid key or value
        (the message names the key, echoes the value and says what is valid).

    Examples
    --------
    >>> load_scene("fig4_eta_vs_k_harmonic").system.N
    3
    """
    path = Path(path_or_name)
    if not path.suffix and not path.exists():
        if str(path_or_name) not in list_scenes():
            raise ParameterError(
                f"scene {str(path_or_name)!r} is neither a file nor a shipped scene; "
                f"shipped scenes: {', '.join(list_scenes())}"
            )
        path = SCENE_DIR / f"{path_or_name}.toml"
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ParameterError(f"scene file {str(path)!r} cannot be read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"scene file {str(path)!r} is not valid TOML: {exc}") from None
    try:
        return scene_from_dict(data, name=path.stem)
    except ParameterError as exc:
        raise ParameterError(f"scene file {str(path)!r}: {exc}") from None
