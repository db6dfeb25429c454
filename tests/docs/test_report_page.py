"""The validation report (report.html) opened in a real headless browser: every figure loads,
every internal link and anchor resolves.

The report is the one ``harvester validate`` wrote into the folder named by the environment
variable ``FPE_HARVESTER_REPORT`` (``.ci/run`` points it at the quick report it has just built);
without it the test is skipped, with the reason (failed where ``DOCS_SITE_REQUIRED=1``). How the
browser is set up and what it refuses: :mod:`tests.docs.conftest`.
"""

from __future__ import annotations

import base64
import os
import re
from pathlib import Path

import pytest

from .conftest import dead_links, offline_page, serve, unavailable, visit

#: The environment variable naming the folder of the report to open.
REPORT_ENV = "FPE_HARVESTER_REPORT"
BUILD = "harvester validate --quick --out DIR"


@pytest.fixture(scope="module")
def report() -> Path:
    """The folder holding report.html and report.md; skips the test when there is none."""
    folder = os.environ.get(REPORT_ENV)
    if not folder:
        unavailable(f"no report to open: build one with {BUILD} and set {REPORT_ENV}=DIR")
    if not (Path(folder) / "report.html").is_file():
        unavailable(f"{REPORT_ENV}={folder} holds no report.html: build it with {BUILD}")
    return Path(folder)


def check_page(browser: object, folder: Path, name: str) -> tuple[dict, list[str], list[str]]:
    """Open ``folder/name`` over HTTP: what the page holds, its images that did not load, and
    its internal links that do not resolve."""
    with serve(folder) as base:
        page = offline_page(browser, base)
        info = visit(page, base + name)
        page.close()
        assert info is not None, f"{folder / name} did not open"
        return info, info["broken"], dead_links({base + name: info}, base, folder)


def test_report_figures_load_and_internal_links_resolve(browser: object, report: Path) -> None:
    info, broken, dead = check_page(browser, report, "report.html")
    # every figure of the Markdown report (linked there as ![caption](file.png)) is in the page
    figures = len(re.findall(r"^!\[", (report / "report.md").read_text(encoding="utf-8"), re.M))
    assert figures > 0 and info["images"] == figures, f"{info['images']} images for {figures} figures"
    assert not broken, "images that did not load (naturalWidth 0):\n" + "\n".join(broken)
    assert not dead, "internal links that do not resolve:\n" + "\n".join(dead)


def test_the_check_finds_a_broken_image_a_missing_file_and_a_missing_anchor(browser: object,
                                                                          tmp_path: Path) -> None:
    import matplotlib.pyplot as plt
    import numpy as np

    plt.imsave(tmp_path / "ok.png", np.eye(4))
    good = base64.b64encode((tmp_path / "ok.png").read_bytes()).decode("ascii")
    (tmp_path / "page.html").write_text(
        f"<!DOCTYPE html><html><body><h2 id='here'>x</h2><img src='ok.png'>"
        f"<img src='data:image/png;base64,{good}'><img src='data:image/png;base64,{good[:40]}'>"
        "<a href='#here'>ok</a><a href='ok.png'>ok</a><a href='#nowhere'>anchor</a>"
        "<a href='gone.html'>file</a></body></html>")
    info, broken, dead = check_page(browser, tmp_path, "page.html")
    assert info["images"] == 3 and len(broken) == 1 and broken[0].startswith("data:image/png;base64,")
    assert sorted(d.split(" (")[1] for d in dead) == ["no such anchor)", "no such file)"]
