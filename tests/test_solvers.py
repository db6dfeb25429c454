"""The solver protocol: what each solver declares matches what it takes, and a fourth solver is one
class and one registry entry (a toy one, registered here, is run by solve, auto, the command line,
scenes, sweeps and the optimizer without any of them knowing its name)."""

from __future__ import annotations

import dataclasses
import importlib
import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import ClassVar

import pytest

from fpe_harvester import Harvester, ParameterError, Scene, Stats, choose_method, get_solver, run_scene, solve, sweep
from fpe_harvester import solvers
from fpe_harvester.cli import main
from fpe_harvester.exact import exact_stats
from fpe_harvester.optimum import optimize
from fpe_harvester.scenes import Axis
from fpe_harvester.scenes.cache import point_seed
from fpe_harvester.solvers import METHODS, Capabilities, Tolerance, option_names, solver_class

# the module, not the function of the same name that the package exports
solve_module = importlib.import_module("fpe_harvester.solve")


@pytest.mark.parametrize("name", list(METHODS))
def test_declared_capabilities_match_the_solver(name: str) -> None:
    cls = solver_class(name)
    caps, fields = cls.capabilities, {f.name: f for f in dataclasses.fields(cls)}
    assert cls.name == name
    if caps.tol is None:
        assert "tol" not in fields
    else:
        assert fields["tol"].default == caps.tol.default
        top = caps.tol.high * (1 - 1e-9) if caps.tol.high_open else caps.tol.high
        assert cls(tol=top).tol == top
        with pytest.raises(ParameterError, match=r"tol must be in \(0, "):
            cls(tol=caps.tol.high if caps.tol.high_open else caps.tol.high * (1 + 1e-9))
    for flag, setting in ((caps.seed, "seed"), (caps.progress, "progress"), (caps.threads, "threads")):
        assert bool(flag) == (setting in fields), (name, setting)
    assert caps.max_time is None or caps.max_time in fields
    assert caps.solve_many == hasattr(cls, "solve_many")


def test_portable_settings_fix_what_the_machine_would_choose() -> None:
    from fpe_harvester.parallel import default_threads

    caps = solvers.capabilities("mc")
    assert caps.portable({}) == {"batch": default_threads()}
    assert caps.portable({"threads": 3}) == {"batch": 3} and caps.portable({"batch": 5, "threads": 3}) == {"batch": 5}


@dataclass(frozen=True)
class Toy:
    """A fourth solver: one harmonic unit by the closed form, with a tolerance, a seed and a time
    budget it records, and one progress line per step."""

    name: ClassVar[str] = "toy"
    capabilities: ClassVar[Capabilities] = Capabilities(title="Toy", tol=Tolerance(0.5, 0.1), seed=True,
                                                        max_time="budget", progress="lines", pooled=True)
    tol: float = 0.1
    seed: int | None = None
    budget: float | None = None
    progress: bool | Callable[[str], None] = False

    def unsupported_reason(self, h: Harvester) -> str | None:
        return None if h.N == 1 and h.is_linear else "the toy solver takes one harmonic unit; use another"

    def solve(self, h: Harvester) -> Stats:
        for step in range(3):
            if callable(self.progress):
                self.progress(f"step {step}")
        res = exact_stats([h])[0]
        return dataclasses.replace(res, method=self.name, info={"tol": self.tol, "seed": self.seed,
                                                                "budget": self.budget})


@dataclass(frozen=True)
class BarToy(Toy):
    """The toy drawing its own progress bar: records the ``progress`` it was given."""

    name: ClassVar[str] = "bartoy"
    capabilities: ClassVar[Capabilities] = dataclasses.replace(Toy.capabilities, title="Bar toy", progress="bar")
    progress: bool | None = None

    def solve(self, h: Harvester) -> Stats:
        return dataclasses.replace(exact_stats([h])[0], method=self.name, info={"progress": self.progress})


@pytest.fixture
def toy() -> Iterator[type]:
    """The toy registered: one entry, the first (auto asks it first)."""
    before = dict(METHODS)
    METHODS.clear()
    METHODS.update({"toy": Toy, **before})
    yield Toy
    METHODS.clear()
    METHODS.update(before)


UNIT, RING = Harvester.build(a=0.5, n=2), Harvester.build(a=0.5, n=2, N=3, k=-0.2)


