"""The examples import without side effects and run."""

from __future__ import annotations

import importlib.util
from pathlib import Path

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_ring_study_runs(tmp_path, capsys):
    module = _load("ring_study")
    assert capsys.readouterr().out == ""  # importing printed nothing and computed nothing
    module.main(tmp_path)
    out = capsys.readouterr().out
    assert "eta = 0.6773938564" in out and "k_di = -0.333333" in out
    assert (tmp_path / "example_eta_vs_k_eta_vs_k.png").exists()
