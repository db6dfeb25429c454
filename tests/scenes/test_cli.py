"""``harvester scene list`` and ``harvester scene run`` on a tiny harmonic scene."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fpe_harvester.cli import main
from fpe_harvester.scenes import list_scenes

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
