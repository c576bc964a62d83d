"""Text from the user is drawn as text, in every picture, within bounds.

Titles, units, part names and sweep keys and values that matplotlib would read as
mathtext (``$``, ``\\frac{``, ``^``, ``_``) go through every command that writes a
picture; each exits 0 and writes its PNGs (the sweep its sweep.json too). What only a
result file can carry (control characters, a title of megabytes) goes through ``plot``
and the drawing functions.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import square_case_dict
from test_cli import invoke

#: Strings a case file may hold as a title (at most 200 printable characters) that
#: matplotlib's mathtext would parse, or fail to.
HOSTILE = {
    "dollar": "$",
    "two-dollars": "$$",
    "frac": "load $\\frac{$ case",
    "open-frac": "\\frac{",
    "caret": "x^",
    "underscore": "a_b",
    "percent": "100%",
    "braces": "{}",
    "math-pair": "$\\alpha$ and $\\beta_{$",
    "long": ("$\\frac{x}^_%{} " * 20)[:200],
    "non-ascii": "荷重 Ωμ ñ 🙂 $x^2$ ∑",
}


def _unit(text: str) -> str:
    """A unit symbol from ``text``: at most 16 printable characters, no spaces."""
    return text.replace(" ", "")[:16] or "$"


def _platen_case(text: str) -> dict:
    """A block pressed by a platen on a part named ``text``, in units named after it, over a
    load path of two steps (so that `solve` writes path.png)."""
    part = text[:64]
    return {
        "title": text,
        "units": {"length": _unit(text), "force": _unit(text[::-1])},
        "geometry": {"polygon": {"vertices": [[0, 0], [1, 0], [1, 0.5], [0, 0.5]],
                                 "edges": ["base", "right", part, "left"]}},
        "mesh": {"size": 0.2},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {part: {"platen": {"force": 2000}}, "left": "symmetry", "right": "free", "base": "contact"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
        "load_path": {"steps": 2},
    }


def _square_case(text: str, divisions: int = 4) -> dict:
    data = square_case_dict(divisions)
    data["title"] = text
    data["units"] = {"length": _unit(text), "force": _unit(text[::-1])}
    return data


def _write(path: Path, data: dict) -> Path:
    path.write_text(yaml.safe_dump(data, allow_unicode=True, sort_keys=False), encoding="utf-8")
    return path


def _is_png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _ok(*args) -> None:
    result = invoke(*args)
    assert result.exit_code == 0, (args, result.stderr)
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("text", HOSTILE.values(), ids=HOSTILE.keys())
def test_every_picture_command_draws_hostile_text_as_text(text, tmp_path, monkeypatch):
    """solve --plot (deformed.png, contact_profile.png, path.png, drawn from solution.h5 as
    `plot` draws them), compare, converge, adapt and sweep, and plot on the compare and
    converge directories (drawn from their JSON): exit 0, every PNG written, sweep.json written."""
    import sys

    monkeypatch.setitem(sys.modules, "dask", None)  # the sweep's points in this process
    monkeypatch.setitem(sys.modules, "distributed", None)
    platen = _write(tmp_path / "platen.yaml", _platen_case(text))
    square = _write(tmp_path / "square.yaml", _square_case(text))

    _ok("solve", platen, "--out", tmp_path / "s", "--plot", "--quiet")
    for name in ("deformed.png", "contact_profile.png", "path.png"):
        assert _is_png(tmp_path / "s" / name), name

    _ok("compare", square, "--out", tmp_path / "c", "--quiet")
    assert _is_png(tmp_path / "c" / "compare.png")
    _ok("plot", tmp_path / "c", "--quiet")

    _ok("converge", square, "--levels", "2", "--method", "positive", "--out", tmp_path / "v", "--quiet")
    for name in ("convergence_h.png", "convergence_time.png"):
        assert _is_png(tmp_path / "v" / name), name
    _ok("plot", tmp_path / "v", "--quiet")

    _ok("adapt", square, "--max-unknowns", "200", "--out", tmp_path / "a", "--quiet")
    assert _is_png(tmp_path / "a" / "adapt.png")

    sweep = _write(tmp_path / "sweep.yaml", {"title": text, "case": "square.yaml",
                                             "grid": {"mesh.divisions": [2, 4], "title": [text, text[:150]]}})
    _ok("sweep", sweep, "--out", tmp_path / "w", "--quiet")
    assert _is_png(tmp_path / "w" / "sweep.png")
    table = json.loads((tmp_path / "w" / "sweep.json").read_text(encoding="utf-8"))
    assert {row["status"] for row in table["points"]} == {"ok"}


# --------------------------------------------------------------------------- what only a result file carries


#: A title only a result file can carry: control characters, mathtext, and megabytes of it.
HUGE = "\x00\x07\x1b[31m $\\frac{$ \r\n\t\ud800 " + "$x^" * 3_500_000


@pytest.fixture(scope="module")
def studies(tmp_path_factory):
    """A compare and a converge directory of the square."""
    root = tmp_path_factory.mktemp("studies")
    square = _write(root / "square.yaml", square_case_dict(4))
    _ok("compare", square, "--out", root / "c", "--quiet")
    _ok("converge", square, "--levels", "2", "--method", "positive", "--out", root / "v", "--quiet")
    _ok("solve", square, "--out", root / "s", "--quiet")
    return root


@pytest.mark.parametrize("name, study", [("c", "compare.json"), ("v", "convergence.json")])
def test_plot_draws_a_result_files_control_characters_and_megabytes_quickly(studies, name, study, tmp_path):
    """compare.json and convergence.json whose title, units and method names hold control
    characters, mathtext and 10 MB: `plot` redraws them in seconds, exit 0."""
    import shutil

    directory = tmp_path / name
    shutil.copytree(studies / name, directory)
    content = json.loads((directory / study).read_text(encoding="utf-8"))
    content["case"]["title"] = HUGE
    content["units"] = {"length": "$\x07^", "force": HUGE, "stress": "\\frac{"}
    if "rows" in content:
        for row in content["rows"]:
            row["method"] = "$" + row["method"] + "\x1b"
    (directory / study).write_text(json.dumps(content), encoding="utf-8")
    started = time.process_time()
    _ok("plot", directory, "--quiet")
    assert time.process_time() - started < 30
    for png in ("compare.png",) if name == "c" else ("convergence_h.png", "convergence_time.png"):
        assert _is_png(directory / png)


def test_a_solution_files_huge_title_is_drawn_quickly_and_cut(studies, tmp_path):
    """deformed.png and contact_profile.png from a solution.h5 whose title attribute is 10 MB
    of mathtext and control characters, and whose units are mathtext: drawn in seconds,
    the title cut to a line with an ellipsis."""
    from contactfem.plots import plot_result_profile
    from contactfem.render import load_result, render_deformed

    data = load_result(studies / "s")
    data["attrs"] = {**data["attrs"], "title": HUGE, "length_unit": "$x^$", "stress_unit": "\\frac{",
                     "method": "$\\frac{"}
    started = time.process_time()
    render_deformed(data, tmp_path / "deformed.png", size=(800, 600))
    plot_result_profile(tmp_path / "contact_profile.png", data, size=(800, 600), title=HUGE)
    assert time.process_time() - started < 30
    assert _is_png(tmp_path / "deformed.png") and _is_png(tmp_path / "contact_profile.png")


# --------------------------------------------------------------------------- the helpers


def test_shown_makes_one_bounded_line_of_anything():
    from contactfem.picture_text import ELLIPSIS, USER_CHARS, shown

    assert shown("load $\\frac{$ case") == "load $\\frac{$ case"  # kept as written: drawn literally
    assert shown("a\tb\nc\rd") == "a b c d"
    assert shown("a\x00b\x1bc\ud800") == "a\ufffdb\ufffdc\ufffd"
    assert shown(3.5) == "3.5"
    long = shown("x" * 10_000_000)
    assert len(long) == USER_CHARS and long.endswith(ELLIPSIS)
    assert shown("y" * USER_CHARS) == "y" * USER_CHARS


def test_heading_wraps_and_cuts():
    from contactfem.picture_text import ELLIPSIS, heading

    assert heading("short title") == "short title"
    text = heading("word " * 1000, width=50, lines=2)
    lines = text.split("\n")
    assert len(lines) == 2 and all(len(line) <= 50 for line in lines) and text.endswith(ELLIPSIS)
    unbroken = heading("$" * 500, width=40, lines=3)
    assert len(unbroken.split("\n")) == 3 and all(len(line) <= 40 for line in unbroken.split("\n"))


def test_literal_leaves_only_tick_labels_to_mathtext(tmp_path):
    """Every text of a figure (title, suptitle, labels, legend, annotation, figure text) is drawn
    literally after literal(); the log axis' tick labels keep their mathtext (10^k)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from contactfem.picture_text import TEXT_CHARS, literal, save_png

    figure, axis = plt.subplots()
    try:
        axis.loglog([1, 10, 100], [1, 10, 100], label="$\\frac{$")
        axis.legend()
        axis.set_title("$x^$")
        axis.set_xlabel("\\frac{")
        axis.annotate("$$", (10, 10))
        figure.suptitle("$" * 10_000)
        figure.text(0.1, 0.1, "_^")
        assert literal(figure) >= 6
        texts = [axis.title, axis.xaxis.label, axis.texts[0], figure.texts[-1], axis.get_legend().get_texts()[0]]
        assert all(not text.get_parse_math() for text in texts)
        assert len(figure._suptitle.get_text()) == TEXT_CHARS
        save_png(figure, tmp_path / "figure.png", layout={})
        ticks = [t for t in axis.xaxis.get_majorticklabels() if t.get_text()]
        assert ticks and all(t.get_parse_math() for t in ticks) and any("$" in t.get_text() for t in ticks)
    finally:
        plt.close(figure)
    assert _is_png(tmp_path / "figure.png")


def test_every_picture_is_written_through_the_literal_writer():
    """No module draws a PNG by itself: each figure goes through picture_text.save_png."""
    root = Path(__file__).resolve().parents[1] / "contactfem"
    writers = [path.relative_to(root).as_posix() for path in root.rglob("*.py")
               if ".savefig(" in path.read_text(encoding="utf-8")]
    assert writers == ["picture_text.py"]


def test_a_missing_glyph_is_a_box_not_a_warning(tmp_path, recwarn):
    """A title in a script the font lacks draws boxes and says nothing on stderr."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from contactfem.picture_text import save_png

    figure, axis = plt.subplots()
    try:
        axis.set_title("荷重")
        save_png(figure, tmp_path / "glyph.png", layout={})
    finally:
        plt.close(figure)
    assert not [w for w in recwarn.list if "Glyph" in str(w.message)]
    assert np.asarray(plt.imread(tmp_path / "glyph.png")).size
