"""Sphinx extension: the API reference pages, written from the packages' ``__all__``.

Each public package gets ``api/<package>.rst``, listing every name of its ``__all__``. An
object is documented once, in the package it comes from (the listed package whose name is
the longest prefix of the object's ``__module__``, e.g. ``fpe_harvester.exact.threshold``);
a package that re-exports it links there. The pages are generated when the configuration is read, so
a name added, removed or moved between internal modules needs no edit here, and a test
(``tests/docs/test_api_coverage.py``) checks that every exported name reaches the built site.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx

#: The packages whose ``__all__`` make the public API, in the order of the reference.
PACKAGES = ("fpe_harvester", "fpe_harvester.exact", "fpe_harvester.fpe", "fpe_harvester.scenes",
            "fpe_harvester.landscape", "montecarlo")

#: One line under each package's title.
_SUMMARY = {
    "fpe_harvester": "The model, the one call :func:`~fpe_harvester.solve`, its result, the optimizer "
                     "and the errors.",
    "fpe_harvester.exact": "Harmonic rings: closed-form moments, stability thresholds, the exact solver.",
    "fpe_harvester.fpe": "The Fokker-Planck solver of one nonlinear unit: stationary and transient.",
    "fpe_harvester.scenes": "Declarative studies: the paper's figures as scenes, their runs and caches.",
    "fpe_harvester.landscape": "The coupled potential of a ring: its equilibria, their Morse index, and the "
                               "single-site buckling of n = 1 with cubic coupling (``harvester landscape``).",
    "montecarlo": "Monte Carlo simulation of any ring, with control variates and error estimates.",
}


def public_names(package: str) -> list[str]:
    """The names of ``package.__all__``, in its order."""
    return list(importlib.import_module(package).__all__)


def home(package: str, name: str) -> str:
    """The package under which ``package.name`` is documented.

    The listed package with the longest name that is a prefix of the object's module and
    exports the same object; ``package`` itself for values without a module (constants).
    """
    obj = getattr(importlib.import_module(package), name)
    module = getattr(obj, "__module__", None)
    if not isinstance(module, str) or isinstance(obj, (tuple, list, dict, str, int, float)):
        return package
    best = package
    for candidate in PACKAGES:
        pkg = importlib.import_module(candidate)
        inside = module == candidate or module.startswith(candidate + ".")
        if inside and len(candidate) > len(best) and getattr(pkg, name, None) is obj \
                and name in pkg.__all__:
            best = candidate
    return best


def page(package: str) -> str:
    """The reStructuredText of ``api/<package>.rst``."""
    names = public_names(package)
    own = [n for n in names if home(package, n) == package]
    moved = [n for n in names if n not in own]
    lines = [package, "=" * len(package), "", _SUMMARY[package], "",
             f".. automodule:: {package}", "   :no-members:", "",
             f".. currentmodule:: {package}", "", ".. autosummary::", "   :toctree: generated",
             "   :nosignatures:", ""]
    lines += [f"   {n}" for n in own] + [""]
    if moved:
        lines += ["Re-exported here", "-" * 16, "",
                  f"Also importable as ``from {package} import NAME``; documented where they are defined.",
                  "", ".. list-table::", "   :header-rows: 1", "", "   * - name", "     - documented as"]
        for n in moved:
            target = f"{home(package, n)}.{n}"
            lines += [f"   * - :obj:`{n} <{target}>`", f"     - ``{target}``"]
        lines.append("")
    return "\n".join(lines)


def index_page() -> str:
    """The reStructuredText of ``api/index.rst``."""
    lines = ["API reference", "=============", "",
             "Generated from the docstrings. Every name a package exports (its ``__all__``) is listed "
             "on the package's page.", "", ".. toctree::", "   :maxdepth: 1", ""]
    return "\n".join(lines + [f"   {p}" for p in PACKAGES] + [""])


def _write_if_changed(path: Path, text: str) -> None:
    # an unchanged file keeps its time stamp, so Sphinx does not read it again
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def write_pages(app: Sphinx, config: Any = None) -> None:
    """Write ``api/index.rst`` and one page per package into the source folder."""
    folder = Path(app.srcdir) / "api"
    folder.mkdir(exist_ok=True)
    _write_if_changed(folder / "index.rst", index_page())
    for package in PACKAGES:
        _write_if_changed(folder / f"{package}.rst", page(package))


def setup(app: Sphinx) -> dict[str, Any]:
    # before Sphinx lists the source files (and autosummary generates the pages' stubs)
    app.connect("config-inited", write_pages)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
