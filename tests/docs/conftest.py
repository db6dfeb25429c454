"""The built documentation site and the headless browser, for the tests of tests/docs.

Pages are opened in the system's Chromium (Debian's ``chromium`` package, ``/usr/bin/chromium``)
driven by playwright, served over HTTP on localhost as a user's browser would load them;
requests to other hosts are refused so the tests need no network. A test is skipped, with the
reason, when what it opens is not built, playwright is not installed or Chromium is missing.
"""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
import threading
from collections.abc import Iterator
from html.parser import HTMLParser
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urldefrag, urlsplit

import pytest

#: Where ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` writes the site.
SITE = Path(__file__).resolve().parents[2] / "docs" / "_build" / "html"
BUILD = "python -m sphinx -W --keep-going -b html docs docs/_build/html"


class Anchors(HTMLParser):
    """The ids and the links (href, text) of one HTML page."""

    def __init__(self) -> None:
        super().__init__()
        self.ids: set[str] = set()
        self.links: list[tuple[str, str]] = []
        self._href: str | None = None
        self._text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        attr = dict(attrs)
        if attr.get("id"):
            self.ids.add(attr["id"])
        if tag == "a" and attr.get("href") is not None:
            self._href, self._text = attr["href"], []

    def handle_data(self, data: str) -> None:
        if self._href is not None:
            self._text.append(data)

    def handle_endtag(self, tag: str) -> None:
        if tag == "a" and self._href is not None:
            self.links.append((self._href, "".join(self._text).strip()))
            self._href = None


def anchors(path: Path) -> Anchors:
    """Parse one page of the site."""
    parser = Anchors()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


def unavailable(reason: str) -> None:
    """Skip the test, or fail it where the site and the browser must be there.

    ``.ci/run`` sets ``DOCS_SITE_REQUIRED=1`` after building the site and installing Chromium,
    so that a missing piece fails CI instead of skipping the check silently.
    """
    if os.environ.get("DOCS_SITE_REQUIRED") == "1":
        pytest.fail(reason)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def site() -> Path:
    """The built site's folder; skips the test when the site is not built."""
    if not (SITE / "index.html").exists():
        unavailable(f"docs site not built ({SITE / 'index.html'} missing): build it with {BUILD}")
    return SITE


CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]

#: Collected in the page: images that did not load (after forcing lazy ones to load), links, ids.
PAGE_SCRIPT = """async () => {
  const imgs = Array.from(document.images);
  imgs.forEach(img => { img.loading = "eager"; });
  await Promise.all(imgs.map(img => img.complete ? null
      : new Promise(done => { img.addEventListener("load", done); img.addEventListener("error", done); })));
  return {
    broken: imgs.filter(img => img.naturalWidth === 0).map(img => (img.currentSrc || img.src).slice(0, 120)),
    images: imgs.length,
    links: Array.from(document.querySelectorAll("a[href]")).map(a => a.href),
    ids: Array.from(document.querySelectorAll("[id], a[name]")).map(e => e.id || e.name),
  };
}"""


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args: object) -> None:
        pass


@contextlib.contextmanager
def serve(folder: Path) -> Iterator[str]:
    """``folder`` served on a free localhost port; yields its base URL."""
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=str(folder)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    finally:
        httpd.shutdown()
        httpd.server_close()


@pytest.fixture(scope="session")
def browser() -> Iterator[object]:
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


def local(url: str, base: str) -> bool:
    """Whether ``url`` is served from ``base``."""
    return url.startswith(base)


def offline_page(browser: object, base: str) -> object:
    """A new page that loads only from ``base``: a page that needs another host fails to show."""
    page = browser.new_page()
    page.route("**/*", lambda route: route.continue_() if local(route.request.url, base) else route.abort())
    return page


def visit(page: object, url: str) -> dict | None:
    """Open ``url`` in ``page``: what :data:`PAGE_SCRIPT` collects there, or None if it did not open."""
    response = page.goto(url, wait_until="load")
    if response is None or not response.ok:
        return None
    return page.evaluate(PAGE_SCRIPT)


def _file_of(url: str, base: str, folder: Path) -> Path:
    """The file of ``folder`` that ``url`` (a URL under ``base``, without fragment) serves."""
    path = folder / unquote(urlsplit(url).path[len(urlsplit(base).path):])
    return path / "index.html" if path.is_dir() else path


def dead_links(pages: dict[str, dict], base: str, folder: Path) -> list[str]:
    """The internal links of ``pages`` (URL -> what :data:`PAGE_SCRIPT` collected there) that
    do not resolve: to no file of ``folder``, or to an anchor missing from an opened page."""
    ids = {url: set(p["ids"]) for url, p in pages.items()}
    dead = []
    for url, p in pages.items():
        for link in p["links"]:
            target, fragment = urldefrag(link)
            if not local(target, base):
                continue
            if not _file_of(target, base, folder).exists():
                dead.append(f"{url} -> {link} (no such file)")
            elif fragment and target in ids and unquote(fragment) not in ids[target]:
                dead.append(f"{url} -> {link} (no such anchor)")
    return sorted(set(dead))
