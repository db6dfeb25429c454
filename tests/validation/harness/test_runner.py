"""The runner and the command line, on tiny fake steps (the real suite runs in CI separately)."""

from __future__ import annotations

import pytest

import validation.harness.cli as vcli
import validation.harness.runner as runner
from fpe_harvester.cli import build_parser, main
from validation.harness.checks import expect
from validation.harness.report import Section
from validation.sections import SECTIONS, Step

#: The closing section: the identities of every result of the run (none here: one skip per solver).
IDENTITIES = SECTIONS[-1]


def _passing(ctx):
    sec = Section("ok", "Passing step")
    sec.checks += [expect(f"fine {i}", "Passing step", True, "ok") for i in range(40)]
    return sec


def _few_passing(ctx):
    sec = Section("few", "Few checks")
    sec.checks.append(expect("fine", "Few checks", True, "ok"))
    return sec


def _failing(ctx):
    sec = Section("bad", "Failing step")
    sec.checks.append(expect("wrong", "Failing step", False, "must fail"))
    return sec


def _crashing(ctx):
    raise RuntimeError("step exploded")


def _finding(ctx):
    from validation.harness.checks import finding

    sec = Section("paper", "Finding step")
    sec.checks.append(finding("paper off", "Finding step", "a second solver confirms ours", 0.6103, 0.609))
    return sec


def _recording(ctx):
    from validation.harness.checks import recorded

    sec = Section("rec", "Recorded step")
    sec.checks.append(recorded("old data", "Recorded step", True, "two decades", source="validation/data/x.json",
                               command="python -m validation.studies.x --out validation/data"))
    return sec


def _raising_check(ctx):
    """A step whose one check raises inside the run's guard: a FAIL with its reason, the step goes on."""
    sec = Section("raise", "Raising check")
    sec.checks += ctx.check("explodes", "Raising check", lambda: 1 / 0)
    sec.checks.append(expect("after it", "Raising check", True, "still ran"))
    return sec


def _skipping(ctx):
    from validation.harness.checks import skipped

    sec = Section("skip", "Skipping step")
    sec.checks.append(skipped("never ran", "Skipping step", "the quick run's overall time budget was used up"))
    return sec


def test_validate_writes_both_reports(tmp_path):
    rep = runner.validate(quick=True, out=tmp_path, steps=[(_passing, "Passing step"), IDENTITIES])
    assert not rep.failed
    assert (tmp_path / "report.md").is_file() and (tmp_path / "report.html").is_file()
    assert "Passing step" in (tmp_path / "report.md").read_text()
    # the closing identities section reports every solver that produced nothing as skipped ...
    skips = [c.name for c in rep.skipped]
    assert skips == ["identities [exact]", "identities [fpe]", "identities [mc]"]
    # ... which a quick run may do (3 of 43 checks), a full run may not
    assert runner.exit_code(rep, quick=True) == 0 and runner.exit_code(rep, quick=False) == 1


def test_a_quick_run_fails_when_too_few_checks_ran(tmp_path):
    """1 check ran and 3 were skipped: 25 % ran, below QUICK_MIN_RAN."""
    rep = runner.validate(quick=True, out=tmp_path, steps=[(_few_passing, "Few checks"), IDENTITIES])
    assert not rep.failed and len(rep.skipped) == 3
    assert runner.exit_code(rep, quick=True) == 1
    rep.sections[0].checks += [expect(f"more {i}", "Few checks", True, "ok") for i in range(26)]
    assert runner.exit_code(rep, quick=True) == 0        # 27 of 30 ran: exactly 90 %
    rep.sections[0].checks.pop()
    assert runner.exit_code(rep, quick=True) == 1        # 26 of 29


def test_a_crashing_step_becomes_a_failed_check(tmp_path):
    rep = runner.validate(out=tmp_path, steps=[(_crashing, "Crashing step")])
    assert rep.failed
    assert any("step exploded" in c.detail for c in rep.checks)


def test_validate_rejects_a_negative_seed(tmp_path):
    from fpe_harvester import ParameterError

    with pytest.raises(ParameterError, match="seed"):
        runner.validate(out=tmp_path, seed=-1, steps=[])


def test_cli_arguments():
    args = build_parser().parse_args(["validate", "--quick", "--out", "somewhere"])
    assert args.command == "validate" and args.quick and args.out == "somewhere" and args.seed == 2017
    args = build_parser().parse_args(["validate"])
    assert not args.quick and args.out == "validation_report"
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["validate", "--seed", "abc"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["validate", "--bogus"])
    assert exc.value.code == 2


