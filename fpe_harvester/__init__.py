"""fpe-harvester: stationary statistics of noise-driven piezoelectric energy harvesters.

Public API: the model (:class:`Params`, :class:`Potential`, :class:`Harvester`), the one
entry point :func:`solve` with its result :class:`Stats` (and :func:`solve_many`, and
:func:`sweep` over parameter grids, a table with the parameters beside the results), what
solvers declare (:class:`Capabilities`, the registry :data:`METHODS`), the exact harmonic
solver (:class:`Exact`, :func:`exact_sweep`), stability thresholds (:func:`k_di`,
:func:`threshold`), optima with error bars (:func:`optimize`, :func:`maximize_noisy`) and
declarative studies (:class:`Scene`, :func:`run_scene`).

The solvers are the subpackages :mod:`.exact` (harmonic rings, closed form),
:mod:`.fpe` (Fokker--Planck, one nonlinear unit) and ``montecarlo`` (a top-level package:
everything); :mod:`.scenes` runs studies over them. The model, its conventions and the
results known exactly are in ``docs/model.md``.
"""

from __future__ import annotations

from .errors import (
    HarvesterError,
    MethodNotAvailableError,
    NotConvergedError,
    ParameterError,
    UnstableSystemError,
)
from .exact import (
    Exact,
    Threshold,
    critical_mode,
    exact_sweep,
    growth_rate,
    k_di,
    ring_spectrum,
    threshold,
)
from .model import Harvester, Params, Potential
from .optimum import Optimum, maximize_noisy, optimize
from .result import QUANTITIES, Stats, Status
from .scenes import Axis, FigureSpec, Optimize, Scene, SceneResult, list_scenes, load_scene, run_scene
from .solve import choose_method, get_solver, solve, solve_many
from .solvers import METHODS, Capabilities, Tolerance
from .sweep import Sweep, sweep

__version__ = "0.1.0"

__all__ = [
    "Params",
    "Potential",
    "Harvester",
    "Stats",
    "Status",
    "QUANTITIES",
    "solve",
    "solve_many",
    "sweep",
    "Sweep",
    "get_solver",
    "choose_method",
    "METHODS",
    "Capabilities",
    "Tolerance",
    "Exact",
    "exact_sweep",
    "Threshold",
    "threshold",
    "k_di",
    "critical_mode",
    "growth_rate",
    "ring_spectrum",
    "Scene",
    "Axis",
    "Optimize",
    "FigureSpec",
    "load_scene",
    "list_scenes",
    "run_scene",
    "SceneResult",
    "optimize",
    "maximize_noisy",
    "Optimum",
    "HarvesterError",
    "ParameterError",
    "UnstableSystemError",
    "NotConvergedError",
    "MethodNotAvailableError",
]
