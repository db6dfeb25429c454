"""Scenes: declarative studies of harvesters and the machinery that runs them.

A scene (:mod:`.spec`: a TOML file or a :class:`Scene` object) says what to compute and
draw: the systems, the sweep axes, the observables, the accuracy and the outputs.
:func:`run_scene` (:mod:`.run`) picks the cheapest adequate solver per point, keeps finished
points in a cache that makes runs resumable (:mod:`.cache`), optionally computes them on a
Dask cluster (:mod:`.cluster`) and returns a
:class:`SceneResult` of :class:`SceneRow` (:mod:`.result`); :mod:`.plotting` draws the
figures from those rows. The shipped scenes (one per figure of the paper, and more) are
the TOML files in ``data/``: see :func:`list_scenes`.
"""

from __future__ import annotations

from .result import SceneResult, SceneRow
from .run import run_scene
from .spec import Axis, FigureSpec, Optimize, Ref, Scene, list_scenes, load_scene, scene_from_dict

__all__ = [
    "Axis",
    "FigureSpec",
    "Optimize",
    "Ref",
    "Scene",
    "SceneResult",
    "SceneRow",
    "list_scenes",
    "load_scene",
    "run_scene",
    "scene_from_dict",
]
