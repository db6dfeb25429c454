"""Command-line interface: ``harvester stats``, ``threshold``, ``optimize``, ``landscape``, ``scene``,
and the subcommands other packages add through the entry-point group :data:`COMMAND_GROUP` (the
validation's ``validate``).

Every command prints a readable table, or one JSON object with ``--json``. Never a traceback:
bad input (an argument out of range, a parameter set whose answer is beyond double precision,
an output folder that cannot be created, a scene no solver can run) gives a one-line error
naming the argument and exit code 2; an interrupt exits 130; anything else is a one-line
internal error with exit code 1 (set ``HARVESTER_DEBUG=1`` for the traceback). A scene that
ends with failed or unavailable points exits 1 and says how many; ``stats --strict`` exits 3
when the status is not ``stable``. The solvers are asked what they take
(:mod:`~fpe_harvester.solvers`): no command knows a method by its name.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import sys
import tomllib
from collections.abc import Callable, Sequence
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from typing import Any, NoReturn

from .errors import HarvesterError, ParameterError
from .exact import threshold
from .model import MAX_EXPONENT, Harvester, Params
from .result import QUANTITIES, Status
from .solve import FALLBACK_SECONDS, solve
from .solvers import METHODS, title

__all__ = ["COMMAND_GROUP", "main", "build_parser", "writable_folder"]

#: Entry-point group of the subcommands other packages add to ``harvester``: each entry is a
#: function ``register(subparsers) -> handler`` that adds its parser and returns the function
#: that runs it (``handler(args) -> exit code``).
COMMAND_GROUP = "fpe_harvester.commands"


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # argparse takes "-1e-3" or "-inf" for an option: let numbers in any notation be values
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$|^-(inf|nan)$",
                                                   re.IGNORECASE)

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}{_param_hint(message)}\n")


#: Physical parameters, which are given as ``--param NAME=VALUE``.
_PARAM_NAMES = tuple(f.name for f in dataclasses.fields(Params))


def _param_hint(message: str) -> str:
    """For an option that is a physical parameter (``--tau -1``), the hint ``--param tau=-1``."""
    if not message.startswith("unrecognized arguments:"):
        return ""
    words = message.removeprefix("unrecognized arguments:").split()
    for i, word in enumerate(words):
        name, _, value = word.removeprefix("--").partition("=")
        if word.startswith("--") and name in _PARAM_NAMES:
            value = value or (words[i + 1] if i + 1 < len(words) else "VALUE")
            return f"; physical parameters are given as --param NAME=VALUE: --param {name}={value}"
    return ""


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    return key.strip(), value.strip()


def _parse_value(text: str) -> Any:
    """Solver option values: int, float, bool or string, in that order of preference."""
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    return text


def _params(pairs: Sequence[tuple[str, str]]) -> Params:
    changes: dict[str, float] = {}
    for key, value in pairs:
        try:
            changes[key] = float(value)
        except ValueError:
            raise ParameterError(f"--param {key}: expected a number, got {value!r}") from None
    return Params().replace(**changes)


def _print_table(rows: Sequence[tuple[str, ...]], header: tuple[str, ...]) -> None:
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(len(header))]
    line = "  ".join("-" * w for w in widths)
    print("  ".join(h.ljust(w) for h, w in zip(header, widths)))
    print(line)
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)))


def _fmt(value: float | None, err: float | None = None) -> tuple[str, str]:
    if value is None:
        return "-", "-"
    return f"{value:.10g}", ("-" if err is None else f"{err:.3g}")


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    """The common settings given (``--tol``, ``--seed``, ``--max-time``, ``--no-progress``) and the
    solver's own (``--opt``)."""
    settings = {key: _parse_value(val) for key, val in args.opt}
    for key in ("tol", "seed", "max_time"):
        if getattr(args, key) is not None:
            settings[key] = getattr(args, key)
    settings["progress"] = False if args.no_progress or args.json else None
    return settings


#: Exit status of ``stats --strict`` when the result's status is not ``stable``.
NOT_STABLE = 3


