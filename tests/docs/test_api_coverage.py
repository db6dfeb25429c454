"""Every public name (each package's ``__all__``) reaches the built site's API reference."""

from __future__ import annotations

import importlib
from pathlib import Path
from urllib.parse import urldefrag

import pytest

from .conftest import anchors

#: The public packages; their ``__all__`` is the public API.
PACKAGES = ("fpe_harvester", "fpe_harvester.exact", "fpe_harvester.fpe", "fpe_harvester.scenes",
            "fpe_harvester.landscape", "montecarlo")


@pytest.mark.parametrize("package", PACKAGES)
def test_every_exported_name_is_documented(site: Path, package: str) -> None:
    """On api/<package>.html each name links to a page that documents an object of that name."""
    page = site / "api" / f"{package}.html"
    assert page.exists(), f"no API page for {package}"
    links = {}
    for href, text in anchors(page).links:
        links.setdefault(text, href)
    missing, unresolved = [], []
    for name in importlib.import_module(package).__all__:
        href = links.get(name)
        if href is None:
            missing.append(name)
            continue
        url, fragment = urldefrag(href)
        target = (page.parent / url).resolve() if url else page
        # the fragment is the documented object's full name, e.g. fpe_harvester.exact.threshold
        if not target.exists() or not fragment.endswith("." + name) or fragment not in anchors(target).ids:
            unresolved.append(f"{name} -> {href}")
    assert not missing, f"{package}: not on its API page: {missing}"
    assert not unresolved, f"{package}: links that document no such object: {unresolved}"
