"""The benchmarks' shared command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from validation.studies import bench_main


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


def test_the_report_includes_an_exhaustive_benchmark_run(tmp_path):
    """harvester validate --bench DIR: the JSON's error/time pairs, targets and figures of
    python -m validation.studies.X --out DIR enter the benchmark section, labelled as not this run."""
    import json
    import types

    from validation.sections import benchmarks as combined
    from validation.harness.checks import Context, SolveCache
    from validation.harness.report import Section, Table

    (tmp_path / "bench_toy.json").write_text(json.dumps({"case": {"time_s": 2.0, "eta_rel_error": 1e-4,
                                                                  "time_target_s": 1.0}}))
    (tmp_path / "bench_toy.png").write_bytes(b"\x89PNG")
    mod = types.SimpleNamespace(STEM="bench_toy", __name__="validation.studies.toy")
    ctx = Context(quick=False, out=tmp_path, cache=SolveCache(), bench=tmp_path)
    sec, targets = Section("b", "B"), Table("t", ("benchmark", "measurement", "time [s]", "target [s]", "met"))
    combined._include(ctx, mod, sec, targets)
    assert len(sec.tables) == 1 and sec.tables[0].rows[0][2] == "0.0001"
    assert "not this run" in sec.tables[0].title and "not this run" in sec.figures[0].caption
    assert targets.rows and targets.rows[0][-1] == "NO"


def test_validate_refuses_a_missing_bench_folder(tmp_path, capsys):
    from fpe_harvester.cli import main

    assert main(["validate", "--quick", "--bench", str(tmp_path / "nowhere"), "--out", str(tmp_path)]) == 2
    assert "--bench" in capsys.readouterr().err


def test_xmesh_series_converges_on_both_meshes_and_plots(tmp_path):
    """The x-mesh benchmark's fixed-M series (M = 4, small meshes): the error against the
    reference falls with the elements on both meshes, and the figure is written."""
    from validation.studies.fpe import xmesh

    series = xmesh.mesh_series(4, (4, 8, 16))
    for mesh in xmesh.MESHES:
        errors = [p["error"] for p in series[mesh]]
        assert errors[-1] < errors[0], (mesh, errors)
    xmesh._plot({"mesh_series": [series]}, tmp_path / "x.png")
    assert (tmp_path / "x.png").stat().st_size > 0


def test_montecarlo_bench_runs_a_subset_of_its_studies(tmp_path):
    """Studies not asked for are listed as not run, and the plot is drawn without them."""
    import pytest

    from validation.studies.mc import bench

    res = bench.run(quick=True, out=tmp_path, studies=("rng",))
    assert "note" in res["equal_error"] and "note" in res["kink_dt"]
    assert (tmp_path / f"{bench.STEM}.png").exists()
    with pytest.raises(ValueError, match="studies must be among"):
        bench.run(quick=True, studies=("no such study",))


def test_each_monte_carlo_study_is_a_module_the_benchmark_runs():
    """Every study of the Monte Carlo benchmark comes from a study module with its own
    ``run``, ``STEM`` and ``draw`` (so ``python -m validation.studies.mc.<name>`` writes it alone)."""
    import importlib

    from validation.studies.mc import bench

    modules = {importlib.import_module(fn.__module__) for fn in bench.STUDIES.values()
               if fn.__module__ != bench.__name__}
    assert len(modules) == 11
    for mod in modules:
        assert mod.__name__.startswith("validation.studies.mc.")
        assert callable(mod.run) and callable(mod.draw) and mod.STEM.startswith("bench_montecarlo_")


def test_recorded_policy_and_martingale_runs_draw(tmp_path):
    """The recorded full runs in validation/data have the shape their study's figure reads."""
    import json

    from validation.studies.cli import DATA, axes_plot
    from validation.studies.mc import martingale, policy

    recorded = json.loads((DATA / "bench_montecarlo_policy.json").read_text())
    axes_plot(policy.draw)(recorded, tmp_path / "policy.png")
    rows = json.loads((DATA / "bench_montecarlo_martingale_rows.json").read_text())
    axes_plot(martingale.draw)(rows, tmp_path / "martingale.png")
    assert (tmp_path / "policy.png").stat().st_size > 0 and (tmp_path / "martingale.png").stat().st_size > 0
