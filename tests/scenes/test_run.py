"""Running scenes: exact batching vs pointwise solve, cache and resume, outputs, failures."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from dataclasses import replace

import numpy as np
import pytest

from fpe_harvester.errors import MethodNotAvailableError, NotConvergedError
from fpe_harvester.exact import Exact, exact_sweep, k_di
from fpe_harvester.model import Harvester, Params
from fpe_harvester.scenes import Axis, FigureSpec, Optimize, Ref, Scene, load_scene
from fpe_harvester.scenes import run as scene_run
from fpe_harvester.scenes.cache import CACHE_NAME, point_seed
from fpe_harvester.solve import solve


def harmonic_scene(**kw: object) -> Scene:
    base = dict(
        name="tiny",
        system=Harvester.build(a=0.5, n=2, N=3),
        axes=(Axis("a", (0.5, 1.0)), Axis("k", (0.2, 0.0, -0.2, -1 / 3, -0.4))),
        observables=("eta", "V2", "Vrms", "Pin", "v2", "vV"),
        figures=(FigureSpec("eta_vs_k", x="k", y=("eta", "Vrms"), series="a",
                            refs=(Ref("vline", x="k_di"), Ref("point", x=-0.33, y=0.677))),
                 FigureSpec("pin_vs_k", x="k", y=("Pin",)),
                 FigureSpec("eta_map", x="k", y=("eta",), series="a", kind="map")),
    )
    base.update(kw)
    return Scene(**base)  # type: ignore[arg-type]


class Counter:
    """Wraps a function, counting calls; raises KeyboardInterrupt after ``stop_after`` calls."""

    def __init__(self, fn, stop_after: int | None = None) -> None:
        self.fn, self.calls, self.stop_after = fn, 0, stop_after

    def __call__(self, *args, **kwargs):
        if self.stop_after is not None and self.calls >= self.stop_after:
            raise KeyboardInterrupt
        self.calls += 1
        return self.fn(*args, **kwargs)


def count_batches(monkeypatch) -> list[int]:
    """Record the size of every vectorized call of the exact solver."""
    sizes: list[int] = []
    real = Exact.solve_many

    def counted(self: Exact, hs):
        sizes.append(len(hs))
        return real(self, hs)

    monkeypatch.setattr(Exact, "solve_many", counted)
    return sizes


def test_vectorized_exact_matches_pointwise_solve(tmp_path: Path, monkeypatch) -> None:
    batches = count_batches(monkeypatch)
    sc = harmonic_scene(observables=("eta", "V2", "Vrms", "Pin", "v2", "vV", "x2"), figures=())
    res = scene_run.run_scene(sc, tmp_path, progress=False)
    assert batches == [10]  # one vectorized call for the whole (N = 3) sweep
    assert len(res.rows) == 10 and res.computed == 10
    for row in res.rows:
        h = sc.harvester(row.point)
        ref = solve(h)
        assert row.status == ref.status.value and row.method == "exact"
        for obs in sc.observables:
            val, err = ref.value(obs)
            if val is None:
                assert row.values[obs] is None
            else:
                assert row.values[obs] == pytest.approx(val, rel=1e-12)
                assert row.values[obs + "_err"] == err
    # a = 0.5: k_di = -1/3 is marginal and k = -0.4 unstable; a = 1 (k_di = -2/3): all stable
    assert [row.status for row in res.rows[:5]] == ["stable"] * 3 + ["marginal", "unstable"]
    assert all(row.status == "stable" for row in res.rows[5:])


def as_harmonic(h: Harvester, method: str, **opts: object):
    """Stand-in for a slow pointwise solver: the exact result of the harmonic counterpart."""
    return solve(h.replace(n=2.0), "exact")


def test_resume_after_interruption_recomputes_nothing(tmp_path: Path, monkeypatch) -> None:
    # a nonlinear ring is solved point by point (here by a stand-in), each point cached when done
    sc = Scene("nl", system=Harvester.build(a=0.5, n=3, N=3), observables=("eta", "x2"),
               axes=(Axis("k", tuple(np.linspace(0.2, -0.3, 6))),))
    interrupted = Counter(as_harmonic, stop_after=4)
    monkeypatch.setattr(scene_run, "solve", interrupted)
    with pytest.raises(KeyboardInterrupt):
        scene_run.run_scene(sc, tmp_path, progress=False)
    lines = (tmp_path / CACHE_NAME).read_text().splitlines()
    assert len(lines) == 4  # every finished point was written before the interruption
    second = Counter(as_harmonic)
    monkeypatch.setattr(scene_run, "solve", second)
    res = scene_run.run_scene(sc, tmp_path, progress=False)
    assert second.calls == 2 and res.computed == 2 and res.reused == 4
    third = Counter(as_harmonic)
    monkeypatch.setattr(scene_run, "solve", third)
    again = scene_run.run_scene(sc, tmp_path, progress=False)
    assert third.calls == 0 and again.reused == 6
    assert [r.values for r in again.rows] == [r.values for r in res.rows]


def test_cache_survives_a_partial_last_line_and_keys_on_accuracy(tmp_path: Path, monkeypatch) -> None:
    sc = harmonic_scene(figures=())
    scene_run.run_scene(sc, tmp_path, progress=False)
    with (tmp_path / CACHE_NAME).open("a") as fh:
        fh.write('{"key": "abc", "stats": {"V2": 0.1')  # run killed mid-write
    batches = count_batches(monkeypatch)
    res = scene_run.run_scene(sc, tmp_path, progress=False)
    assert batches == [] and res.reused == 10
    # the exact solver ignores rtol, so a different accuracy still reuses exact points
    res = scene_run.run_scene(harmonic_scene(rtol=1e-2, figures=()), tmp_path, progress=False)
    assert res.reused == 10


def test_only_requested_observables_figures_and_outputs(tmp_path: Path) -> None:
    sc = harmonic_scene(observables=("eta",), outputs=("csv",))
    res = scene_run.run_scene(sc, tmp_path, progress=False, figures=["pin_vs_k"])
    assert set(res.figures) == {"pin_vs_k"} and res.figures["pin_vs_k"].exists()
    assert not (tmp_path / "tiny_eta_vs_k.png").exists()
    assert res.json_path is None and res.table_path is None and not (tmp_path / "tiny.json").exists()
    assert all(set(r.values) == {"eta", "eta_err"} for r in res.rows)
    with res.csv_path.open() as fh:
        header = next(csv.reader(fh))
    assert header == ["a", "k", "eta", "eta_err", "status", "method", "message"]
    none = scene_run.run_scene(sc, tmp_path / "none", progress=False, figures=[])
    assert not none.figures and not list((tmp_path / "none").glob("*.png"))
    with pytest.raises(Exception, match="figure 'nope' is not in scene 'tiny'"):
        scene_run.run_scene(sc, tmp_path, progress=False, figures=["nope"])


def test_all_outputs_written(tmp_path: Path) -> None:
    res = scene_run.run_scene(harmonic_scene(), tmp_path, progress=False)
    data = json.loads(res.json_path.read_text())
    assert data["scene"] == "tiny" and len(data["rows"]) == 10
    assert data["spec"]["axes"]["k"]["values"][-1] == -0.4 and data["spec"]["figures"][0]["series"] == "a"
    unstable = [r for r in data["rows"] if r["status"] == "unstable"]
    assert unstable and all(r["eta"] is None for r in unstable)  # never NaN
    text = res.table()
    assert "unstable: k = -0.4 is beyond k_di" in text and set(res.figures) == {"eta_vs_k", "pin_vs_k", "eta_map"}
    assert res.table_path.read_text().startswith("a ")


def test_derived_only_scene_needs_no_solver(tmp_path: Path, monkeypatch) -> None:
    calls = Counter(solve)
    monkeypatch.setattr(scene_run, "solve", calls)
    sc = Scene("kdi", system=Harvester.build(n=2), axes=(Axis("N", (1, 2, 3)),), observables=("k_di",))
    res = scene_run.run_scene(sc, tmp_path, progress=False)
    assert calls.calls == 0
    assert [r.values["k_di"] for r in res.rows] == [None, k_di(2, 0.5), k_di(3, 0.5)]


def fake_nonlinear_scene() -> Scene:
    return Scene("nl", system=Harvester.build(a=0.5, n=3, N=3), axes=(Axis("k", (0.0, -0.5, -0.2)),),
                 observables=("eta",), rtol=0.05,
                 figures=(FigureSpec("eta_vs_k", x="k", y=("eta",)),))


def test_failures_are_reported_per_point_and_retried(tmp_path: Path, monkeypatch) -> None:
    seen: list[dict] = []

    def flaky(h, method, solver_options, **opts):
        seen.append({"method": method, **solver_options["mc"]})
        if h.k == 0.0:
            raise MethodNotAvailableError("method 'mc' is not available yet")
        if h.k == -0.5:
            raise NotConvergedError("did not reach tol")
        return solve(h.replace(n=2.0), "exact")

    monkeypatch.setattr(scene_run, "solve", flaky)
    res = scene_run.run_scene(fake_nonlinear_scene(), tmp_path, progress=False)
    assert [r.status for r in res.rows] == ["not_available", "error", "stable"]
    assert "not available yet" in res.rows[0].message and "NotConvergedError" in res.rows[1].message
    assert res.rows[0].values["eta"] is None and res.figures["eta_vs_k"].exists()
    # coupled nonlinear ring -> Monte Carlo with tol = rtol and a seed from the scene and point
    assert all(s["method"] == "auto" and s["tol"] == 0.05 for s in seen)
    assert [r.method for r in res.rows] == ["mc", "mc", "exact"]
    h0 = fake_nonlinear_scene().harvester({"k": 0.0})
    assert seen[0]["seed"] == point_seed("nl", h0) != seen[1]["seed"]
    seen.clear()
    res = scene_run.run_scene(fake_nonlinear_scene(), tmp_path, progress=False)
    assert len(seen) == 2 and res.reused == 1  # failed points are tried again, the good one reused


def test_optimize_at_threshold_and_interior(tmp_path: Path) -> None:
    sc = Scene("opt", system=Harvester.build(a=0.5, n=2), axes=(Axis("N", (1, 2, 3)),),
               observables=("eta",), optimize=Optimize("eta", "k", ("k_di", 0.0), points=9))
    res = scene_run.run_scene(sc, tmp_path, progress=False)
    assert res.rows[0].point["k"] == 0.0 and res.rows[0].values["eta"] == pytest.approx(20 / 39)
    for row, N in zip(res.rows[1:], (2, 3)):
        dense = exact_sweep(0.5, np.linspace(k_di(N, 0.5), 0.0, 2001), N)["eta"]
        assert row.point["k"] == k_di(N, 0.5) and row.status == "marginal"
        assert row.values["eta"] == pytest.approx(dense.max(), rel=1e-12)
        assert "the largest eta on the grid is at the low end" in row.message
    # <vV> has an interior maximum over tau_p: the grid cell is refined by a bounded optimizer
    sc = Scene("opt2", system=Harvester.build(a=0.5, n=2), observables=("vV",),
               optimize=Optimize("vV", "tau_p", (0.1, 5.0), points=7))
    row = scene_run.run_scene(sc, tmp_path, progress=False).rows[0]
    grid = np.linspace(0.8, 0.95, 30001)
    vv = [float(exact_sweep(0.5, 0.0, 1, Params(tau_p=t))["vV"]) for t in grid[::100]]
    best = grid[::100][int(np.argmax(vv))]
    assert row.point["tau_p"] == pytest.approx(best, abs=1e-2 * 0.15)
    assert row.values["vV"] >= max(vv) - 1e-12
    assert row.info["optimize"]["at_bound"] is None


def test_optimize_monte_carlo_points_use_the_noisy_optimizer(tmp_path: Path, monkeypatch) -> None:
    from fpe_harvester import Optimum, Status

    asked: list[dict] = []

    def fake_optimize(h, over, bounds, maximize, **kw):
        asked.append({"h": h, "over": over, "bounds": bounds, **kw})
        return Optimum(over, maximize, -0.3, 0.002, 0.553, 0.0006, (-0.304, -0.296), (0.5518, 0.5542),
                       status=Status.STABLE, method="mc", message="converged", info={"window": [], "batches": 8})

    monkeypatch.setattr(scene_run, "optimize", fake_optimize)
    # the final solve at k_opt: its harmonic twin stands in for Monte Carlo (stable at k = -0.3)
    monkeypatch.setattr(scene_run, "solve", lambda h, method, **o: solve(h.replace(n=2.0), "exact"))
    sc = Scene("nlopt", system=Harvester.build(a=0.5, n=3, N=3), observables=("eta", "Vrms"),
               optimize=Optimize("eta", "k", (-1.0, 0.0), points=9))
    row = scene_run.run_scene(sc, tmp_path, progress=False, figures=[]).rows[0]
    assert asked[0]["bounds"] == (-1.0, 0.0) and asked[0]["method"] == "mc"
    assert asked[0]["seed"] == point_seed("nlopt", sc.harvester({}))
    assert row.point["k"] == -0.3 and (row.values["eta"], row.values["eta_err"]) == (0.553, 0.0006)
    assert row.values["Vrms"] is not None and row.info["optimize"]["x_opt_err"] == 0.002
    assert row.status == "stable" and row.message.startswith("converged")


def test_shipped_harmonic_scene_quick(tmp_path: Path) -> None:
    res = scene_run.run_scene(load_scene("fig4_eta_vs_k_harmonic"), tmp_path, quick=True, progress=False)
    row = next(r for r in res.rows if r.point["k"] == pytest.approx(-0.33))
    assert row.values["eta"] == pytest.approx(0.6773938564, rel=1e-9)
    assert row.values["Vrms"] ** 2 == pytest.approx(0.2302970396, rel=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fig1_eta_vs_n", "fig2_eta_vs_k_n1_ring", "fig3_eta_vs_k_n3_ring",
                                  "fig5_optimum_vs_N", "fig6_eta_vs_k_several_a", "kdi_map"])
def test_shipped_scene_quick_runs(tmp_path: Path, name: str) -> None:
    """Every figure drawn, every status true for its system, the accuracy asked for met by every
    stable row, harmonic rows equal to the 60-digit closed form (validation.sections.figures.row_checks)."""
    from validation.sections.figures import row_checks

    res = scene_run.run_scene(load_scene(name), tmp_path, quick=True, progress=False)
    assert res.rows and len(res.figures) == len(res.scene.figures)
    assert all(p.exists() for p in res.figures.values())
    failed = [c.detail for c in row_checks(name, res.scene, res.rows) if not c.passed]
    assert not failed, failed


def test_parallel_workers_match_serial(tmp_path: Path, monkeypatch) -> None:
    # pooling the pointwise stand-in (normally only "fpe" points are pooled) exercises the pool
    # cheaply; the forked workers inherit the patched solve
    sc = Scene("nl", system=Harvester.build(a=0.5, n=3, N=3), observables=("eta", "x2"),
               axes=(Axis("a", (0.5, 1.0)), Axis("k", (0.2, 0.0, -0.2, -0.3, -0.1))))
    monkeypatch.setattr(scene_run, "solve", as_harmonic)
    serial = scene_run.run_scene(sc, tmp_path / "serial", progress=False, workers=1)
    from montecarlo import MonteCarlo

    monkeypatch.setattr(MonteCarlo, "capabilities", replace(MonteCarlo.capabilities, pooled=True))
    parallel = scene_run.run_scene(sc, tmp_path / "parallel", progress=False, workers=2)
    assert parallel.computed == 10
    assert [r.values for r in parallel.rows] == [r.values for r in serial.rows]
    assert len((tmp_path / "parallel" / "points.jsonl").read_text().splitlines()) == 10
    with pytest.raises(Exception, match=r"workers must be an integer in \[1, inf\], got 0"):
        scene_run.run_scene(sc, tmp_path, workers=0)


def test_auto_falls_back_to_monte_carlo_when_fokker_planck_misses_the_tolerance(tmp_path, monkeypatch):
    # Fokker-Planck (inside its domain) returns numbers whose error exceeds the scene's rtol:
    # Monte Carlo is tried, and kept when it reaches the tolerance or does better
    from fpe_harvester.fpe import FokkerPlanck
    from fpe_harvester.result import Status
    from montecarlo import MonteCarlo

    exact = solve(Harvester.build(a=0.5, n=2), "exact")
    fpe = replace(exact, method="fpe", status=Status.NOT_CONVERGED, eta_err=0.01 * exact.eta,
                  message="fpe stopped")
    outcomes = {"fpe": fpe, "mc": replace(exact, method="mc", eta_err=0.004 * exact.eta, message="mc ok")}
    for cls in (FokkerPlanck, MonteCarlo):  # the solvers' own settings and refusals, stand-in results
        monkeypatch.setattr(cls, "solve", lambda self, h: outcomes[self.name])
    scene = Scene(name="miss", system=Harvester.build(a=0.5, n=1.25), observables=("eta",), rtol=5e-3,
                  outputs=())
    row = scene_run.run_scene(scene, tmp_path / "ok", progress=False, workers=1).rows[0]
    assert row.method == "mc" and row.status == "stable"
    assert "Fokker-Planck did not reach the tolerance" in row.message and "fpe stopped" in row.message
    # the replaced Fokker-Planck numbers stay on the row, for the validation's cross-check
    assert row.info["fallback"]["kept"] == "mc"
    assert row.info["fallback"]["other"]["method"] == "fpe"
    assert row.info["fallback"]["other"]["eta"] == fpe.eta and row.info["fallback"]["other"]["eta_err"] == fpe.eta_err
    # Monte Carlo not converged either: the smaller relative error wins, the message says why
    outcomes["mc"] = replace(fpe, method="mc", eta_err=0.02 * exact.eta, message="mc stopped")
    row = scene_run.run_scene(scene, tmp_path / "worse", progress=False, workers=1).rows[0]
    assert row.method == "fpe" and row.status == "not_converged"
    assert "Monte Carlo did no better (mc stopped)" in row.message
    assert row.info["fallback"]["kept"] == "fpe" and row.info["fallback"]["other"]["method"] == "mc"
    outcomes["mc"] = replace(fpe, method="mc", eta_err=0.007 * exact.eta, message="mc stopped")
    row = scene_run.run_scene(scene, tmp_path / "better", progress=False, workers=1).rows[0]
    assert row.method == "mc" and row.status == "not_converged"
    # numbers without an error estimate lose to any that have one
    outcomes["fpe"] = replace(fpe, eta_err=None)
    row = scene_run.run_scene(scene, tmp_path / "no_error", progress=False, workers=1).rows[0]
    assert row.method == "mc" and "no error estimate" in row.message


def test_auto_goes_to_monte_carlo_where_fokker_planck_declines(tmp_path, monkeypatch):
    # n = 1, a = 2 (the strong kink) is outside Fokker-Planck's measured domain: the scene asks
    # the solvers in order and Monte Carlo answers, with no Fokker-Planck attempt first.
    from fpe_harvester import Harvester, Scene, run_scene
    from fpe_harvester.fpe import FokkerPlanck

    def attempted(self, h):
        raise AssertionError("Fokker-Planck attempted outside its domain")

    monkeypatch.setattr(FokkerPlanck, "solve", attempted)
    scene = Scene(name="declined", system=Harvester.build(a=2.0, n=1), observables=("eta",),
                  rtol=0.05, options={"mc": {"paths": 64, "t_run": 40.0, "min_replicas": 4},
                                      "fpe": {"max_seconds": 5.0}},
                  outputs=())
    row = run_scene(scene, tmp_path, progress=False, workers=1).rows[0]
    assert row.method == "mc" and row.status == "stable"
    assert "chose Monte Carlo" in row.message and "outside the measured domain" in row.message
    assert 0.1 < row.values["eta"] < 0.2 and row.values["eta_err"] > 0
