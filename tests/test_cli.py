"""Command line: tables, JSON, exit codes."""

from __future__ import annotations

import json

import pytest

from fpe_harvester.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_stats_table(capsys):
    code, out, _ = run(capsys, "stats", "--n", "2", "--a", "0.5", "--N", "3", "--k", "-0.33")
    assert code == 0
    assert "0.6773938564" in out and "method = exact" in out and "status = stable" in out


def test_stats_json(capsys):
    code, out, _ = run(capsys, "stats", "--N", "3", "--k", "-0.33", "--json")
    d = json.loads(out)
    assert code == 0
    for key in ("eta", "V2", "Vrms", "Pin", "method", "eta_err", "V2_err", "status"):
        assert key in d
    assert d["eta"] == pytest.approx(0.6773938564, abs=1e-9)


def test_stats_params_and_unstable(capsys):
    code, out, _ = run(capsys, "stats", "--param", "tau_p=2", "--json")
    assert json.loads(out)["eta"] == pytest.approx(20 / 39)
    code, out, _ = run(capsys, "stats", "--N", "3", "--k", "-0.5", "--json")
    d = json.loads(out)
    assert code == 0 and d["status"] == "unstable" and d["eta"] is None and d["growth_rate"] > 0


def test_threshold(capsys):
    code, out, _ = run(capsys, "threshold", "--N", "3", "--a", "0.5", "--json")
    d = json.loads(out)
    assert code == 0 and d["k_di"] == pytest.approx(-1 / 3) and d["critical_mode"] == [1, 2]
    code, out, _ = run(capsys, "threshold", "--N", "4")
    assert code == 0 and "-0.25" in out


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["stats", "--a", "-1"], "a must be in"),
        (["stats", "--a", "x"], "argument --a"),
        (["stats", "--N", "0"], "N must be an integer"),
        (["stats", "--param", "foo=1"], "unknown parameter"),
        (["stats", "--param", "tau=abc"], "--param tau"),
        (["stats", "--param", "tau"], "NAME=VALUE"),
        (["stats", "--method", "magic"], "argument --method"),
        (["stats", "--n", "3", "--method", "exact"], "n = 2"),
        (["threshold", "--N", "0"], "N must be an integer"),
    ],
)
def test_bad_arguments_exit_2_one_line(capsys, argv, match):
    with pytest.raises(SystemExit) as exc:
        code = main(argv)
        raise SystemExit(code)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert match in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