@pytest.mark.parametrize(("steps", "quick", "code"), [
    (((_passing, "Passing step"),), True, 0),
    (((_passing, "Passing step"), (_failing, "Failing step")), True, 1),
    (((_passing, "Passing step"), (_skipping, "Skipping step")), True, 0),
    (((_passing, "Passing step"), (_skipping, "Skipping step")), False, 1),
    (((_passing, "Passing step"), (_finding, "Finding step")), True, 0),
    (((_passing, "Passing step"), (_recording, "Recorded step")), True, 0),
    (((_passing, "Passing step"), (_raising_check, "Raising check")), True, 1),
])
def test_cli_exit_code(monkeypatch, tmp_path, capsys, steps, quick, code):
    """A failure fails any run; a skip fails the full run, and a quick run names every skip."""
    monkeypatch.setattr(runner, "SECTIONS", (*steps, IDENTITIES))
    assert main(["validate", *(["--quick"] if quick else []), "--no-progress", "--out", str(tmp_path)]) == code
    captured = capsys.readouterr()
    out = captured.out
    assert "passed" in out and "report.md" in out
    # each step's wall time is printed as soon as it ends (a long full run shows where it is)
    assert all(f"{title}: " in captured.err for _, title in steps)
    assert ("1 FAILED" in captured.err) == any(title in ("Failing step", "Raising check") for _, title in steps)
    assert (tmp_path / "report.html").is_file()
    if any(title == "Skipping step" for _, title in steps):
        assert "SKIP      never ran" in out and "check(s) SKIPPED" in out
    if any(title == "Recorded step" for _, title in steps):
        assert "RECORDED  old data" in out and "40 passed, 1 recorded, 0 findings, 0 failed, 3 skipped" in out
        assert "validation/data/x.json, written by python -m validation.studies.x" in out
        assert "1 checks, 1 recorded" in captured.err
    if any(title == "Raising check" for _, title in steps):
        assert "FAIL      explodes" in out and "ZeroDivisionError" in out
        assert "41 passed, 0 recorded, 0 findings, 1 failed, 3 skipped" in out
    if any(title == "Finding step" for _, title in steps):
        assert "FINDING   paper off" in out and "40 passed, 0 recorded, 1 finding, 0 failed, 3 skipped" in out
        assert "Finding step: " in captured.err and "1 checks, 1 finding" in captured.err
        assert ("a quick run fails below 90%" in out) == quick


def test_cli_negative_seed_is_a_clean_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(runner, "SECTIONS", ())
    assert main(["validate", "--seed", "-3", "--no-progress", "--out", str(tmp_path)]) == 2
    assert "seed" in capsys.readouterr().err


def test_python_m_validation_parser():
    args = vcli.build_parser().parse_args(["--quick", "--out", "d"])
    assert args.quick and args.out == "d"


def test_module_steps_are_imported_and_a_missing_one_fails(tmp_path):
    rep = runner.validate(out=tmp_path, steps=[("validation.no_such_module:run", "Missing step")])
    assert rep.failed
    (sec,) = [s for s in rep.sections if s.title == "Missing step"]
    assert "ModuleNotFoundError" in sec.checks[0].detail


def test_report_keeps_the_plan_order(tmp_path):
    rep = runner.validate(out=tmp_path, steps=[(_failing, "Failing step"), (_passing, "Passing step")])
    assert [s.title for s in rep.sections] == ["Failing step", "Passing step"]


@pytest.mark.parametrize("quick", [True, False])
def test_steps_run_in_their_mode_s_order_and_read_in_the_table_s(tmp_path, quick):
    ran = []

    def step(name):
        def run(ctx):
            ran.append(name)
            return Section(name, name)
        return run

    plan = [Step(step("a"), "a", quick=2, full=1), Step(step("b"), "b", quick=1, full=3),
            Step(step("c"), "c", quick=3, full=2)]
    rep = runner.validate(quick=quick, out=tmp_path, steps=plan)
    assert ran == (["b", "a", "c"] if quick else ["a", "c", "b"])
    assert [s.title for s in rep.sections] == ["a", "b", "c"]


def test_the_sections_table_names_each_section_once_and_the_identities_last():
    import importlib

    targets = [s.target for s in SECTIONS]
    assert len(set(targets)) == len(targets) and len({s.title for s in SECTIONS}) == len(SECTIONS)
    for s in SECTIONS:
        name, _, func = s.target.partition(":")
        assert callable(getattr(importlib.import_module(name), func or "run")), s.target
    # the identities read every result the other sections computed: they run last in both modes
    for mode in ("quick", "full"):
        assert max(SECTIONS, key=lambda s: getattr(s, mode)) is IDENTITIES
        assert sorted(getattr(s, mode) for s in SECTIONS).count(getattr(IDENTITIES, mode)) == 1
    assert IDENTITIES.target == "validation.sections.identities"


def test_python_m_validation_unwritable_out_is_a_one_line_error(capsys):
    assert vcli.main(["--out", "/dev/null/x", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out '/dev/null/x': cannot create the output folder" in err


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/stat"), reason="reads /proc (Linux)")
def test_processor_time_counts_the_live_worker_process():
    # the full run's worker solves Fokker-Planck problems for the sections; until it ends it is
    # not among the finished children, so the sections' CPU time reads it from /proc
    from fpe_harvester import Harvester
    from validation.harness.checks import SolveCache

    cache = SolveCache(background=True)
    assert cache.worker_cpu() == 0.0
    h = Harvester.build(a=0.5, n=3)
    before = runner.cpu_time(cache)
    try:
        cache.prefetch(h, "fpe", tol=1e-3)
        cache.solve(h, "fpe", tol=1e-3)
        worker = cache.worker_cpu()
        assert worker > 0.0
        assert runner.cpu_time(cache) - before >= worker
    finally:
        cache.close()
    assert cache.worker_cpu() == 0.0