def cmd_stats(args: argparse.Namespace) -> int:
    h = Harvester.build(a=args.a, n=args.n, N=args.N, k=args.k, k4=args.k4, k3=args.k3)
    h = h.replace(params=_params(args.param))
    result = solve(h, args.method, fallback_time=args.fallback_time, **_settings(args))
    code = NOT_STABLE if args.strict and result.status is not Status.STABLE else 0
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
        return code
    print(
        f"Harvester: U(x) = {h.a:g}|x|^{h.n:g}, N = {h.N}, k = {h.k:g}{_higher_couplings(h)}; "
        f"method = {result.method}; status = {result.status.value}"
    )
    if result.message and result.message != "stable":
        print(result.message)
    ignored = [f"--{key.replace('_', '-')}" for key in result.info.get("ignored", ())]
    if ignored:
        print(f"note: the {title(result.method)} solver has no use for {', '.join(ignored)}: ignored")
    rows = [(name, *_fmt(*result.value(name))) for name in QUANTITIES]
    _print_table(rows, ("quantity", "value", "error"))
    if result.growth_rate is not None:
        print(f"largest growth rate of the drift: {result.growth_rate:.6g}")
    return code


def _higher_couplings(h: Harvester) -> str:
    """``", k4 = .., k3 = .."`` for the couplings beyond the diffusive one that are nonzero."""
    return "".join(f", {name} = {value:g}" for name, value in (("k4", h.k4), ("k3", h.k3)) if value != 0.0)


def cmd_threshold(args: argparse.Namespace) -> int:
    th = threshold(args.N, args.a, args.k4)
    if args.json:
        print(json.dumps(th.to_dict(), indent=2))
        return 0
    kd = "none (always stable)" if th.k_di is None else f"{th.k_di:.12g}"
    _print_table(
        [("k_di", kd, ""), ("critical_mode", ", ".join(map(str, th.critical_mode)), "")],
        ("quantity", "value", ""),
    )
    print(th.explanation)
    return 0


def cmd_optimize(args: argparse.Namespace) -> int:
    """The coupling (or other parameter) that maximizes eta, with error bars."""
    from .optimum import optimize

    h = Harvester.build(a=args.a, n=args.n, N=args.N, k4=args.k4, k3=args.k3).replace(params=_params(args.param))
    opt = optimize(h, args.over, None if args.bounds is None else tuple(args.bounds), args.maximize,
                   method=args.method, tol=args.tol, seed=args.seed, batches=args.batches,
                   replicas=args.replicas, progress=False if args.no_progress or args.json else None)
    if args.json:
        print(json.dumps({**opt.to_dict(), "harvester": h.to_dict()}, indent=2))
        return 0
    print(f"Harvester: U(x) = {h.a:g}|x|^{h.n:g}, N = {h.N}{_higher_couplings(h)}; maximize {opt.maximize} "
          f"over {opt.over}; method = {opt.method}; status = {opt.status.value}")
    print(opt.message)
    level = f"{opt.confidence:.0%} interval"

    def ci(pair: tuple[float, float] | None) -> str:
        return "-" if pair is None else f"[{pair[0]:.6g}, {pair[1]:.6g}]"

    _print_table([(f"{opt.over}_opt", *_fmt(opt.x_opt, opt.x_opt_err), ci(opt.x_ci)),
                  (f"{opt.maximize}_max", *_fmt(opt.value, opt.value_err), ci(opt.value_ci))],
                 ("quantity", "value", "error", level))
    if "wall_time" in opt.info:
        print(f"{opt.info.get('evaluations')} {title(opt.method)} runs in {opt.info['wall_time']:.1f} s")
    return 0


def cmd_landscape(args: argparse.Namespace) -> int:
    """Equilibria of the coupled potential, with energies and Morse index; buckling for n = 1."""
    from .landscape import RingEnergy, landscape

    ls = landscape(RingEnergy(n=args.n, a=args.a, N=args.N, k=args.k, k4=args.k4, k3=args.k3))
    if args.json:
        print(json.dumps(ls.to_dict(), indent=2))
        return 0
    e = ls.energy
    print(f"E(x) = {_energy_text(e)}, N = {e.N}")
    print(ls.message)
    if ls.buckling is not None:
        b = ls.buckling
        rows = [("k_sn (fold)", f"{b.k_sn:.10g}"), ("k_co (coexistence)", f"{b.k_co:.10g}")]
        rows += [(name, "-" if value is None else f"{value:.10g}") for name, value in (
            ("u_s", b.u_s), ("u_plus", b.u_plus), ("escape_barrier", b.escape_barrier),
            ("return_barrier", b.return_barrier), ("u_hop", b.u_hop), ("hop_barrier", b.hop_barrier))]
        _print_table(rows, ("single-site buckling", "value"))
        print()
    rows = [(q.kind, f"{q.energy:.10g}", str(q.index), " ".join(f"{v:.6g}" for v in q.x))
            for q in ls.equilibria[:args.max_rows]]
    _print_table(rows, ("equilibrium", "energy", "index", "x"))
    if len(ls.equilibria) > args.max_rows:
        print(f"... {len(ls.equilibria) - args.max_rows} more (--max-rows, or --json for all)")
    return 0


