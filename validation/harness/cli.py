"""Command line of the validation: ``harvester validate`` and ``python -m validation``.

The validation adds its subcommand to ``harvester`` through the entry-point group
``fpe_harvester.commands`` (declared in pyproject.toml): :func:`register` adds the ``validate``
parser and returns the function that runs it, so that the library never imports its
validation. :func:`main` is the same command on its own (``python -m validation``, and the
``harvester-validate`` script).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

from fpe_harvester.cli import writable_folder
from fpe_harvester.errors import ParameterError

from .runner import run_cli

__all__ = ["add_arguments", "register", "run", "build_parser", "main"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``validate``: --quick, --out, --seed, --no-progress, --bench."""
    p.add_argument("--quick", action="store_true", help="CI subset, under 3 minutes")
    p.add_argument("--out", default="validation_report", metavar="DIR",
                   help="output folder for report.md, report.html, figures (default ./validation_report)")
    p.add_argument("--seed", type=int, default=2017, help="base Monte Carlo seed (default 2017)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--bench", default=None, metavar="DIR",
                   help="include the exhaustive benchmarks written by python -m validation.studies.* --out DIR")


def run(args: argparse.Namespace) -> int:
    """Run the validation with parsed ``args``; returns the exit code of :func:`.runner.run_cli`.

    Raises
    ------
    ParameterError
        A negative --seed, an --out folder that cannot be written or a --bench that is not a folder.
    """
    if args.seed < 0:
        raise ParameterError(f"--seed must be >= 0, got {args.seed}")
    if args.bench is not None and not os.path.isdir(args.bench):
        raise ParameterError(f"--bench {args.bench!r}: not a folder (give the --out folder of "
                             "python -m validation.studies.fpe.bench, .mc.bench or .exact.bench)")
    return run_cli(quick=args.quick, out=writable_folder("--out", args.out), seed=args.seed,
                   progress=not args.no_progress, bench=args.bench)


def register(subparsers: Any) -> Callable[[argparse.Namespace], int]:
    """Add ``validate`` to ``harvester``'s subcommands (entry point of ``fpe_harvester.commands``).

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The ``harvester`` parser's subcommands.

    Returns
    -------
    callable
        :func:`run`, which ``harvester`` calls with the parsed arguments.
    """
    add_arguments(subparsers.add_parser(
        "validate", help="cross-checks, paper comparison, stress tests, benchmarks -> report"))
    return run


def build_parser() -> argparse.ArgumentParser:
    """Arguments of ``python -m validation`` (the same as ``harvester validate``)."""
    p = argparse.ArgumentParser(prog="python -m validation", description=__doc__.splitlines()[0])
    add_arguments(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m validation``; returns the exit code (2 for bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return run(args)
    except ParameterError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
