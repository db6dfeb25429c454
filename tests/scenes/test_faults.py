"""Faults in long scene runs: kills at random moments, garbled cache lines, two runs on one
folder, and rows that miss the accuracy asked for."""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fpe_harvester.model import Harvester
from fpe_harvester.optimum import Optimum
from fpe_harvester.result import Status
from fpe_harvester.scenes import Axis, FigureSpec, Optimize, Scene
from fpe_harvester.scenes import run as scene_run
from fpe_harvester.scenes.cache import CACHE_NAME, PointCache, _encode
from fpe_harvester.solve import solve

ROOT = Path(__file__).resolve().parents[2]

#: Twelve single-unit quartic points solved by Fokker--Planck one by one (~0.4 s each).
KILL_SCENE = """
name = "kill"
observables = ["eta", "V2"]
method = "fpe"
rtol = 0.05
outputs = ["csv", "json"]

[system]
n = 4
N = 1

[axes]
a = [{a}]
"""


def cli(toml: Path, out: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "fpe_harvester", "scene", "run", str(toml),
                             "--out", str(out), "--no-progress"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def kill_scene(tmp_path: Path, n_points: int) -> Path:
    toml = tmp_path / "kill.toml"
    toml.write_text(KILL_SCENE.format(a=", ".join(f"{a:.2f}" for a in np.linspace(0.3, 1.4, n_points))))
    return toml


def run_killed(toml: Path, out: Path, delays: np.ndarray) -> list[int]:
    """Start the scene and SIGKILL it, each time ``delay`` seconds after it finished a new
    point (the start-up takes seconds, a point ~0.4 s: kills land inside a point, between
    points or while one is written). Returns the points cached after each kill."""
    progress = [0]
    for delay in delays:
        proc = cli(toml, out)
        deadline = time.monotonic() + 120
        while proc.poll() is None and _lines(out) <= progress[-1] and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(delay)
        proc.kill()  # SIGKILL: no handler, no flush, no cleanup
        proc.wait()
        assert proc.returncode in (-signal.SIGKILL, 0), proc.stderr.read().decode()
        cache = PointCache(out)
        progress.append(len(cache))
        assert cache.skipped_lines == 0 or cache.problems  # what was skipped is explained
    return progress[1:]


def _lines(out: Path) -> int:
    path = out / CACHE_NAME
    return path.read_bytes().count(b"\n") if path.exists() else 0


def check_resumed(toml: Path, tmp_path: Path, delays: np.ndarray, n_points: int) -> list[int]:
    """Kill a run after each delay, finish it, and compare with an uninterrupted run."""
    reference, out = tmp_path / "reference", tmp_path / "killed"
    proc = cli(toml, reference)
    assert proc.wait() == 0, proc.stderr.read().decode()
    progress = run_killed(toml, out, delays)
    proc = cli(toml, out)
    assert proc.wait() == 0, proc.stderr.read().decode()
    final, ref = csv_rows(out / "kill.csv"), csv_rows(reference / "kill.csv")
    assert len(final) == n_points and len({r["a"] for r in final}) == n_points
    assert final == ref  # every value, error, status and message bit for bit (as CSV text)
    data = json.loads((out / "kill.json").read_text())
    assert [r["eta"] for r in data["rows"]] == [float(r["eta"]) for r in ref]
    cache = PointCache(out)
    assert len(cache) == n_points and cache.skipped_lines <= len(delays)  # at most one cut line per kill
    return progress


def test_sigkill_at_random_moments_resumes_to_the_same_numbers(tmp_path: Path) -> None:
    n_points = 10
    rng = np.random.default_rng(15)
    progress = check_resumed(kill_scene(tmp_path, n_points), tmp_path, rng.uniform(0.0, 0.5, 2), n_points)
    # the first kill lands mid-run (later ones may find the sweep done on a fast machine)
    assert 0 < progress[0] < n_points and progress == sorted(progress)


@pytest.mark.slow
def test_sigkill_many_times_in_a_long_sweep(tmp_path: Path) -> None:
    n_points = 16
    rng = np.random.default_rng(1515)
    progress = check_resumed(kill_scene(tmp_path, n_points), tmp_path, rng.uniform(0.0, 0.5, 8), n_points)
    assert progress == sorted(progress) and 0 < progress[0]


def stand_in(h: Harvester, method: str, **opts: object):
    """Deterministic stand-in for a slow pointwise solver: the exact harmonic counterpart."""
    return solve(h.replace(n=2.0), "exact")


class Recorder:
    def __init__(self, delay: float = 0.0) -> None:
        self.ks: list[float] = []
        self.delay = delay

    def __call__(self, h: Harvester, method: str, **opts: object):
        self.ks.append(h.k)
        time.sleep(self.delay)
        return stand_in(h, method, **opts)


def nonlinear_scene(n_k: int = 6, **kw: object) -> Scene:
    return Scene("nl", system=Harvester.build(a=0.5, n=3, N=3), observables=("eta", "x2"),
                 axes=(Axis("k", tuple(np.linspace(0.2, -0.3, n_k))),), **kw)  # type: ignore[arg-type]


def test_garbled_lines_are_skipped_counted_and_their_points_recomputed(tmp_path: Path, monkeypatch) -> None:
    sc = nonlinear_scene()
    monkeypatch.setattr(scene_run, "solve", Recorder())
    first = scene_run.run_scene(sc, tmp_path, progress=False)
    path = tmp_path / CACHE_NAME
    lines = path.read_bytes().splitlines(keepends=True)
    assert len(lines) == 6 and first.cache_skipped == 0
    k = [json.loads(line)["harvester"]["k"] for line in lines]
    # line 1: a digit of eta changed (still valid JSON, same key: only the checksum sees it)
    rec = json.loads(lines[1])
    eta = repr(rec["stats"]["eta"])
    digit = next(i for i in range(len(eta) - 1, 0, -1) if eta[i].isdigit() and eta[i] != "9")
    wrong = eta[:digit] + str(int(eta[digit]) + 1) + eta[digit + 1:]
    lines[1] = lines[1].replace(f'"eta":{eta}'.encode(), f'"eta":{wrong}'.encode(), 1)
    assert wrong.encode() in lines[1]
    # line 2: a NaN with a valid checksum (a writer bug, not a transmission error)
    rec = json.loads(lines[2])
    del rec["sum"]
    rec["stats"]["eta"] = float("nan")
    lines[2] = _encode(rec)
    # line 3: no key; then junk inserted; line 5 (the last) cut mid-write
    rec = json.loads(lines[3])
    del rec["sum"], rec["key"]
    lines[3] = _encode(rec)
    lines.insert(4, b"\x00\xff junk {\n")
    lines[-1] = lines[-1][: len(lines[-1]) // 2]
    path.write_bytes(b"".join(lines))

    recorder = Recorder()
    monkeypatch.setattr(scene_run, "solve", recorder)
    second = scene_run.run_scene(sc, tmp_path, progress=False)
    assert sorted(recorder.ks) == sorted([k[1], k[2], k[3], k[5]])  # exactly the damaged points
    assert second.cache_skipped == 5 and second.computed == 4 and second.reused == 2
    assert [r.values for r in second.rows] == [r.values for r in first.rows]
    problems = " | ".join(PointCache(tmp_path).problems)
    for reason in ("checksum mismatch", "invalid stats", "no key", "not a JSON line"):
        assert reason in problems
    # the cut last line was ended before the next append: every point is read back
    third_recorder = Recorder()
    monkeypatch.setattr(scene_run, "solve", third_recorder)
    third = scene_run.run_scene(sc, tmp_path, progress=False)
    assert third_recorder.ks == [] and third.reused == 6 and third.cache_skipped == 5


def test_lines_of_earlier_versions_are_read_when_valid(tmp_path: Path) -> None:
    h = Harvester.build(n=2)
    stats = solve(h).to_dict()
    legacy = {"key": "a" * 24, "harvester": h.to_dict(), "scene": "s", "seed": None, "stats": stats}
    typo = {**legacy, "key": "b" * 24, "sun": "0123456789abcdef"}  # a garbled checksum field name
    (tmp_path / CACHE_NAME).write_text(json.dumps(legacy) + "\n" + json.dumps(typo) + "\n")
    cache = PointCache(tmp_path)
    assert cache.get("a" * 24).eta == stats["eta"] and cache.get("b" * 24) is None
    assert cache.skipped_lines == 1 and "unknown fields ['sun']" in cache.problems[0]


def _concurrent_run(sc: Scene, out: Path, barrier) -> None:
    scene_run.solve = Recorder(delay=0.01)  # forked: this process only
    barrier.wait()
    scene_run.run_scene(sc, out, progress=False)


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="needs fork")
def test_two_runs_on_one_folder(tmp_path: Path) -> None:
    sc = nonlinear_scene(20, outputs=("csv", "json", "table"),
                         figures=(FigureSpec("eta_vs_k", x="k", y=("eta",)),))
    ctx = multiprocessing.get_context("fork")
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_concurrent_run, args=(sc, tmp_path, barrier)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    cache = PointCache(tmp_path)
    lines = (tmp_path / CACHE_NAME).read_text().splitlines()
    assert cache.skipped_lines == 0 and len(cache) == 20 and len(lines) >= 20  # duplicates allowed
    rows = csv_rows(tmp_path / "nl.csv")
    assert len(rows) == 20 and len({r["k"] for r in rows}) == 20
    data = json.loads((tmp_path / "nl.json").read_text())
    assert len(data["rows"]) == 20 and (tmp_path / "nl_eta_vs_k.png").stat().st_size > 0
    assert not list(tmp_path.glob(".*"))  # no temporary file left behind
    for row in rows:
        ref = stand_in(sc.harvester({"k": float(row["k"])}), "mc")
        assert float(row["eta"]) == ref.eta and row["status"] == "stable"


def test_rows_missing_the_accuracy_are_not_converged(tmp_path: Path, monkeypatch) -> None:
    """Whatever status the solver gives, a row that misses rtol on eta says not_converged:
    fresh, from the cache, from the exact batch and at an optimum."""

    def sloppy(h: Harvester, method: str, **opts: object):
        good = stand_in(h, method)
        if h.k < 0:  # a solver that claims stable with a 10 % error
            return replace(good, eta_err=0.1 * good.eta)
        return good

    monkeypatch.setattr(scene_run, "solve", sloppy)
    sc = nonlinear_scene(4, rtol=0.01)
    for run in range(2):  # computed, then served from the cache
        res = scene_run.run_scene(sc, tmp_path, progress=False)
        assert res.reused == 4 * run
        for row in res.rows:
            if row.point["k"] < 0:
                assert row.status == "not_converged" and "accuracy not met" in row.message
                assert row.values["eta"] is not None  # the best estimate stays
            else:
                assert row.status == "stable" and "accuracy" not in row.message

    from fpe_harvester.exact import Exact

    exact_many = Exact.solve_many

    def loose_exact(self, hs):
        return [replace(s, eta_err=1e-2 * s.eta) for s in exact_many(self, hs)]

    harmonic = Scene("h", system=Harvester.build(a=0.5, n=2, N=3), observables=("eta",), rtol=1e-3,
                     axes=(Axis("k", (0.2, -0.2)),))
    monkeypatch.setattr(Exact, "solve_many", loose_exact)
    res = scene_run.run_scene(harmonic, tmp_path / "exact", progress=False)
    assert [r.status for r in res.rows] == ["not_converged"] * 2
    def stand_in_optimum(h: Harvester, over: str, interval: tuple, maximize: str, **kw: object) -> Optimum:
        # the Monte Carlo optimizer has its own tests (tests/test_optimize.py); here only the row
        return Optimum(over, maximize, x_opt=-0.2, x_opt_err=0.01, value=0.5, value_err=1e-4,
                       status=Status.STABLE, method="mc")

    monkeypatch.setattr(scene_run, "optimize", stand_in_optimum)
    opt = Scene("o", system=Harvester.build(a=0.5, n=3, N=3), observables=("eta",), rtol=0.01,
                optimize=Optimize("eta", "k", (-0.3, -0.1), points=3))
    row = scene_run.run_scene(opt, tmp_path / "opt", progress=False).rows[0]
    assert row.status == "not_converged" and "accuracy not met" in row.message


def test_cli_says_how_many_cache_lines_it_skipped(tmp_path: Path, capsys) -> None:
    from fpe_harvester.cli import main

    toml = tmp_path / "h.toml"
    toml.write_text('name = "h"\nobservables = ["eta"]\noutputs = []\n[system]\nn = 2\nN = 3\n'
                    "[axes]\nk = [0.0, -0.1]\n")
    args = ["scene", "run", str(toml), "--out", str(tmp_path), "--no-progress"]
    assert main(args) == 0 and "skipped" not in capsys.readouterr().out
    path = tmp_path / CACHE_NAME
    path.write_bytes(path.read_bytes()[:-20])  # the last line cut
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "1 computed, 1 reused" in out and "points.jsonl: 1 unreadable lines skipped" in out