def _energy_text(e: Any) -> str:
    """The ring energy with its nonzero terms only, each coefficient's sign written once:
    ``sum 1|x_j|^1 - (2/2) sum d^2 + (1/4) sum d^4``."""
    text = f"sum {e.a:g}|x_j|^{e.n:g}"
    for coefficient, divisor, term in ((e.k, 2, "sum d^2"), (e.k4, 2, "sum (Lx)^2"), (e.k3, 4, "sum d^4")):
        if coefficient != 0.0:
            text += f" {'-' if coefficient < 0 else '+'} ({abs(coefficient):g}/{divisor}) {term}"
    return text


def writable_folder(flag: str, path: str) -> str:
    """``path`` after creating it, or a :class:`ParameterError` naming ``flag`` if that fails."""
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"{flag} {path!r}: cannot create the output folder ({exc.strerror or exc})") from None
    if not os.access(path, os.W_OK):
        raise ParameterError(f"{flag} {path!r}: the output folder is not writable")
    return path


def _scheduler(args: argparse.Namespace) -> str | None:
    """Where scene points run: ``--scheduler``, ``--dask local``, else ``DASK_SCHEDULER_ADDRESS``
    unless ``--workers`` asks for local processes, else this process (``None``)."""
    if args.scheduler or args.dask:
        return args.scheduler or args.dask
    if args.workers is None:
        return os.environ.get("DASK_SCHEDULER_ADDRESS") or None
    return None


def _with_couplings(scene: Any, args: argparse.Namespace) -> Any:
    """``scene`` (and its quick variant) with ``--k4`` / ``--k3`` set in its system, if given."""
    changes = {name: value for name, value in (("k4", args.k4), ("k3", args.k3)) if value is not None}
    if not changes:
        return scene
    quick = None if scene.quick is None else _with_couplings(scene.quick, args)
    return dataclasses.replace(scene, system=scene.system.replace(**changes), quick=quick)


def cmd_scene(args: argparse.Namespace) -> int:
    """List the shipped scenes, or run one and print its table and output paths."""
    from .scenes import list_scenes, load_scene, run_scene
    from .scenes.result import ERROR, NOT_AVAILABLE

    if args.action == "list":
        scenes = [load_scene(name) for name in list_scenes()]
        if args.json:
            print(json.dumps([{"name": s.name, "title": s.title, "points": s.n_points,
                               "quick_points": s.variant(True).n_points} for s in scenes], indent=2))
            return 0
        _print_table([(s.name, f"{s.n_points}/{s.variant(True).n_points}", s.title) for s in scenes],
                     ("scene", "points (full/quick)", "title"))
        return 0
    out = writable_folder("--out", args.out)
    try:
        result = run_scene(_with_couplings(load_scene(args.scene), args), out, quick=args.quick,
                           progress=False if args.no_progress or args.json else None, workers=args.workers,
                           scheduler=_scheduler(args))
    except KeyboardInterrupt:
        from .scenes.cache import CACHE_NAME, PointCache

        saved = len(PointCache(Path(out)))
        print(f"harvester scene run: interrupted; {saved} finished points are saved in "
              f"{Path(out) / CACHE_NAME}: run the same command again to resume (they are reused, only the "
              "others are computed)", file=sys.stderr)
        return 130
    failed = sum(row.status in (ERROR, NOT_AVAILABLE) for row in result.rows)
    if args.json:
        print(json.dumps(result.to_dict(), indent=2, default=str))
        return _failed_points(failed, len(result.rows))
    print(f"{result.scene.title or result.scene.name}{' (quick)' if args.quick else ''}")
    print(result.table())
    print(f"\n{len(result.rows)} points: {result.computed} computed, {result.reused} reused, "
          f"{result.elapsed:.1f} s")
    if result.cache_skipped:
        print(f"points.jsonl: {result.cache_skipped} unreadable lines skipped (partial, garbled or invalid); "
              "their points were computed again")
    for label, path in (("csv", result.csv_path), ("json", result.json_path),
                        ("table", result.table_path), *result.figures.items()):
        if path is not None:
            print(f"{label}: {path}")
    return _failed_points(failed, len(result.rows))


