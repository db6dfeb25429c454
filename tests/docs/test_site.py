"""The built site opened in a real headless browser: every image loads, every internal link resolves.

How the browser is set up and what it refuses: :mod:`tests.docs.conftest`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urldefrag

import pytest

from .conftest import dead_links, local, offline_page, serve, visit


@pytest.fixture(scope="module")
def server(site: Path) -> Iterator[str]:
    """The site served on a free localhost port; yields its base URL."""
    with serve(site) as base:
        yield base


def crawl(browser: object, base: str, site: Path) -> tuple[dict[str, dict], list[str]]:
    """Every page reachable from the home page: what each holds, and the pages that did not open."""
    page = offline_page(browser, base)
    seen: dict[str, dict] = {}
    failed: list[str] = []
    todo = [base + "index.html"]
    while todo:
        url = todo.pop()
        if url in seen:
            continue
        info = visit(page, url)
        if info is None:
            failed.append(url)
            seen[url] = {"broken": [], "links": [], "ids": [], "images": 0}
            continue
        seen[url] = info
        for link in info["links"]:
            target = urldefrag(link)[0]
            if local(target, base) and target.endswith(".html") and target not in seen:
                todo.append(target)
    page.close()
    return seen, failed


def test_site_images_load_and_internal_links_resolve(browser: object, server: str, site: Path) -> None:
    pages, failed = crawl(browser, server, site)
    assert not failed, f"pages that did not open: {failed}"
    assert len(pages) > 20, f"only {len(pages)} pages reached from the home page"
    assert sum(p["images"] for p in pages.values()) >= 7, "the gallery's figures are not on the site"
    broken = [f"{url}: {src}" for url, p in pages.items() for src in p["broken"]]
    assert not broken, "images that did not load (naturalWidth 0):\n" + "\n".join(broken)
    dead = dead_links(pages, server, site)
    assert not dead, "internal links that do not resolve:\n" + "\n".join(dead)
