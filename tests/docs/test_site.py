"""The built site opened in a real headless browser: every image loads, every internal link resolves.

Uses the system's Chromium (Debian's ``chromium`` package, ``/usr/bin/chromium``) driven by
playwright; skipped, with the reason, when the site is not built, playwright is not installed
or Chromium is missing. The site is served over HTTP on localhost, as a user's browser would
load it; requests to other hosts are refused so the test needs no network.
"""

from __future__ import annotations

import functools
import shutil
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urldefrag, urlsplit

import pytest

from .conftest import unavailable

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]

#: Collected in the page: images that did not load (after forcing lazy ones to load), links, ids.
_PAGE_SCRIPT = """async () => {
  const imgs = Array.from(document.images);
  imgs.forEach(img => { img.loading = "eager"; });
  await Promise.all(imgs.map(img => img.complete ? null
      : new Promise(done => { img.addEventListener("load", done); img.addEventListener("error", done); })));
  return {
    broken: imgs.filter(img => img.naturalWidth === 0).map(img => img.currentSrc || img.src),
    images: imgs.length,
    links: Array.from(document.querySelectorAll("a[href]")).map(a => a.href),
    ids: Array.from(document.querySelectorAll("[id], a[name]")).map(e => e.id || e.name),
  };
}"""


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture(scope="module")
def server(site: Path) -> Iterator[str]:
    """The site served on a free localhost port; yields its base URL."""
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(site)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture(scope="module")
def browser(site: Path) -> Iterator[object]:
    """Headless Chromium from the system, through playwright."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        unavailable("playwright not installed (python -m pip install -e '.[docs]')")
    if not Path(CHROMIUM).exists():
        unavailable(f"chromium not found at {CHROMIUM} (apt-get install chromium)")
    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS, headless=True)
        yield chromium
        chromium.close()


def _local(url: str, base: str) -> bool:
    return url.startswith(base)


def _file_of(url: str, base: str, site: Path) -> Path:
    """The site's file that ``url`` (a URL under ``base``, without fragment) serves."""
    path = site / unquote(urlsplit(url).path[len(urlsplit(base).path):])
    return path / "index.html" if path.is_dir() else path


def crawl(browser: object, base: str, site: Path) -> tuple[dict[str, dict], list[str]]:
    """Every page reachable from the home page: what each holds, and the pages that did not open."""
    page = browser.new_page()
    # no network: a site that needs an outside host to show its pages or images fails here
    page.route("**/*", lambda route: route.continue_() if _local(route.request.url, base) else route.abort())
    seen: dict[str, dict] = {}
    failed: list[str] = []
    todo = [base + "index.html"]
    while todo:
        url = todo.pop()
        if url in seen:
            continue
        response = page.goto(url, wait_until="load")
        if response is None or not response.ok:
            failed.append(url)
            seen[url] = {"broken": [], "links": [], "ids": [], "images": 0}
            continue
        seen[url] = info = page.evaluate(_PAGE_SCRIPT)
        for link in info["links"]:
            target = urldefrag(link)[0]
            if _local(target, base) and target.endswith(".html") and target not in seen:
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
    ids = {url: set(p["ids"]) for url, p in pages.items()}
    dead = []
    for url, p in pages.items():
        for link in p["links"]:
            target, fragment = urldefrag(link)
            if not _local(target, server):
                continue
            if not _file_of(target, server, site).exists():
                dead.append(f"{url} -> {link} (no such file)")
            elif fragment and target in ids and unquote(fragment) not in ids[target]:
                dead.append(f"{url} -> {link} (no such anchor)")
    assert not dead, "internal links that do not resolve:\n" + "\n".join(sorted(set(dead)))
