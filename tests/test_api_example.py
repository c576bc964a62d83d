"""The example of the documentation's Python API page runs exactly as written, in an empty directory."""

from __future__ import annotations

import re
from pathlib import Path

API_PAGE = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def api_example() -> str:
    """The first ```python block of docs/api.md's "An example" section."""
    text = API_PAGE.read_text(encoding="utf-8")
    section = text[text.index("\n## An example\n"):]
    section = section[:section.index("\n## ", 1)]
    match = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL)
    assert match is not None, "docs/api.md's example section has no python code block"
    return match.group(1)


def test_the_documented_python_api_example_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = api_example()
    exec(compile(code, str(API_PAGE), "exec"), {"__name__": "api_example"})  # noqa: S102 - the page's own code
    printed = capsys.readouterr().out
    assert printed.startswith("converged")
    out = tmp_path / "results" / "block"
    for name in ("report.json", "solution.h5", "solution.vtu", "contact.vtu", "deformed.png", "contact_profile.png"):
        assert (out / name).is_file(), name
    assert "'stress': 'MPa'" in printed
