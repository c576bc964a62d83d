"""The "Python API" example of README.md runs exactly as written, in an empty directory."""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def api_example() -> str:
    """The first ```python block of README.md's "Python API" section."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("\n## Python API\n"):]
    section = section[:section.index("\n## ", 1)]
    match = re.search(r"```python\n(.*?)```", section, flags=re.DOTALL)
    assert match is not None, "README.md's Python API section has no python code block"
    return match.group(1)


def test_the_readme_python_api_example_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    code = api_example()
    exec(compile(code, str(README), "exec"), {"__name__": "readme_example"})  # noqa: S102 - README's own code
    printed = capsys.readouterr().out
    assert printed.startswith("converged")
    out = tmp_path / "results" / "block"
    for name in ("report.json", "solution.h5", "solution.vtu", "contact.vtu", "deformed.png", "contact_profile.png"):
        assert (out / name).is_file(), name
    assert "'stress': 'MPa'" in printed
