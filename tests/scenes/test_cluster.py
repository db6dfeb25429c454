"""Scenes on a Dask cluster: same numbers as in one process, resumable cache, lost workers."""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

import pytest

from fpe_harvester.cli import main
from fpe_harvester.errors import ParameterError
from fpe_harvester.model import Harvester
from fpe_harvester.parallel import default_threads
from fpe_harvester.scenes import Axis, Scene, run_scene
from fpe_harvester.scenes import run as scene_run
from fpe_harvester.scenes.cache import CACHE_NAME

distributed = pytest.importorskip("distributed")

#: Small Monte Carlo settings: each point takes a fraction of a second once compiled.
MC = {"paths": 32, "t_run": 20.0, "min_replicas": 4}


def mc_scene(ks: tuple[float, ...] = (0.1, 0.0, -0.1, -0.2)) -> Scene:
    return Scene("dask_mc", system=Harvester.build(a=0.5, n=3, N=2), observables=("eta", "V2"),
                 method="mc", rtol=0.1, axes=(Axis("k", ks),), options={"mc": MC}, outputs=())


def loopback_cluster():
    """Two single-threaded worker processes on 127.0.0.1, no dashboard."""
    return distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                    dashboard_address=None, scheduler_kwargs={"dashboard": False})


@pytest.fixture(scope="module")
def client():
    with loopback_cluster() as cluster, distributed.Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory):
    """The scene run in this process: the numbers every cluster run must reproduce."""
    return run_scene(mc_scene(), tmp_path_factory.mktemp("in_process"), progress=False)


def cache_lines(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / CACHE_NAME).read_text().splitlines()]


def test_cluster_gives_the_numbers_of_one_process_and_resumes(tmp_path: Path, client, reference,
                                                              capsys) -> None:
    res = run_scene(mc_scene(), tmp_path, progress=True, scheduler=client)
    assert res.computed == 4 and res.reused == 0
    assert "dask_mc:" in capsys.readouterr().err  # the progress bar is drawn
    assert [(r.status, r.values, r.info["seed"]) for r in res.rows] == \
        [(r.status, r.values, r.info["seed"]) for r in reference.rows]
    assert all(r.status == "stable" for r in res.rows)
    lines = cache_lines(tmp_path)  # written by this process as points finished
    assert len(lines) == 4
    # one worker thread per task; the replica batch of this machine, as in the reference
    assert {(rec["stats"]["info"]["threads"], rec["stats"]["info"]["batch"]) for rec in lines} == \
        {(1, default_threads())}
    again = run_scene(mc_scene(), tmp_path, progress=False, scheduler=client)
    assert again.computed == 0 and again.reused == 4
    assert [r.values for r in again.rows] == [r.values for r in reference.rows]


def kill_a_busy_worker_after_the_first_point(client, monkeypatch) -> list[int]:
    """Once the first point reaches the cache, SIGKILL a worker that is computing another one;
    returns the killed process id (filled during the run)."""
    killed: list[int] = []
    put = scene_run.PointCache.put

    def put_then_kill(self, *args, **kwargs):
        put(self, *args, **kwargs)
        if not killed:
            busy = [addr for addr, tasks in client.processing().items() if tasks]
            assert busy, "no point in flight: the test needs slower points"
            killed.extend(client.run(os.getpid, workers=busy[:1]).values())
            os.kill(killed[0], signal.SIGKILL)

    monkeypatch.setattr(scene_run.PointCache, "put", put_then_kill)
    return killed


def test_a_worker_killed_mid_run_loses_nothing(tmp_path: Path, client, reference, monkeypatch) -> None:
    killed = kill_a_busy_worker_after_the_first_point(client, monkeypatch)
    res = run_scene(mc_scene(), tmp_path, progress=False, scheduler=client)
    assert len(killed) == 1 and killed[0] not in client.run(os.getpid).values()
    assert res.computed == 4
    assert [(r.status, r.values) for r in res.rows] == [(r.status, r.values) for r in reference.rows]
    lines = cache_lines(tmp_path)
    assert len(lines) == 4 and len({rec["key"] for rec in lines}) == 4  # every point once