def _failed_points(failed: int, total: int) -> int:
    """Exit status of a scene run: 1 (and a line on stderr) when points failed or had no solver."""
    if not failed:
        return 0
    print(f"harvester scene run: {failed} of {total} points failed or had no solver available (status error "
          "or not_available; their messages say why); the others are saved", file=sys.stderr)
    return 1


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "scene": cmd_scene,
    "stats": cmd_stats,
    "threshold": cmd_threshold,
    "optimize": cmd_optimize,
    "landscape": cmd_landscape,
}


def _coupling_arguments(p: argparse.ArgumentParser, default: float | None = 0.0) -> None:
    """--k4 and --k3, the couplings beyond the diffusive one."""
    p.add_argument("--k4", type=_number, default=default,
                   help="bi-Laplacian coupling k4, any real (default 0): adds k4 mu_q^2 to mode q's stiffness")
    p.add_argument("--k3", type=_number, default=default,
                   help="cubic bond coupling k3 >= 0 (default 0): bond energy (k3/4) d^4; nonlinear")


def _harvester_arguments(p: argparse.ArgumentParser, N: int) -> None:
    """--n, --a, --N (default ``N``), --k4, --k3 and --param: the harvester of ``stats`` and ``optimize``."""
    p.add_argument("--n", type=_number, default=2.0, help=f"potential exponent n in [1, {MAX_EXPONENT:g}] (default 2)")
    p.add_argument("--a", type=_number, default=0.5, help="potential strength a > 0 (default 0.5)")
    p.add_argument("--N", type=int, default=N, help=f"number of units in the ring (default {N})")
    _coupling_arguments(p)
    p.add_argument("--param", type=_key_value, action="append", default=[], metavar="NAME=VALUE",
                   help="physical parameter (m, gamma, Kv, Kc, sigma, tau, D, tau_p, R); repeatable")


def command_plugins() -> list[EntryPoint]:
    """The entry points of :data:`COMMAND_GROUP`: from the installed metadata, else from the
    pyproject.toml of the source tree this module runs from (an editable install made before
    the group was declared has none in its metadata until it is reinstalled)."""
    found = list(entry_points(group=COMMAND_GROUP))
    pyproject = Path(__file__).resolve().parents[1] / "pyproject.toml"
    if found or not pyproject.is_file():
        return found
    declared = tomllib.loads(pyproject.read_text()).get("project", {}).get("entry-points", {})
    return [EntryPoint(name, value, COMMAND_GROUP) for name, value in declared.get(COMMAND_GROUP, {}).items()]


