"""The built documentation site, for the tests of tests/docs (skipped when it is not built)."""

from __future__ import annotations

import os
from html.parser import HTMLParser
from pathlib import Path

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