def test_an_interrupted_run_cancels_its_tasks_and_resumes(tmp_path: Path, client, reference,
                                                          monkeypatch) -> None:
    put = scene_run.PointCache.put

    def put_then_stop(self, *args, **kwargs):
        put(self, *args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(scene_run.PointCache, "put", put_then_stop)
    with pytest.raises(KeyboardInterrupt):
        run_scene(mc_scene(), tmp_path, progress=False, scheduler=client)
    monkeypatch.undo()
    assert len(cache_lines(tmp_path)) == 1
    assert not any(client.processing().values())  # nothing left running for the stopped run
    res = run_scene(mc_scene(), tmp_path, progress=False, scheduler=client)
    assert (res.computed, res.reused) == (3, 1)
    assert [r.values for r in res.rows] == [r.values for r in reference.rows]


def test_fokker_planck_points_match_too(tmp_path: Path, client) -> None:
    sc = Scene("dask_fpe", system=Harvester.build(a=0.5, n=3, N=1), observables=("eta", "V2", "x2"),
               method="fpe", rtol=1e-3, axes=(Axis("a", (0.5, 1.0)),), outputs=())
    here = run_scene(sc, tmp_path / "here", progress=False)
    there = run_scene(sc, tmp_path / "there", progress=False, scheduler=client)
    assert [(r.status, r.values) for r in there.rows] == [(r.status, r.values) for r in here.rows]
    assert all(r.status == "stable" and r.method == "fpe" for r in there.rows)


@pytest.mark.slow
def test_a_point_that_keeps_killing_workers_fails_alone(tmp_path: Path, reference, monkeypatch) -> None:
    # no second chance: the point whose worker is killed is reported failed, the rest finish,
    # and the next run computes it
    dask = pytest.importorskip("dask")
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), loopback_cluster() as cluster, \
            distributed.Client(cluster) as c:
        kill_a_busy_worker_after_the_first_point(c, monkeypatch)
        res = run_scene(mc_scene(), tmp_path, progress=False, scheduler=c)
        # the worker held the point it was computing and maybe one queued behind it
        failed = [r for r in res.rows if r.status == "error"]
        assert 1 <= len(failed) <= 2 and res.computed == 4 - len(failed)
        assert all("kept dying" in r.message and r.method == "mc" for r in failed)
        monkeypatch.undo()
        again = run_scene(mc_scene(), tmp_path, progress=False, scheduler=c)
    assert again.computed == len(failed) and again.reused == 4 - len(failed)
    assert [r.values for r in again.rows] == [r.values for r in reference.rows]


@pytest.mark.filterwarnings("ignore:Port 8787 is already in use")  # its dashboard moves elsewhere
def test_local_cluster_started_for_the_run(tmp_path: Path, reference) -> None:
    res = run_scene(mc_scene((0.1,)), tmp_path, progress=False, scheduler="local", workers=1)
    assert res.computed == 1 and res.rows[0].values == reference.rows[0].values


def test_identical_points_stay_separate_tasks(tmp_path: Path, client, reference) -> None:
    res = run_scene(mc_scene((0.1, 0.1)), tmp_path, progress=False, scheduler=client)
    assert res.computed == 2 and res.rows[0].values == res.rows[1].values == reference.rows[0].values


def test_cli_scheduler_address_flag_and_environment(tmp_path: Path, client, reference, monkeypatch,
                                                     capsys) -> None:
    # the scene of ``reference`` (seeds depend on the scene's name), first two points
    scene = tmp_path / "dask_mc.toml"
    scene.write_text('name = "dask_mc"\nobservables = ["eta", "V2"]\nmethod = "mc"\nrtol = 0.1\n'
                     "[system]\na = 0.5\nn = 3\nN = 2\n[axes]\nk = [0.1, 0.0]\n"
                     f"[options.mc]\npaths = {MC['paths']}\nt_run = {MC['t_run']}\n"
                     f"min_replicas = {MC['min_replicas']}\n")
    seen: list[object] = []
    real = scene_run.run_scene

    def spy(*args, **kwargs):
        seen.append(kwargs.get("scheduler"))
        return real(*args, **kwargs)

    monkeypatch.setattr("fpe_harvester.scenes.run_scene", spy)
    address = client.scheduler.address
    assert main(["scene", "run", str(scene), "--out", str(tmp_path / "a"), "--json",
                 "--scheduler", address]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["computed"] == 2
    assert [row["eta"] for row in out["rows"]] == [r.values["eta"] for r in reference.rows[:2]]
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", address)
    assert main(["scene", "run", str(scene), "--out", str(tmp_path / "a"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["reused"] == 2
    # an explicit --workers means local processes: the environment variable is not used
    assert main(["scene", "run", str(scene), "--out", str(tmp_path / "a"), "--json", "--workers", "1"]) == 0
    capsys.readouterr()
    assert seen == [address, address, None]
    assert main(["scene", "run", str(scene), "--out", str(tmp_path / "a"), "--scheduler", address,
                 "--workers", "2"]) == 2
    assert "only applies to local processes" in capsys.readouterr().err


def test_errors_name_the_extra_and_the_address(tmp_path: Path, monkeypatch) -> None:
    with pytest.raises(ParameterError, match="scheduler must be 'local', a scheduler address"):
        run_scene(mc_scene(), tmp_path, scheduler=8786)
    with pytest.importorskip("dask").config.set({"distributed.comm.timeouts.connect": "0.5s"}):
        with pytest.raises(ParameterError, match=r"cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"):
            run_scene(mc_scene(), tmp_path, scheduler="tcp://127.0.0.1:9")
        # harmonic points never leave this process: no scheduler is contacted
        harmonic = Scene("dask_exact", system=Harvester.build(a=0.5, n=2, N=3), observables=("eta",),
                         axes=(Axis("k", (0.0, -0.2)),), outputs=())
        assert run_scene(harmonic, tmp_path, scheduler="tcp://127.0.0.1:9").computed == 2
    with pytest.raises(ParameterError, match=r"workers=2 only applies to local processes or "
                                              r"scheduler='local': the cluster at 'tcp://127.0.0.1:9' has"):
        run_scene(mc_scene(), tmp_path, scheduler="tcp://127.0.0.1:9", workers=2)
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ParameterError, match=r'needs Dask, which is not installed: '
                                              r'pip install "fpe-harvester\[dask\]"'):
        run_scene(mc_scene(), tmp_path, scheduler="local")
