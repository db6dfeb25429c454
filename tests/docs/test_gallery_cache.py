"""The gallery's committed caches hold every point of their scenes (the docs build computes none).

A change to what keys a point (the harvester's fields, a scene's options, the solver settings
in the key) would make the gallery recompute a scene inside the docs build: minutes for the
Fokker-Planck and Monte Carlo scenes. This check runs without the site and says how to
regenerate the cache.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from fpe_harvester import load_scene
from fpe_harvester.scenes.cache import PointCache
from fpe_harvester.scenes.run import _Runner

DOCS = Path(__file__).resolve().parents[2] / "docs"
CACHED = sorted(p.name for p in (DOCS / "_cache").iterdir() if (p / "points.jsonl").exists())


def test_the_cached_scenes_are_the_gallery_s() -> None:
    examples = {p.stem.removeprefix("scene_") for p in (DOCS / "examples").glob("scene_*.py")}
    uses_cache = sorted(e for e in examples if "_cache" in (DOCS / "examples" / f"scene_{e}.py").read_text())
    assert CACHED == uses_cache and CACHED, (CACHED, uses_cache)


@pytest.mark.parametrize("name", CACHED)
def test_committed_cache_holds_every_point(name: str) -> None:
    scene = load_scene(name)
    cache = PointCache(DOCS / "_cache" / name)
    assert cache.skipped_lines == 0, cache.problems
    runner = _Runner(scene, cache, bar=None)
    missing = [p for p in scene.points() if cache.get(runner.key(scene.harvester(p))[0]) is None]
    assert not missing, (f"{len(missing)} points of {name} are not in docs/_cache/{name} (first: {missing[0]}); "
                         f"regenerate: harvester scene run {name} --out docs/_cache/{name}")
