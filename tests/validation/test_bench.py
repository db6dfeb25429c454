"""The benchmarks' shared command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from validation.bench import bench_main


def test_bench_main_parses_runs_and_drops(tmp_path, capsys):
    calls = []

    def run(quick, out):
        calls.append((quick, out))
        return {"quick": quick, "rows": [1, 2, 3], "total": 6}

    res = bench_main(run, "Toy benchmark.\n\nMore text.", drop=("rows",),
                     argv=["--quick", "--out", str(tmp_path)])
    assert calls == [(True, tmp_path)]
    assert res["rows"] == [1, 2, 3]
    assert json.loads(capsys.readouterr().out) == {"quick": True, "total": 6}
    bench_main(run, "Toy benchmark.", argv=[])
    assert calls[-1] == (False, Path("validation_report"))
    assert "rows" in json.loads(capsys.readouterr().out)
    with pytest.raises(SystemExit):
        bench_main(run, "Toy benchmark.", argv=["--help"])
    assert "Toy benchmark." in capsys.readouterr().out
