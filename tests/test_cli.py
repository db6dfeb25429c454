"""Command line: tables, JSON, exit codes."""

from __future__ import annotations

import json
import re

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


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["stats", "--a", "1e308"], r"a = 1e\+308 is out of range .* a <= 4.\de\+153 keeps"),
        (["stats", "--a", "1e300"], r"a = 1e\+300 is out of range"),
        (["stats", "--param", "m=1e300"], r"m = 1e\+300 is out of range .* m <= "),
        (["stats", "--param", "tau=1e300"], r"tau = 1e\+300 is out of range"),
        (["stats", "--param", "D=1e-320"], r"D = 9.99989e-321 is out of range .* D >= "),
        (["stats", "--tol", "0"], r"tol must be in \(0, 1\), got 0"),
        (["stats", "--tol", "2"], r"tol must be in \(0, 1\), got 2"),
        (["stats", "--seed", "-1"], "seed must be an integer"),
        (["stats", "--max-time", "0"], r"max_time must be in \(0, inf\)"),
        (["stats", "--n", "3", "--method", "fpe", "--tol", "0.5"], r"tol must be in \(0, 0.1\]"),
        (["stats", "--n", "3", "--method", "mc", "--tol", "0"], r"tol must be in \(0, 1\)"),
        (["stats", "--n", "1e6"], r"n must be in \[1, 64\], got 1000000.0"),
        (["stats", "--n", "0.5"], r"n must be in \[1, 64\]"),
        (["stats", "--opt", "foo=1"], "invalid option for method 'exact': no option 'foo'"),
        (["stats", "--n", "3", "--opt", "foo=1"], "invalid option for method 'fpe': no option 'foo'; valid options: tol"),
        (["stats", "--N", "3", "--k", "-inf"], "k must be finite"),
        (["stats", "--N", "5000000", "--method", "exact"], r"N must be in \[1, 4194304\]"),
        # found by the long fuzz: the twin's <v^2> ~ sigma^2 beyond the double range
        (["stats", "--param", "sigma=1e157", "--method", "mc", "--opt", "max_time=0.2"],
         r"stationary covariance .* overflows .* sigma = 1e\+157.* outside double precision"),
        (["stats", "--param", "sigma=1e155", "--method", "mc", "--opt", "max_time=0.2"],
         r"stationary covariance .* sigma = 1e\+155.* outside double precision"),
        (["validate", "--out", "/dev/null/x"], "--out '/dev/null/x': cannot create the output folder"),
        (["scene", "run", "fig4_eta_vs_k_harmonic", "--out", "/dev/null/x"], "--out '/dev/null/x': cannot create"),
    ],
)
def test_extreme_and_misplaced_arguments_are_one_line_errors(capsys, argv, match):
    """Inputs out of range or malformed: each a one-line error naming the argument, exit code 2, no traceback."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert __import__("re").search(match, err), err


@pytest.mark.parametrize(("argv", "eta"), [
    (["stats", "--N", "3", "--k", "1e14"], 20 / 39),  # was "marginal" with eta = 0.7407
    (["stats", "--N", "2", "--k", "1e50"], 20 / 39),
    (["stats", "--N", "3", "--k", "-1e-3"], None),  # a negative number in e-notation is a value
    (["stats", "--param", "tau=1e100"], 12 / 13),  # were tracebacks
    (["stats", "--param", "D=1e-300"], 20 / 39),
])
def test_extreme_but_valid_inputs_give_numbers(capsys, argv, eta):
    code = main([*argv, "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    d = json.loads(out.out)
    assert d["status"] == "stable" and d["eta"] is not None and d["eta_err"] < d["eta"]
    if eta is not None:
        assert d["eta"] == pytest.approx(eta, rel=1e-12)


def test_unexpected_failures_are_one_line_internal_errors(capsys, monkeypatch):
    from fpe_harvester import cli

    def boom(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setitem(cli.COMMANDS, "stats", boom)
    assert main(["stats"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: ZeroDivisionError: float division by zero" in err
    monkeypatch.setenv("HARVESTER_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        main(["stats"])
    monkeypatch.delenv("HARVESTER_DEBUG")

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setitem(cli.COMMANDS, "stats", interrupted)
    assert main(["stats"]) == 130
    assert capsys.readouterr().err == "harvester stats: interrupted\n"


def test_common_settings_are_accepted_for_every_method_and_the_ignored_ones_named(capsys):
    code, out, err = run(capsys, "stats", "--tol", "1e-3", "--seed", "1", "--max-time", "5")
    assert code == 0 and "method = exact" in out and err == ""
    assert "note: the exact solver has no use for --max-time, --seed, --tol: ignored" in out
    code, out, _ = run(capsys, "stats", "--tol", "1e-3", "--json")
    assert code == 0 and json.loads(out)["info"]["ignored"] == ["tol"]


def test_a_parameter_typed_as_an_option_gets_a_hint(capsys):
    def refused(*argv: str) -> str:
        with pytest.raises(SystemExit) as exc:
            main(list(argv))
        assert exc.value.code == 2
        return capsys.readouterr().err

    err = refused("stats", "--tau", "-1")
    assert "unrecognized arguments: --tau -1" in err
    assert "--param tau=-1" in err and len(err.strip().splitlines()) == 1
    assert "--param tau_p=3" in refused("stats", "--tau_p=3")
    assert "--param" not in refused("stats", "--colour", "red")


@pytest.mark.parametrize(("argv", "code"), [(["--N", "3", "--k", "-0.2"], 0), (["--N", "3", "--k", "-0.4"], 3),
                                            (["--N", "4", "--k", "-0.25"], 3)])
def test_strict_exits_3_unless_stable(capsys, argv, code):
    plain, out, _ = run(capsys, "stats", *argv)
    assert plain == 0  # without --strict the status is only printed
    assert run(capsys, "stats", *argv, "--strict")[0] == code
    assert run(capsys, "stats", *argv, "--strict", "--json")[0] == code


def test_stability_messages_give_k_and_k_di_to_the_same_precision(capsys):
    code, out, _ = run(capsys, "stats", "--N", "3", "--k", "-0.333334")
    assert code == 0 and "unstable: k = -0.333334 is beyond k_di = -0.3333333333" in out
    code, out, _ = run(capsys, "stats", "--N", "3", "--k", "-0.33333333334")
    assert "k = -0.3333333333 is beyond k_di = -0.3333333333" in out


def _number_text() -> "st.SearchStrategy[str]":
    from hypothesis import strategies as st

    finite = st.floats(allow_nan=False, allow_infinity=False)
    wide = st.builds(lambda m, e, s: f"{s}{m:.6g}e{e}", st.floats(1.0, 9.99), st.integers(-330, 310),
                     st.sampled_from(["", "", "", "-"]))
    return st.one_of(wide, finite.map(repr), st.sampled_from(["0", "-0", "inf", "-inf", "nan", "1e-320", "5e-324"]))


_NAMES = ("a", "n", "N", "k", "m", "gamma", "Kv", "Kc", "sigma", "tau", "D", "tau_p", "R", "tol", "seed")


def _argv():
    from hypothesis import strategies as st

    num = _number_text()
    params = st.lists(st.tuples(st.sampled_from(_NAMES[4:13]), num), max_size=4)
    return st.builds(
        lambda a, n, N, k, ps, method: ["stats", "--a", a, "--n", n, "--N", N, "--k", k,
                                        *[x for p, v in ps for x in ("--param", f"{p}={v}")], *method, "--json"],
        num, st.one_of(st.just("2"), st.just("2"), num), st.one_of(st.sampled_from(["1", "2", "3", "7"]),
                                                                    st.integers(-2, 10**7).map(str)),
        st.one_of(st.just("0"), num), params,
        st.sampled_from([[], [], [], ["--method", "fpe", "--opt", "max_seconds=0.2", "--tol", "0.05"],
                         ["--method", "mc", "--seed", "0", "--opt", "max_time=0.2", "--opt", "paths=16",
                          "--opt", "t_run=5", "--opt", "min_replicas=2"]]))


def _check_cli(argv: list[str]) -> None:
    import contextlib
    import io
    import math
    import re

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: unparsable argument
            code = exc.code
    text = err.getvalue().strip()
    if code == 0:
        d = json.loads(out.getvalue(), parse_constant=lambda c: pytest.fail(f"non-finite {c} in the JSON"))
        assert d["status"] in ("stable", "marginal", "unstable", "metastable", "not_converged")
        for q in ("eta", "V2", "Vrms", "Pin", "v2", "vV", "x2"):
            v, e = d[q], d[q + "_err"]
            assert (v is None) == (e is None)
            if v is not None:
                assert math.isfinite(v) and math.isfinite(e) and e >= 0
                if d["status"] in ("stable", "marginal") and q in ("eta", "V2", "Pin"):
                    assert e < abs(v), (q, v, e, d["message"])
        return
    assert code == 2, (code, text)
    lines = [ln for ln in text.splitlines() if not ln.startswith(("fpe ", "mc "))]  # progress bars
    assert len(lines) == 1 and "Traceback" not in text, text
    assert re.search(r"(\b|--)(" + "|".join(_NAMES) + r")\b", lines[0]), lines[0]


def test_stats_fuzz_numbers_or_one_line_error(fuzz):
    """``harvester stats`` on arbitrary numbers (any notation, any size, nan/inf, negative, subnormal):
    exit 0 with finite numbers and errors below their values, or exit 2 with one line naming the argument."""
    fuzz(_check_cli, {"ci": 40, "long": 3000}, argv=_argv())


@pytest.mark.parametrize(("N", "k4", "k_di", "modes"), [
    ("4", "0.1", -0.9, [2]), ("4", "0.5", -2.0, [1, 3]), ("6", "0.5", -13 / 6, [2, 4]), ("64", "0.5", -2.0, [16, 48]),
])
def test_threshold_with_k4(capsys, N, k4, k_di, modes):
    code, out, _ = run(capsys, "threshold", "--N", N, "--a", "1", "--k4", k4, "--json")
    d = json.loads(out)
    assert code == 0 and d["k_di"] == pytest.approx(k_di, abs=1e-12) and d["critical_mode"] == modes
    assert d["k4"] == float(k4)


def test_stats_with_k4_and_kv_zero(capsys):
    code, out, _ = run(capsys, "stats", "--N", "3", "--k", "-0.5", "--k4", "0.1", "--json")
    shifted = json.loads(run(capsys, "stats", "--N", "3", "--k", "-0.2", "--json")[1])
    d = json.loads(out)
    assert code == 0 and d["eta"] == pytest.approx(shifted["eta"], rel=1e-12)
    assert d["harvester"]["k4"] == 0.1 and "k3" not in d["harvester"]
    code, out, _ = run(capsys, "stats", "--param", "Kv=0", "--json")
    # without back-action Pin = D sigma^2 (tau + tau_p)/d1, d1 = m(tau + tau_p)(1 + gamma tau) + 2a tau^2 (tau + tau_p)
    assert code == 0 and json.loads(out)["Pin"] == pytest.approx(3.0 / 9.0, rel=1e-14)


@pytest.mark.parametrize(("argv", "match"), [
    (("stats", "--N", "3", "--k3", "0.1", "--method", "exact"), r"k3 = 0.1 \(cubic coupling\) is nonlinear"),
    (("stats", "--k4", "0.1"), r"k4 must be 0 for a single unit \(N = 1"),
    (("stats", "--N", "3", "--k3", "-1"), r"k3 must be in \[0, inf\), got -1"),
    (("stats", "--param", "Kv=0", "--param", "gamma=0"), "gamma = 0 and Kv = 0 leave the oscillator undamped"),
    (("landscape", "--N", "7"), r"N must be in \[1, 6\]"),
])
def test_higher_couplings_refused_in_one_line(capsys, argv, match):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert re.search(match, err)


def test_landscape_table_and_json(capsys):
    code, out, _ = run(capsys, "landscape", "--n", "1", "--a", "1", "--N", "3", "--k", "-2", "--k3", "1", "--json")
    d = json.loads(out)
    assert code == 0 and d["bounded"] is True
    b = d["buckling"]
    assert b["k_sn"] == pytest.approx(-(27 / 16) ** (1 / 3), abs=1e-8) and b["k_co"] == pytest.approx(-1.5, abs=1e-8)
    assert b["escape_barrier"] == pytest.approx(0.127088, abs=5e-7)
    assert b["return_barrier"] == pytest.approx(0.782190, abs=5e-7)
    assert b["hop_barrier"] == pytest.approx(0.193831, abs=5e-7)
    assert sum(q["kind"] == "minimum" for q in d["equilibria"]) == 7
    code, out, _ = run(capsys, "landscape", "--k", "-2", "--k3", "1", "--max-rows", "3")
    assert code == 0 and "k_sn (fold)" in out and "-1.190550789" in out and "22 more" in out
    code, out, _ = run(capsys, "landscape", "--k", "-0.5")
    assert code == 0 and "no global minimum" in out


def test_scene_couplings_reach_the_system_and_its_quick_variant():
    import argparse

    from fpe_harvester.cli import _with_couplings
    from fpe_harvester.scenes import load_scene

    scene = load_scene("fig4_eta_vs_k_harmonic")
    same = _with_couplings(scene, argparse.Namespace(k4=None, k3=None))
    assert same is scene
    changed = _with_couplings(scene, argparse.Namespace(k4=0.05, k3=None))
    assert changed.system.k4 == 0.05 and changed.variant(True).system.k4 == 0.05
    assert changed.system.k3 == 0.0
