"""Command line and output files shared by the studies.

Each study module has ``run(quick, out) -> dict``, writes ``<STEM>.json`` and ``<STEM>.png``
with :func:`save_benchmark` (a one-panel study through :func:`run_study`), and runs as
``python -m validation.studies.<module> [--quick] [--out DIR]`` through :func:`bench_main`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["DATA", "bench_main", "save_benchmark", "run_study", "study_runner", "axes_plot"]

#: The folder of the studies' recorded runs (``--out validation/data``) that the report and the
#: docs read.
DATA = Path(__file__).resolve().parents[1] / "data"


def save_benchmark(res: dict, out: Path | str | None, stem: str, plot: Callable[[dict, Path], None]) -> None:
    """Write a benchmark's ``{stem}.json`` and ``{stem}.png`` into ``out`` (nothing if None)."""
    if out is None:
        return
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{stem}.json").write_text(json.dumps(res, indent=2))
    plot(res, out / f"{stem}.png")


def axes_plot(draw: Callable[[dict, Any], None], size: tuple[float, float] = (6.0, 4.2)
              ) -> Callable[[dict, Path], None]:
    """A ``plot(res, path)`` for :func:`save_benchmark` that draws ``res`` on one panel with
    ``draw(res, ax)`` (``size`` in inches)."""

    def plot(res: dict, path: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=size)
        draw(res, ax)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return plot


def run_study(study: Callable[[bool], dict], stem: str, draw: Callable[[dict, Any], None], quick: bool,
              out: Path | str | None) -> dict[str, Any]:
    """Run a one-panel study: ``study(quick)``, with ``quick`` and the wall time [s] added,
    written as ``{stem}.json`` and ``{stem}.png`` (drawn by ``draw(res, ax)``) into ``out``."""
    t0 = time.perf_counter()
    res = {"quick": quick, **study(quick)}
    res["wall_s"] = time.perf_counter() - t0
    save_benchmark(res, out, stem, axes_plot(draw))
    return res


def study_runner(study: Callable[[bool], dict], stem: str, draw: Callable[[dict, Any], None]
                 ) -> Callable[..., dict[str, Any]]:
    """The ``run(quick=False, out=None) -> dict`` of a one-panel study: :func:`run_study` of
    ``study``, written as ``{stem}.json`` and ``{stem}.png`` (drawn by ``draw``)."""

    def run(quick: bool = False, out: Path | str | None = None) -> dict[str, Any]:
        return run_study(study, stem, draw, quick, out)

    run.__doc__ = f"Run :func:`{study.__module__}.{study.__name__}`; write ``{stem}.json`` and ``.png`` into ``out``."
    return run


def bench_main(run: Callable[..., dict], doc: str | None, drop: Sequence[str] = (),
               argv: Sequence[str] | None = None) -> dict:
    """Command line of a benchmark module: ``python -m validation.studies.X [--quick] [--out DIR]``.

    Parses the arguments, calls ``run(quick=..., out=...)`` and prints the result as JSON
    without the keys in ``drop`` (bulky tables that are in the written JSON file anyway).

    Parameters
    ----------
    run : callable
        The benchmark's ``run(quick: bool, out: Path | None) -> dict``.
    doc : str or None
        The module docstring; its first line is the ``--help`` description.
    drop : sequence of str, optional
        Top-level keys of the result left out of the printed JSON (default: none).
    argv : sequence of str, optional
        Arguments to parse instead of ``sys.argv[1:]``.

    Returns
    -------
    dict
        The full result of ``run``.
    """
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    prog = f"python -m {spec.name}" if spec is not None else None  # not the bare "fpe.py"
    ap = argparse.ArgumentParser(prog=prog, description=doc.splitlines()[0] if doc else None)
    ap.add_argument("--quick", action="store_true", help="small subset, well under a minute")
    ap.add_argument("--out", type=Path, default=Path("validation_report"), metavar="DIR",
                    help="folder for the JSON and PNG (default ./validation_report)")
    args = ap.parse_args(argv)
    res = run(quick=args.quick, out=args.out)
    print(json.dumps({k: v for k, v in res.items() if k not in drop}, indent=2))
    return res
