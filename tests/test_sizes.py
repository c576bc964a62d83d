"""The package stays readable: no module over 800 lines, no function over 120, no class over 400.

Read from the source with :mod:`ast`, so that a long docstring counts like code: a reader
has to get through both.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "contactfem"
MODULE_LINES, FUNCTION_LINES, CLASS_LINES = 800, 120, 400


def _sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _too_long(path: Path) -> list[str]:
    text = path.read_text(encoding="utf-8")
    found = []
    if text.count("\n") > MODULE_LINES:
        found.append(f"module {path.relative_to(PACKAGE.parent)}: {text.count(chr(10))} lines")
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            length = node.end_lineno - node.lineno + 1
            bound = CLASS_LINES if isinstance(node, ast.ClassDef) else FUNCTION_LINES
            if length > bound:
                found.append(f"{path.relative_to(PACKAGE.parent)}: {node.name}: {length} lines")
    return found


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_modules_functions_and_classes_stay_within_their_bounds(path):
    assert _too_long(path) == []


def test_the_check_reports_a_function_of_121_lines_and_not_one_of_120(tmp_path, monkeypatch):
    monkeypatch.setattr(__import__(__name__), "PACKAGE", tmp_path)
    body = "\n".join(f"    x{i} = {i}" for i in range(119))
    (tmp_path / "long.py").write_text(f"def f():\n{body}\n    return 0\n")
    (tmp_path / "short.py").write_text(f"def f():\n{body}\n")
    assert _too_long(tmp_path / "long.py") == ["long.py: f: 121 lines".replace("long.py", f"{tmp_path.name}/long.py")]
    assert _too_long(tmp_path / "short.py") == []
