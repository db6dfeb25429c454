"""``harvester scene list`` and ``harvester scene run`` on a tiny harmonic scene."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from fpe_harvester.cli import main
from fpe_harvester.scenes import list_scenes
from fpe_harvester.solve import solve as real_solve

TINY = """
name = "tiny_cli"
observables = ["eta", "Vrms"]

[system]
a = 0.5
n = 2
N = 3

[axes]
k = [0.0, -0.33, -0.4]

[[figures]]
name = "eta_vs_k"
x = "k"
y = "eta"
refs = [{ vline = "k_di" }]

[quick]
axes = { k = [-0.33] }
"""


def test_scene_list(capsys) -> None:
    assert main(["scene", "list"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in list_scenes())
    assert main(["scene", "list", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {d["name"] for d in data} == set(list_scenes())


def test_scene_run_table_and_json(tmp_path: Path, capsys) -> None:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    out_dir = tmp_path / "out"
    assert main(["scene", "run", str(path), "--out", str(out_dir), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "0.677394" in out and "unstable" in out and "k_di" in out
    assert f"eta_vs_k: {out_dir / 'tiny_cli_eta_vs_k.png'}" in out
    assert (out_dir / "tiny_cli_eta_vs_k.png").exists() and (out_dir / "tiny_cli.csv").exists()
    assert main(["scene", "run", str(path), "--out", str(out_dir), "--quick", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["rows"]) == 1 and data["reused"] == 1 and data["computed"] == 0
    assert data["rows"][0]["eta"] == pytest.approx(0.6773938564, rel=1e-9)


def test_scene_run_errors(tmp_path: Path, capsys) -> None:
    assert main(["scene", "run", "fig99", "--out", str(tmp_path)]) == 2
    assert "neither a file nor a shipped scene" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'b'\nobservables = ['power']\n")
    assert main(["scene", "run", str(bad), "--out", str(tmp_path)]) == 2
    assert "observables must be one of" in capsys.readouterr().err


def _scene(tmp_path: Path, text: str) -> str:
    path = tmp_path / "s.toml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(("text", "match"), [
    (TINY + "\n[options.mc]\nfoo = 1\n", "options.mc: invalid option for method 'mc': no option 'foo'"),
    (TINY.replace('observables = ["eta", "Vrms"]', 'observables = ["eta"]\nmethod = "fpe"'),
     r"method: 'fpe' cannot handle the point \(a = 0.5, n = 2, N = 3, k = 0\) of scene 'tiny_cli': the "
     "Fokker-Planck solver handles a single oscillator"),
    ("", "system: missing required table"),
    ("name = 'e'\n[system]\n", "system: the table is empty"),
])
def test_scenes_are_checked_before_the_first_point(tmp_path: Path, capsys, text: str, match: str) -> None:
    out = tmp_path / "out"
    assert main(["scene", "run", _scene(tmp_path, text), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert re.search(match, err) and len(err.strip().splitlines()) == 1, err
    assert not (out / "points.jsonl").exists()  # nothing ran


def test_failed_points_make_a_non_zero_exit_that_says_how_many(tmp_path: Path, capsys, monkeypatch) -> None:
    from fpe_harvester.errors import NotConvergedError
    from fpe_harvester.scenes import run as scene_run

    def flaky(h, method, **opts):
        if h.k == -0.2:
            raise NotConvergedError("did not reach tol")
        return real_solve(h.replace(n=2.0), "exact")

    text = TINY.replace("n = 2", "n = 3").replace("k = [0.0, -0.33, -0.4]", "k = [0.0, -0.2, -0.3]")
    monkeypatch.setattr(scene_run, "solve", flaky)
    code = main(["scene", "run", _scene(tmp_path, text), "--out", str(tmp_path / "o"), "--no-progress"])
    captured = capsys.readouterr()
    assert code == 1 and "1 of 3 points failed or had no solver available" in captured.err
    assert "error" in captured.out  # the table shows the failed row


def test_ctrl_c_says_how_many_points_are_saved_and_how_to_resume(tmp_path: Path, capsys, monkeypatch) -> None:
    from fpe_harvester.scenes import run as scene_run

    solved: list[float] = []

    def interrupted(h, method, **opts):
        if len(solved) == 2:
            raise KeyboardInterrupt
        solved.append(h.k)
        return real_solve(h.replace(n=2.0), "exact")

    text = TINY.replace("n = 2", "n = 3").replace("k = [0.0, -0.33, -0.4]", "k = [0.0, -0.1, -0.2, -0.3]")
    monkeypatch.setattr(scene_run, "solve", interrupted)
    args = ["scene", "run", _scene(tmp_path, text), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(args) == 130
    err = capsys.readouterr().err
    assert "interrupted; 2 finished points are saved in" in err and "run the same command again to resume" in err
    monkeypatch.setattr(scene_run, "solve", lambda h, method, **o: real_solve(h.replace(n=2.0), "exact"))
    assert main(args) == 0 and "2 computed, 2 reused" in capsys.readouterr().out


def test_scene_results_go_into_pandas(tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas")
    from fpe_harvester.scenes import load_scene, run_scene

    res = run_scene(load_scene(_scene(tmp_path, TINY)), tmp_path / "o", progress=False)
    frame = res.to_frame()
    assert isinstance(frame, pd.DataFrame) and list(frame["k"]) == [0.0, -0.33, -0.4]
    assert list(frame.columns[:3]) == ["index", "k", "eta"] and frame["status"].tolist()[-1] == "unstable"
    assert frame["eta"].isna().tolist() == [False, False, True]