def _add_plugins(sub: Any) -> None:
    """Let each :func:`command_plugins` entry add its subcommand; one whose package cannot be
    imported is left out (``harvester`` works without it)."""
    for ep in command_plugins():
        try:
            register = ep.load()
        except ImportError:
            continue
        handler = register(sub)
        sub.choices[ep.name].set_defaults(handler=handler)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (exposed for documentation and tests)."""
    parser = _Parser(prog="harvester", description="Power and efficiency of noise-driven harvesters.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("stats", help="stationary statistics (eta, V2, Vrms, Pin) of one harvester")
    _harvester_arguments(p, N=1)
    p.add_argument("--k", type=_number, default=0.0, help="coupling k (default 0)")
    p.add_argument("--method", choices=("auto", *METHODS), default="auto",
                   help="solver (default auto: the first of exact, fpe, mc that handles the system)")
    p.add_argument("--tol", type=_number, default=None,
                   help="requested relative error on eta, in (0, 1) (each solver checks its own range; one "
                        "without a tolerance, exact, ignores it)")
    p.add_argument("--seed", type=int, default=None, help="random seed, >= 0 (a deterministic solver ignores it)")
    p.add_argument("--max-time", type=_number, default=None, metavar="SECONDS",
                   help="wall-time budget of the solver, > 0 (one without a budget ignores it)")
    p.add_argument("--opt", type=_key_value, action="append", default=[], metavar="NAME=VALUE",
                   help="a setting of the solver itself (e.g. dt=0.01 for mc, M=8 for fpe); repeatable")
    p.add_argument("--fallback-time", type=_number, default=FALLBACK_SECONDS, metavar="SECONDS",
                   help="method auto: where the answering solver stops short of the tolerance, the next one "
                        "runs for at most this many seconds and gives the numbers if better "
                        f"(default {FALLBACK_SECONDS:g}; 0: no fallback)")
    p.add_argument("--strict", action="store_true",
                   help=f"exit with status {NOT_STABLE} when the result is not stable (marginal, unstable, "
                        "metastable or not converged); without it the status is only printed")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    p = sub.add_parser("threshold", help="diffusive-instability threshold k_di of a harmonic ring")
    p.add_argument("--N", type=int, default=3, help="number of units (default 3)")
    p.add_argument("--a", type=_number, default=0.5, help="potential strength a > 0 (default 0.5)")
    p.add_argument("--k4", type=_number, default=0.0, help="bi-Laplacian coupling k4, any real (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser("optimize", help="the coupling k (or another parameter) that maximizes eta, with errors")
    _harvester_arguments(p, N=3)
    p.add_argument("--over", default="k", help="parameter varied (default k; a, n or a --param name)")
    p.add_argument("--maximize", default="eta", help="observable maximized (default eta)")
    p.add_argument("--bounds", type=_number, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="search interval (default for k: [k_di, 0] harmonic, [3 k_di, 0] nonlinear)")
    p.add_argument("--method", choices=("auto", *METHODS), default="auto",
                   help="solver of the objective (default auto: the first that handles the system and gives "
                        "an exact or a common-random-number objective: exact for n = 2, else mc)")
    p.add_argument("--tol", type=_number, default=None,
                   help="random objective: target standard error of the optimum's position, > 0 (adds batches)")
    p.add_argument("--batches", type=int, default=8, help="independent common-random-number batches, >= 3")
    p.add_argument("--replicas", type=int, default=48, help="replicas per point and batch of a random objective, >= 2 (default 48)")
    p.add_argument("--seed", type=int, default=2017, help="base random seed, >= 0 (default 2017)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    p = sub.add_parser("landscape", help="equilibria of the coupled potential: energies, Morse index, barriers")
    p.add_argument("--n", type=_number, default=1.0, help=f"potential exponent n in [1, {MAX_EXPONENT:g}] (default 1)")
    p.add_argument("--a", type=_number, default=1.0, help="potential strength a > 0 (default 1)")
    p.add_argument("--N", type=int, default=3, help="number of units, 1 to 6 (default 3)")
    p.add_argument("--k", type=_number, default=0.0, help="diffusive coupling k (default 0)")
    _coupling_arguments(p)
    p.add_argument("--max-rows", type=int, default=40, help="equilibria listed in the table (default 40)")
    p.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser("scene", help="declarative studies: the paper's figures and more")
    scene_sub = p.add_subparsers(dest="action", required=True, parser_class=_Parser)
    q = scene_sub.add_parser("list", help="shipped scenes")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q = scene_sub.add_parser("run", help="run a scene: table, CSV/JSON and figures")
    q.add_argument("scene", metavar="NAME_OR_PATH", help="shipped scene name or TOML file")
    q.add_argument("--out", default="scene_output", metavar="DIR",
                   help="output folder; its points.jsonl cache is reused by later runs (default ./scene_output)")
    q.add_argument("--quick", action="store_true", help="the scene's reduced variant")
    _coupling_arguments(q, default=None)
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.add_argument("--no-progress", action="store_true", help="no progress bar")
    q.add_argument("--workers", type=int, default=None, metavar="P",
                   help="processes for the points of single-threaded solvers, Fokker-Planck (default 1; Monte "
                        "Carlo runs its own threads); "
                        "with --dask local: the cluster's workers (default: one per CPU)")
    where = q.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the points on the Dask cluster of this scheduler, e.g. tcp://host:8786 "
                            "(default: $DASK_SCHEDULER_ADDRESS if set and --workers is not given)")
    where.add_argument("--dask", choices=("local",),
                       help="run the points on a local Dask cluster (one worker per CPU)")
    _add_plugins(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``harvester`` command; returns the exit code.

    0 on success (``validate``: 1 if a check failed; ``scene run``: 1 if points failed; ``stats
    --strict``: 3 unless stable), 2 for bad input, 130 when interrupted, 1 for an internal error;
    every error is one line on stderr, never a traceback (unless the environment variable
    ``HARVESTER_DEBUG`` is set, for bug reports).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    prefix = f"harvester {args.command}"
    try:
        return COMMANDS[args.command](args) if args.command in COMMANDS else args.handler(args)
    except HarvesterError as exc:
        print(f"{prefix}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # output piped into e.g. `head`: stop quietly, as Unix tools do
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"{prefix}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - the promise is one line, never a traceback
        if os.environ.get("HARVESTER_DEBUG"):
            raise
        print(f"{prefix}: internal error: {type(exc).__name__}: {_one_line(exc)} (a bug: please report it; "
              "HARVESTER_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
