"""Every study runs as ``python -m validation.studies.<subject>.<name>``, and every command or
dotted name under ``validation`` that the docs, the README, the packages' docstrings and the
recorded data mention names a module that exists (a study that moves takes its mentions along).

Read from the files (AST and text); nothing is imported.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
STUDIES = ROOT / "validation" / "studies"
#: Where the mentions are read: the user's pages and every file the packages ship.
PLACES = ("README.md", "docs", "examples", "fpe_harvester", "montecarlo", "validation")
#: Modules of the studies that other studies import, not run on their own.
LIBRARIES = {"cli", "prototypes.xvw_mesh", "prototypes.xvw_w", "prototypes.xvw_hybrid"}

#: A command or a dotted name; ``.<name>``, ``.*`` or ``.X`` after it make it a pattern, not a name.
COMMAND = re.compile(r"python -m (validation(?:\.\w+)*+)(?!\.[<*])")
DOTTED = re.compile(r"(?<![\w.])(validation(?:\.\w+)++)(?!\.[<*])")


def _module_path(dotted: str) -> Path | None:
    base = ROOT.joinpath(*dotted.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _runs_as_script(path: Path) -> bool:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return any(isinstance(node, ast.If) and "__main__" in ast.unparse(node.test) for node in tree.body)


def _top_level_names(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
    return names


def _texts() -> list[tuple[Path, str]]:
    out = []
    for place in PLACES:
        root = ROOT / place
        files = [root] if root.is_file() else [p for p in root.rglob("*")
                                               if p.suffix in (".py", ".md", ".json", ".rst") and "_build" not in p.parts]
        out += [(p, p.read_text(encoding="utf-8")) for p in files]
    return out


def test_every_study_runs_as_a_script() -> None:
    studies = {p.relative_to(STUDIES).with_suffix("").as_posix().replace("/", ".") for p in STUDIES.rglob("*.py")
               if p.name != "__init__.py"}
    assert {s.split(".")[0] for s in studies} >= {"exact", "fpe", "mc", "kink", "prototypes"}
    assert LIBRARIES <= studies, "a library module moved: update LIBRARIES"
    silent = sorted(s for s in studies - LIBRARIES if not _runs_as_script(STUDIES.joinpath(*s.split(".")).with_suffix(".py")))
    assert not silent, f"studies without a command line: {silent}"


def test_every_command_names_a_module_that_runs() -> None:
    bad = []
    for path, text in _texts():
        for name in set(COMMAND.findall(text)):
            if re.search(r"\.[A-Z]$", name):
                continue
            module = _module_path(name)
            if module is None or (module.name != "__init__.py" and not _runs_as_script(module)):
                bad.append(f"{path.relative_to(ROOT)}: python -m {name}")
            elif module.name == "__init__.py" and not (module.parent / "__main__.py").is_file():
                bad.append(f"{path.relative_to(ROOT)}: python -m {name} (a package without __main__)")
    assert not bad, "commands that do not run:\n" + "\n".join(sorted(bad))


def test_every_dotted_name_resolves() -> None:
    bad = []
    for path, text in _texts():
        for name in set(DOTTED.findall(text)):
            if re.search(r"\.[A-Z]$", name):
                continue
            parts = name.split(".")
            for i in range(len(parts), 0, -1):
                module = _module_path(".".join(parts[:i]))
                if module is not None:
                    break
            rest = parts[i:]
            if rest and rest[0] not in _top_level_names(module):
                bad.append(f"{path.relative_to(ROOT)}: {name}")
    assert not bad, "names of no module or definition:\n" + "\n".join(sorted(bad))