def test_a_fourth_solver_is_one_class_and_one_entry(toy: type) -> None:
    r = solve(UNIT, "toy", tol=0.2, seed=3, max_seconds=9.0, progress=False)
    assert r.method == "toy" and r.info == {"tol": 0.2, "seed": 3, "budget": 9.0}
    assert r.eta == pytest.approx(20 / 39, rel=1e-14) and r.harvester == UNIT
    assert choose_method(UNIT) == "toy" and choose_method(RING) == "exact"
    ring = solve(RING, tol=0.2)
    assert ring.method == "exact" and ring.info["auto"]["declined"] == {"toy": Toy().unsupported_reason(RING)}
    assert "method auto chose exact; declined: Toy (the toy solver takes one harmonic unit)" in ring.message
    with pytest.raises(ParameterError, match=r"invalid option for method 'toy': no option 'dt'; valid options: tol, "
                                             "seed, budget, progress"):
        get_solver("toy", dt=0.1)


def test_the_command_line_runs_it(toy: type, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["stats", "--method", "toy", "--tol", "0.3", "--seed", "4", "--max-time", "2", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == "toy" and d["info"] == {"tol": 0.3, "seed": 4, "budget": 2.0} and d["harvester"]["a"] == 0.5


def test_scenes_and_sweeps_run_it(toy: type, tmp_path) -> None:
    scene = Scene("toy_scene", system=UNIT, axes=(Axis("a", (0.5, 1.0, 2.0)),), method="toy", rtol=0.25,
                  outputs=())
    for workers in (1, 2):  # pooled: its points also go to a process pool
        res = run_scene(scene, tmp_path / str(workers), progress=False, workers=workers)
        assert [r.method for r in res.rows] == ["toy"] * 3 and res.computed == 3
        info = res.rows[2].info
        assert info["seed"] == point_seed("toy_scene", scene.harvester({"a": 2.0}))
    s = sweep(UNIT, {"a": [0.5, 1.0]}, "toy", tol=0.4)
    assert [r.info["tol"] for r in s.results] == [0.4, 0.4] and s.records()[1]["a"] == 1.0
    with pytest.raises(ParameterError, match="method: 'toy' cannot handle the point .* the toy solver takes one"):
        run_scene(Scene("toy_ring", system=RING, method="toy"), tmp_path / "ring", progress=False)


def test_the_optimizer_asks_what_kind_of_objective_it_gives(toy: type) -> None:
    # the toy has a tolerance and no common random numbers: not an objective the optimizer can use
    with pytest.raises(ParameterError, match="method 'toy' cannot be optimized over: .* Toy gives neither"):
        optimize(RING, method="toy")
    assert optimize(RING).method == "exact"


def test_progress_bars_only_on_a_terminal_and_the_last_line_is_the_reported_value(
        toy: type, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(solve_module, "BAR_DELAY", 0.0)
    monkeypatch.setitem(METHODS, "bartoy", BarToy)
    solve(UNIT, "toy")  # progress=None and stderr is no terminal (captured): no bar
    assert capsys.readouterr().err == ""
    assert solve(UNIT, "bartoy").info["progress"] is False  # a solver drawing its own bar: told not to
    assert solve(UNIT, "bartoy", progress=True).info["progress"] is True
    monkeypatch.setattr(solve_module, "_terminal", lambda: True)
    assert solve(UNIT, "bartoy").info["progress"] is None  # on a terminal: its own rule (and delay)
    assert get_solver("fpe").progress is False  # a solver object keeps its own default
    r = solve(UNIT, "toy")
    err = capsys.readouterr().err
    assert "toy n=2 a=0.5" in err and "3step" in err.replace(" ", "")
    last = err.rstrip().split("\r")[-1]
    assert f"reported eta = {r.eta:.6g}" in last and "(stable)" in last
    solve(UNIT, "toy", progress=False)
    assert capsys.readouterr().err == ""
    lines: list[str] = []
    solve(UNIT, "toy", progress=lines.append)  # a callable receives the lines themselves
    assert lines == ["step 0", "step 1", "step 2"]


def test_option_names_are_the_fields() -> None:
    assert option_names(Toy) == ["tol", "seed", "budget", "progress"]
    assert option_names(dict) == []
    assert isinstance(solvers.title("nope"), str) and solvers.title("fpe") == "Fokker-Planck"
    assert Capabilities(title="x").progress is None
    with pytest.raises(ValueError, match="progress must be None, 'bar' or 'lines'"):
        Capabilities(title="x", progress="dots")


def test_solver_options_reach_the_solver_by_name(toy: type) -> None:
    r = solve(UNIT, solver_options={"toy": {"tol": 0.3, "budget": 1.0}}, tol=0.2)
    assert r.info == {"tol": 0.3, "seed": None, "budget": 1.0, "auto": r.info["auto"]}
    with pytest.raises(ParameterError, match="method must be one of"):
        solve(UNIT, solver_options={"rk4": {}})
    with pytest.raises(ParameterError, match="solver_options.'toy'. must be a mapping"):
        solve(UNIT, solver_options={"toy": 3})
