"""Every code example of the documentation runs, without the site: each page's ``python`` blocks in
order, in one namespace, in a temporary folder; every ``harvester`` command line on the pages
parses, and the ones that answer at once (threshold, landscape, scene list, harmonic stats) run."""

from __future__ import annotations

import dataclasses
import re
import shlex
from pathlib import Path

import pytest

from fpe_harvester.cli import build_parser, main

DOCS = Path(__file__).resolve().parents[2] / "docs"
PAGES = sorted(DOCS.glob("*.md"))


def blocks(path: Path, language: str) -> list[str]:
    """The fenced code blocks of one language on a page."""
    return re.findall(rf"^```{language}\n(.*?)^```", path.read_text(encoding="utf-8"), re.DOTALL | re.MULTILINE)


def commands(path: Path) -> list[list[str]]:
    """The ``harvester`` command lines of a page's bash blocks, without their comments."""
    out = []
    for block in blocks(path, "bash"):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words[:1] == ["harvester"]:
                out.append(words[1:])
    return out


@pytest.mark.parametrize("page", [p.name for p in PAGES if blocks(p, "python")])
def test_python_examples_run(page: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # examples write their outputs where they run
    namespace: dict[str, object] = {"__name__": "__docs__"}
    for i, code in enumerate(blocks(DOCS / page, "python")):
        exec(compile(code, f"docs/{page} (python block {i + 1})", "exec"), namespace)  # noqa: S102


def _answers_at_once(argv: list[str]) -> bool:
    if argv[0] in ("threshold", "landscape") or argv[:2] == ["scene", "list"]:
        return True
    if argv[0] != "stats":
        return False
    args = build_parser().parse_args(argv)
    return args.n == 2 and args.k3 == 0 and args.method in ("auto", "exact")


@pytest.mark.parametrize("page", [p.name for p in PAGES if commands(p)])
def test_command_lines_parse_and_the_quick_ones_run(page: str, capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    for argv in commands(DOCS / page):
        parser.parse_args(argv)  # an option that does not exist exits here
        if _answers_at_once(argv):
            assert main(argv) == 0, (argv, capsys.readouterr().err)
    capsys.readouterr()


def test_the_cli_page_covers_every_command_and_option() -> None:
    text = (DOCS / "cli.md").read_text(encoding="utf-8")
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    missing = []
    for name, command in sub.choices.items():
        if f"harvester {name}" not in text:
            missing.append(f"harvester {name}")
        for action in command._actions:
            missing += [f"{name} {o}" for o in action.option_strings if o.startswith("--") and o != "--help"
                        and o not in text]
    assert not missing, f"docs/cli.md does not mention: {missing}"


def test_the_scene_format_page_covers_every_key() -> None:
    from fpe_harvester.scenes import spec

    text = (DOCS / "scene-format.md").read_text(encoding="utf-8")
    keys = {*spec._TOP_KEYS, *spec._QUICK_KEYS, *spec.AXIS_NAMES, "k4", "k3", "params", "values", "linspace",
            "logspace", "integers", "unit", "maximize", "over", "bounds", "points", "vline", "hline", "point",
            "label", "panel", *(f.name for f in dataclasses.fields(spec.FigureSpec))}
    prose = re.sub(r"^```.*?^```", "", text, flags=re.DOTALL | re.MULTILINE)  # the example file aside
    spans = {word for span in re.findall(r"`([^`]+)`", prose) for word in re.findall(r"\w+", span)}
    missing = sorted(keys - spans)
    assert not missing, f"docs/scene-format.md does not mention: {missing}"
