"""The README stays a short first document, and the documentation site builds without a warning.

README.md opens with the two commands CI runs verbatim, and is at most MAX_README_LINES
lines; every page of mkdocs.yml's nav exists; every relative link of README.md and
docs/*.md reaches a file; and, where mkdocs and its plugins are installed (the ``docs``
extra), ``mkdocs build --strict`` succeeds.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
MKDOCS_YML = ROOT / "mkdocs.yml"

MAX_README_LINES = 300
#: The README's first two fenced blocks, exactly: install and solve, then the tests.
OPENING_COMMANDS = (
    "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && contactfem solve cases/square.yaml",
    "pip install -e '.[test]' && python -m pytest -q",
)

_FENCE = re.compile(r"^(```|~~~)[^\n]*\n(.*?)^\1[ \t]*$", flags=re.DOTALL | re.MULTILINE)
_INLINE_CODE = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def fenced_blocks(text: str) -> list[str]:
    """The contents of the fenced code blocks of a Markdown text, in order."""
    return [match.group(2) for match in _FENCE.finditer(text)]


def relative_links(text: str) -> list[str]:
    """Link and image targets outside code that point into the repository (no scheme, not
    only an anchor), without their anchor."""
    prose = _INLINE_CODE.sub("", _FENCE.sub("", text))
    targets = []
    for target in _LINK.findall(prose):
        if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith("#"):
            continue
        targets.append(target.split("#", 1)[0])
    return targets


def nav_pages(nav: list) -> list[str]:
    """Every page file named in a mkdocs nav (nested sections included)."""
    pages = []
    for item in nav:
        value = item
        if isinstance(item, dict):
            (value,) = item.values()
        if isinstance(value, list):
            pages += nav_pages(value)
        elif isinstance(value, str) and not re.match(r"^[a-z]+://", value):
            pages.append(value)
    return pages


def markdown_files() -> list[Path]:
    return [README, *sorted(DOCS.rglob("*.md"))]


def test_the_readme_is_at_most_300_lines():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; move detail into docs/"


def test_the_readme_opens_with_the_install_and_test_commands():
    blocks = fenced_blocks(README.read_text(encoding="utf-8"))
    assert [block.strip() for block in blocks[:2]] == list(OPENING_COMMANDS)


def test_every_page_of_the_nav_exists():
    config = yaml.safe_load(MKDOCS_YML.read_text(encoding="utf-8"))
    docs_dir = ROOT / config.get("docs_dir", "docs")
    pages = nav_pages(config["nav"])
    assert pages, "mkdocs.yml has no nav"
    missing = [page for page in pages if not (docs_dir / page).is_file()]
    assert missing == []


@pytest.mark.parametrize("path", markdown_files(), ids=lambda path: str(path.relative_to(ROOT)))
def test_every_relative_link_reaches_a_file(path):
    text = path.read_text(encoding="utf-8")
    broken = [target for target in relative_links(text)
              if target and not (path.parent / target).exists()]
    assert broken == []


def test_the_link_finder_skips_code_urls_and_anchors():
    text = ("See [a](a.md#x), ![b](img/b.png), [c](https://example.org), [d](#local) and `[e](e.md)`.\n"
            "```\n[f](f.md)\n```\n")
    assert relative_links(text) == ["a.md", "img/b.png"]


def test_the_site_builds_without_a_warning(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(module)
    environment = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, env=environment, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "site" / "index.html").is_file()
