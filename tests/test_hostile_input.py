"""Hostile input through the command line: whatever the case file (or the path to it)
holds, ``contactfem solve`` refuses it with exit code 2 and exactly one line on stderr,
``error: <file>: <key> ...``, naming the file, without a traceback and without creating
the output directory, and it does so quickly and without reading more than it must.

Each case here was found by a hostile-input round (alias bombs, endless files, repeated
keys, overlong paths, expression corner cases, tiny holes) or written as a variant of
one (encodings, YAML oddities, number forms). A few inputs are valid and must solve.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
import yaml
from conftest import make_runner

from contactfem.case import (
    MAX_CASE_BYTES,
    MAX_POLYGON_VERTICES,
    MAX_YAML_DEPTH,
    MAX_YAML_VALUES,
    NAME_MAX,
    PATH_MAX,
    load_case,
    parse_case,
    path_problem,
)
from contactfem.cli import main
from contactfem.errors import CaseError

ROOT = Path(__file__).resolve().parents[1]
SQUARE_TEXT = (ROOT / "cases" / "square.yaml").read_text(encoding="utf-8").replace("divisions: 32", "divisions: 4")
CASE_NAME = "hostile.yaml"




def invoke(*args: object):
    return make_runner().invoke(main, [str(a) for a in args])


def assert_one_line(result, *fragments: str, code: int = 2) -> str:
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == code, (result.exit_code, result.stderr, result.stdout)
    assert "Traceback" not in result.stderr and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert len(lines[0]) < 1000, len(lines[0])
    return lines[0]


def refuse_file(case: Path, *fragments: str, out: Path | None = None) -> str:
    """Solve ``case`` into a fresh --out directory: one line naming the file, nothing written."""
    out = out if out is not None else case.parent / "out"
    line = assert_one_line(invoke("solve", case, "--out", out, "--quiet"), *fragments)
    assert not out.exists(), f"{out} was created"
    return line


def write(tmp_path: Path, content: str | bytes, name: str = CASE_NAME) -> Path:
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))
    return path


def refuse_text(tmp_path: Path, content: str | bytes, *fragments: str) -> str:
    return refuse_file(write(tmp_path, content), CASE_NAME, *fragments)


def solves(tmp_path: Path, content: str | bytes) -> None:
    out = tmp_path / "out"
    result = invoke("solve", write(tmp_path, content), "--out", out, "--quiet")
    assert result.exit_code == 0, result.stderr
    assert (out / "report.json").exists()


def square(**changes: object) -> str:
    """The square case (4 divisions) with top-level sections replaced, as YAML text."""
    data = yaml.safe_load(SQUARE_TEXT)
    data.update(changes)
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


def substitute(old: str, new: str) -> str:
    assert old in SQUARE_TEXT, old
    return SQUARE_TEXT.replace(old, new, 1)


# --------------------------------------------------------------------------- the file itself


def test_dev_zero_is_refused_without_reading_it():
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    started = time.process_time()
    assert_one_line(invoke("check", "/dev/zero"), "/dev/zero", "character device", "not a regular file")
    assert time.process_time() - started < 5


def test_a_fifo_is_refused_without_blocking(tmp_path):
    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs here")
    fifo = tmp_path / "case.fifo"
    os.mkfifo(fifo)
    refuse_file(fifo, "case.fifo", "FIFO", "not a regular file")


def test_a_huge_sparse_file_is_refused_from_its_size(tmp_path):
    case = tmp_path / CASE_NAME
    with open(case, "wb") as handle:
        handle.truncate(10 << 30)  # 10 GiB of holes: nothing is stored, nothing may be read
    refuse_file(case, CASE_NAME, "larger than", "1 MiB")


def test_one_byte_over_the_limit_is_refused_and_the_limit_itself_is_read(tmp_path):
    padding = MAX_CASE_BYTES - len(SQUARE_TEXT.encode("utf-8")) - 2
    at_limit = SQUARE_TEXT + "#" + "x" * padding + "\n"
    assert len(at_limit.encode("utf-8")) == MAX_CASE_BYTES
    assert load_case(write(tmp_path, at_limit)).title.startswith("square")
    refuse_text(tmp_path, at_limit + "\n", "larger than")


def test_a_directory_is_refused_in_one_line_by_the_reader(tmp_path):
    with pytest.raises(CaseError, match="is a directory") as caught:
        load_case(tmp_path)
    assert "\n" not in str(caught.value)


def test_a_directory_is_refused_through_the_cli(tmp_path):
    # click's Path(dir_okay=False) or the reader: either says so in one line
    assert_one_line(invoke("solve", tmp_path, "--out", tmp_path / "out"), str(tmp_path), "is a directory")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("length", [300, 5_000])
def test_overlong_case_file_paths(tmp_path, length):
    name = "a" * (length - len(".yaml")) + ".yaml" if length <= 2 * NAME_MAX else "a/" * (length // 2) + CASE_NAME
    line = assert_one_line(invoke("solve", tmp_path / name, "--out", tmp_path / "out"),
                           "component" if length <= 2 * NAME_MAX else "bytes long")
    assert "..." in line  # the path is shortened in the message
    assert not (tmp_path / "out").exists()


def test_a_nul_in_the_case_path_is_refused_by_the_reader(tmp_path):
    with pytest.raises(CaseError, match="NUL"):
        load_case(str(tmp_path / "a\x00b.yaml"))


def test_path_problem_checks_text_only():
    assert path_problem("results/square") is None
    assert "NUL" in path_problem("a\x00b")
    assert "component" in path_problem("x" * (NAME_MAX + 1))
    assert "bytes long" in path_problem("a/" * PATH_MAX)
    assert "kept for" in path_problem("x" * NAME_MAX, name_reserve=32)
    assert "surrogate" in path_problem("\ud800")


# --------------------------------------------------------------------------- YAML structure

BOMB = "".join(
    f"{name}: &{name} [{', '.join([f'*{prev}'] * 9 if prev else ['lol'] * 9)}]\n"
    for prev, name in zip([None, *"abcdefgh"], "abcdefghi")
)


def test_billion_laughs_is_refused_quickly(tmp_path):
    assert len(BOMB) < 1000  # 9**9 = 387 million strings once expanded
    started = time.process_time()
    refuse_text(tmp_path, BOMB, "aliases expanded", str(MAX_YAML_VALUES))
    refuse_text(tmp_path, square(title="x") + BOMB.replace("i: &i", "title: &i"), "aliases expanded")
    assert time.process_time() - started < 5


def test_billion_laughs_through_parse_case():
    with pytest.raises(CaseError, match=r"f\[0\] = \*e"):
        parse_case(BOMB, source="bomb.yaml")


@pytest.mark.parametrize(("text", "fragments"), [
    ("title: &a [1, *a]\n", ("title[1] = *a", "contains it")),
    ("title: &a {x: *a}\n", ("title.x = *a", "contains it")),
    ("title: " + "[" * 100 + "]" * 100 + "\n", (f"nested more than {MAX_YAML_DEPTH}",)),
    ("a: &a " + "[" * 20 + "1" + "]" * 20 + "\ntitle: " + "[" * 20 + "*a" + "]" * 20 + "\n",
     ("= *a", f"nested more than {MAX_YAML_DEPTH}")),
    ("title: [" + "0, " * (MAX_YAML_VALUES + 10) + "0]\n", ("title[", f"more than {MAX_YAML_VALUES} values")),
    ("title: *nothing\n", ("undefined alias",)),
], ids=["recursive-list", "recursive-map", "deep", "deep-by-alias", "too-many-values", "undefined-alias"])
def test_yaml_structure_is_bounded(tmp_path, text, fragments):
    started = time.process_time()
    refuse_text(tmp_path, text, *fragments)
    assert time.process_time() - started < 5


@pytest.mark.parametrize(("old", "new", "fragments"), [
    ("title: square", "title: a\ntitle: square", ("title:", "appears twice", "lines 9 and 10")),
    ("  nu: 0.3\n", "  nu: 0.3\n  nu: 0.2\n", ("material.nu", "appears twice")),
    ("  left: clamped\n", "  left: clamped\n  left: free\n", ("boundary.left", "appears twice")),
    ("  E: 1.0e6\n", "  E: 1.0e6\n  0x10: 1\n  16: 2\n", ("material.16", "appears twice")),
], ids=["top", "material", "boundary-part", "same-number-two-spellings"])
def test_repeated_keys_are_refused(tmp_path, old, new, fragments):
    refuse_text(tmp_path, substitute(old, new), *fragments)


def test_merge_keys_and_anchors_stay_allowed(tmp_path):
    text = substitute("  E: 1.0e6\n  nu: 0.3\n", "  <<: {E: 1.0e6, nu: 0.2}\n  nu: 0.3\n")
    text = text.replace('  top: {traction: [1.0e4, "-1e4*(1-1.5*x)"]}',
                        '  top: &load {traction: [1.0e4, "-1e4*(1-1.5*x)"]}').replace("  right: free", "  right: *load")
    case = parse_case(text, source="anchors.yaml")
    assert case.material.poisson == 0.3
    assert case.part("right").kind == "traction"
    solves(tmp_path, text)


@pytest.mark.parametrize(("content", "fragments"), [
    (SQUARE_TEXT + "---\ntitle: second\n", ("more than one YAML document", "line 31")),
    (substitute("  E: 1.0e6", "\tE: 1.0e6"), ("line 16", "a tab")),
    (("\ufeff" + SQUARE_TEXT).encode("utf-16-le"), ("UTF-16",)),
    (("\ufeff" + SQUARE_TEXT).encode("utf-32"), ("UTF-32",)),
    (SQUARE_TEXT.encode().replace(b"square on", b"squ\xe4re on"), ("byte 0xe4", "line 9", "not UTF-8")),
    (SQUARE_TEXT.encode() + b"\xff\xfe", ("byte 0xff", "not UTF-8")),
    (substitute("title: square", "title: \x00square"), ("U+0000", "line 9")),
    (substitute("title: square", "title: \x1b[31msquare"), ("U+001B", "line 9")),
    ("", ("empty",)),
    ("# nothing but a comment\n\n", ("empty",)),
    ("---\n...\n", ("empty",)),
    ("- geometry\n- material\n", ("expected a mapping",)),
    ("just a sentence\n", ("'just a sentence'", "expected a mapping")),
    ("title: [1, 2\n", ("not valid YAML", "line 2")),
    (SQUARE_TEXT + "? [1, 2]\n: x\n", ("unhashable key",)),
    (SQUARE_TEXT + "k" * 5000 + ": 1\n", ("not valid YAML",)),
    (substitute("title: square", 'title: "\\ud800square"'), ("invalid Unicode",)),
    (substitute("title: square", "title: sq\u2028uare"), ("not valid YAML",)),
    (substitute("  E: 1.0e6", "  E: !!python/object/apply:os.system [echo]"), ("material", "constructor")),
    (substitute("  E: 1.0e6", "  E: !custom 1.0e6"), ("constructor", "!custom")),
], ids=["two-documents", "tab", "utf-16", "utf-32", "latin-1", "stray-bytes", "nul", "escape-char", "empty",
        "comment-only", "empty-document", "list", "scalar", "unclosed", "list-key", "5000-char-key",
        "surrogate-escape", "line-separator", "python-tag", "unknown-tag"])
def test_malformed_files(tmp_path, content, fragments):
    refuse_text(tmp_path, content, *fragments)


def test_a_leading_bom_is_accepted(tmp_path):
    solves(tmp_path, "\ufeff" + SQUARE_TEXT)


# --------------------------------------------------------------------------- keys and values


@pytest.mark.parametrize(("old", "new", "fragments"), [
    ("  E: 1.0e6", "  E: .inf", ("material.E = inf", "finite")),
    ("  E: 1.0e6", "  E: -.inf", ("material.E = -inf", "finite")),
    ("  E: 1.0e6", "  E: .nan", ("material.E = nan", "finite")),
    ("  E: 1.0e6", "  E: 1e400", ("material.E", "finite")),
    ("  E: 1.0e6", "  E: 1.0e400", ("material.E = inf", "finite")),
    ("  E: 1.0e6", "  E: 1.0e-400", ("material.E = 0.0", "> 0")),
    ("  E: 1.0e6", "  E: 0x" + "f" * 500, ("material.E = 0xfff", "integer of 502 characters")),
    ("  E: 1.0e6", "  E: " + "9" * 5000, ("material.E", "integer of 5000 characters")),
    ("  E: 1.0e6", "  E: yes", ("material.E = True", "expected a number")),
    ("  nu: 0.3", "  nu: off", ("material.nu = False", "expected a number")),
    ("divisions: 4", "divisions: true", ("mesh.divisions = True", "integer")),
    ("  method: positive", "  method: positive\n  max_iterations: 1.0e1", ("solver.max_iterations", "integer")),
    ("  E: 1.0e6", "  E: 2001-12-14", ("material.E = 2001-12-14", "expected a number")),
    ("  E: 1.0e6", "  E: !!binary aGVsbG8=", ("material.E = b'hello'", "expected a number")),
    ("  E: 1.0e6", "  E: [1.0e6]", ("material.E", "expected a number")),
    ("  E: 1.0e6", "  E: 1.0e6\n  1: x", ("material.1", "unknown key")),
    ("  E: 1.0e6", "  E: 1.0e6\n  ~: x", ("material.None", "unknown key")),
    ("material:", "mat\u200berial:", ("mat\\u200berial", "unknown key")),
    ("material:", "matеrial:", ("matеrial", "unknown key")),  # a Cyrillic e
    ("title: square", "title: \u202esquare", ("title", "printable")),
    ("title: square on a foundation with partial contact", 'title: "\\e[31mred"', ("title", "printable")),
    ("title: square on a foundation with partial contact", 'title: "two\\nlines"', ("title", "printable")),
    ("title: square on a foundation with partial contact", "title: " + "t" * 300, ("title", "200")),
    ("  rectangle: {lower: [0, 0], upper: [1, 1]}",
     '  rectangle: {lower: [0, 0], upper: [1, 1], names: {bottom: "a\\nb"}}',
     ("geometry.rectangle.names.bottom", "printable")),
    ("  left: clamped", "  left: clamped\n  1: free", ("boundary", "part names must be strings")),
], ids=["inf", "-inf", "nan", "1e400-string", "1e400-float", "underflow", "long-hex", "long-decimal",
        "bool-yes", "bool-off", "bool-divisions", "float-iterations", "date", "binary", "list", "int-key",
        "null-key", "zero-width-key", "homoglyph-key", "rtl-title", "escape-title", "newline-title", "long-title",
        "newline-name", "int-part-name"])
def test_odd_values_and_keys(tmp_path, old, new, fragments):
    refuse_text(tmp_path, substitute(old, new), *fragments)


@pytest.mark.parametrize("value", ["0x10", "020", "1_6", "16.0e0"], ids=["hex", "octal", "underscore", "float"])
def test_other_number_spellings_are_read(tmp_path, value):
    text = substitute("  E: 1.0e6", f"  E: {value}")
    assert parse_case(text, source="numbers.yaml").material.young == 16.0


# --------------------------------------------------------------------------- paths in the case


def output_case(tmp_path: Path, directory: str) -> Path:
    return write(tmp_path, substitute("  directory: results/square", f"  directory: {directory}"))


@pytest.mark.parametrize(("directory", "fragments"), [
    ("a" * 300, ("output.directory", "component of 300 bytes")),
    ("a" * (NAME_MAX - 10), ("output.directory", "kept for the names")),
    ("a/" * 2_500, ("output.directory", "5000 bytes long")),
    ('"res\\0ults"', ("output.directory = 'res\\x00ults'", "NUL")),
    ('"\\ud800"', ("line 30", "invalid Unicode")),
], ids=["300", "no-room-for-staging", "5000", "nul", "surrogate"])
def test_output_directory_paths(tmp_path, monkeypatch, directory, fragments):
    """Without --out: the case's own directory, relative to the working directory."""
    monkeypatch.chdir(tmp_path)
    case = output_case(tmp_path, directory)
    assert_one_line(invoke("solve", case, "--quiet"), CASE_NAME, *fragments)
    assert sorted(p.name for p in tmp_path.iterdir()) == [CASE_NAME]


def test_the_default_output_directory_of_a_long_case_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    name = "c" * (NAME_MAX - len(".yaml")) + ".yaml"
    path = write(tmp_path, SQUARE_TEXT.replace("  directory: results/square\n", "  files: [vtu, h5, json]\n"), name)
    assert_one_line(invoke("solve", path, "--quiet"), "output.directory", "the default")
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def mesh_file_case(tmp_path: Path, spec: str) -> Path:
    text = substitute("  rectangle: {lower: [0, 0], upper: [1, 1]}", f"  mesh_file: {spec}")
    return write(tmp_path, text.replace("  divisions: 4", "  refine: 0"))


@pytest.mark.parametrize(("spec", "fragments"), [
    ("a" * 300 + ".msh", ("component of 304 bytes",)),
    ("a/" * 2_500 + "m.msh", ("bytes long",)),
    ('"a\\0.msh"', ("NUL",)),
    ("/dev/zero", ("not a regular file",)),
    ("fifo.msh", ("not a regular file",)),
    (".", ("is a directory",)),
], ids=["300", "5000", "nul", "dev-zero", "fifo", "directory"])
def test_mesh_file_paths(tmp_path, spec, fragments):
    if spec == "fifo.msh":
        if not hasattr(os, "mkfifo"):
            pytest.skip("no FIFOs here")
        os.mkfifo(tmp_path / spec)
    if spec == "/dev/zero" and not os.path.exists(spec):
        pytest.skip("no /dev/zero")
    refuse_file(mesh_file_case(tmp_path, spec), CASE_NAME, "geometry.mesh_file", *fragments)


# --------------------------------------------------------------------------- expressions

MANUFACTURED = (ROOT / "cases" / "manufactured.yaml").read_text(encoding="utf-8")


def exact_case(ux: str, uy: str = "0") -> str:
    data = yaml.safe_load(MANUFACTURED)
    data["mesh"] = {"divisions": [4, 2]}
    data["exact"]["displacement"] = [ux, uy]
    return yaml.safe_dump(data, sort_keys=False)


def balanced(items: list[str], op: str) -> str:
    while len(items) > 1:
        items = [f"({a}{op}{b})" for a, b in zip(items[::2], items[1::2])] + (items[-1:] if len(items) % 2 else [])
    return items[0]


@pytest.mark.parametrize(("ux", "fragments"), [
    ("x % 0", ("modulo by zero",)),
    ("x % (y-y)", ("modulo by zero",)),
    ("1 % 0 * x", ("modulo by zero",)),
    ("0/0", ("not finite",)),
    ("(0/0)*x", ("not finite",)),
    ("0**-1", ("not finite",)),
    ("1/0*x", ("not finite",)),
    ("log(0)*x", ("not finite",)),
    ("x**(0**-1)", ("not finite",)),
    ("10**400*x", ("outside the range of float64",)),
    ("2**-1100*x", ("outside the range of float64",)),
    ("9**9**9*x", ("outside the range of float64",)),
    ("sqrt(-1)*x", ("not a real number",)),
    ("(" * 60 + "x" + ")" * 60, ("nested too deeply",)),
    ("x" + "+x" * 600, ("too long",)),
    ("-" * 80 + "x", ("nested too deeply",)),
    (balanced([f"sin({i}*x*y)" for i in range(1, 40)], "*"), ("gradient", "simpler")),
    ("floor(x)", ("cannot be differentiated",)),
    ("1e-3*x*y", ("frictionless",)),
], ids=["mod-zero", "mod-simplified-zero", "mod-number", "zero-over-zero", "nan-times-x", "zero-to-minus-one",
        "one-over-zero", "log-zero", "power-of-zoo", "huge-number", "tiny-number", "power-tower", "imaginary",
        "deep", "long", "many-signs", "big-gradient", "floor", "sliding"])
def test_exact_block_corner_cases(tmp_path, ux, fragments):
    started = time.process_time()
    refuse_text(tmp_path, exact_case(ux), "exact", *fragments)
    assert time.process_time() - started < 5


def test_a_tower_of_exponentials_in_both_components_is_refused_before_deriving(tmp_path):
    tower = "exp(" * 45 + "x*y" + ")" * 45
    started = time.process_time()
    refuse_text(tmp_path, exact_case(tower, tower), "exact.displacement", "gradient")
    assert time.process_time() - started < 5


@pytest.mark.parametrize(("ux", "fragments"), [
    ("acos(2)*x", ("not finite",)),
    ("x**1e300", ("not finite",)),
    ("x**-1", ("not finite",)),
    ("arctan2(0,0)*x", ("not finite",)),
    ("(-8)**(1/3)*x", ("not finite",)),
], ids=["acos-2", "huge-exponent", "pole-on-mesh", "atan2-origin", "negative-cube-root"])
def test_exact_fields_that_are_not_finite_are_refused_with_the_key(tmp_path, ux, fragments):
    line = refuse_text(tmp_path, exact_case(ux), *fragments)
    assert "exact" in line


@pytest.mark.parametrize("text", ["x % 0", "0/0", "0**-1", "1/(x-x)", "1e308*1e308", "exp(1000)"])
def test_load_expressions_that_are_not_finite(tmp_path, text):
    refuse_text(tmp_path, square(boundary={"left": "clamped", "top": {"traction": [0, text]}, "bottom": "contact"}),
                "boundary.top.traction", "not finite")


# --------------------------------------------------------------------------- geometry


def polygon_case(holes: list | None = None, vertices: list | None = None, edges: list | None = None) -> str:
    vertices = vertices if vertices is not None else [[0, 0], [1, 0], [1, 1], [0, 1]]
    edges = edges if edges is not None else ["bottom", "right", "top", "left"]
    polygon = {"vertices": vertices, "edges": edges}
    if holes is not None:
        polygon["holes"] = holes
    return square(geometry={"polygon": polygon}, mesh={"size": 0.25})


@pytest.mark.parametrize("radius", [1e-300, 1e-12, 1e-8, 1e-7])
def test_a_tiny_circular_hole_names_the_key(tmp_path, radius):
    holes = [{"circle": {"center": [0.5, 0.5], "radius": radius}}]
    refuse_text(tmp_path, polygon_case(holes), "geometry.polygon.holes[0].circle.radius", "must be at least")


def test_a_small_hole_above_the_bound_solves(tmp_path):
    solves(tmp_path, polygon_case([{"circle": {"center": [0.5, 0.5], "radius": 1e-5}}]))


def test_a_tiny_circular_hole_far_from_the_origin(tmp_path):
    vertices = [[1e6, 0], [1e6 + 1, 0], [1e6 + 1, 1], [1e6, 1]]
    holes = [{"circle": {"center": [1e6 + 0.5, 0.5], "radius": 1e-4}}]
    refuse_text(tmp_path, polygon_case(holes, vertices), "holes[0].circle.radius", "1e-6 of the centre")


def test_a_tiny_polygonal_hole_names_the_key(tmp_path):
    holes = [{"vertices": [[0.5, 0.5], [0.5 + 1e-8, 0.5], [0.5, 0.5 + 1e-8]], "edges": ["h", "h", "h"]}]
    refuse_text(tmp_path, polygon_case(holes), "geometry.polygon.holes[0].vertices", "across")


def test_an_arc_loop_of_two_equal_vertices_names_the_key(tmp_path):
    vertices = [[1, 0], [1, 0]]
    edges = [{"name": "rim", "arc": {"center": [0, 0]}}, {"name": "rim", "arc": {"center": [0, 0]}}]
    refuse_text(tmp_path, polygon_case(None, vertices, edges), "geometry.polygon.vertices", "too small")


# An inline polygon cannot reach MAX_POLYGON_VERTICES (a million: the YAML bounds come first;
# a profile file can, see tests/test_rough.py): the checks are run against a lower bound.
INLINE_LIMIT = 2000


def test_too_many_polygon_vertices(tmp_path, monkeypatch):
    monkeypatch.setattr("contactfem.case.limits.MAX_POLYGON_VERTICES", INLINE_LIMIT)
    n = INLINE_LIMIT + 1
    vertices = [[i, 0] for i in range(n)]
    started = time.process_time()
    refuse_text(tmp_path, polygon_case(None, vertices, ["e"] * n), "geometry.polygon.vertices",
                f"at most {INLINE_LIMIT}")
    assert time.process_time() - started < 5
    assert MAX_POLYGON_VERTICES >= 100_000


def test_too_many_holes(tmp_path, monkeypatch):
    monkeypatch.setattr("contactfem.case.limits.MAX_POLYGON_VERTICES", INLINE_LIMIT)
    holes = [{"circle": {"center": [0.02 + 0.04 * (i % 25), 0.02 + 0.04 * (i // 25)], "radius": 0.01}}
             for i in range(INLINE_LIMIT // 4 + 1)]
    refuse_text(tmp_path, polygon_case(holes), "geometry.polygon.holes[", f"more than {INLINE_LIMIT}")


def test_the_limits_are_what_the_documentation_says():
    assert MAX_CASE_BYTES == 1 << 20
    assert PATH_MAX >= 256 and NAME_MAX >= 14


# --------------------------------------------------------------------- hostile options and states


def _square(tmp_path, **changes) -> Path:
    data = yaml.safe_load(SQUARE_TEXT)
    data.update(changes)
    path = tmp_path / CASE_NAME
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


@pytest.mark.parametrize("option, value", [("--theta", "nan"), ("--theta", "inf"), ("--target", "inf"),
                                           ("--target", "nan"), ("--max-seconds", "nan"),
                                           ("--max-seconds", "-inf"), ("--max-unknowns", "1e9")])
def test_adapt_refuses_non_finite_budgets(tmp_path, option, value):
    out = tmp_path / "out"
    assert_one_line(invoke("adapt", _square(tmp_path), option, value, "--out", out), option)
    assert not out.exists()


@pytest.mark.parametrize("command", ["solve", "check", "compare", "converge", "adapt"])
def test_a_backend_that_is_not_installed_is_bad_input_for_every_command(tmp_path, command):
    from contactfem.linalg import BACKEND_NAMES, available_backends

    missing = [name for name in BACKEND_NAMES if name not in available_backends()]
    if not missing:
        pytest.skip("every backend is installed here")
    path = _square(tmp_path, solver={"backend": missing[0]})
    extra = () if command == "check" else ("--out", tmp_path / "out")
    assert_one_line(invoke(command, path, *extra), CASE_NAME, "solver.backend", missing[0], "not installed")
    assert not (tmp_path / "out").exists()


def test_converge_on_an_unloaded_body_reports_undefined_rates_as_null(tmp_path):
    """u = 0 on every mesh: every error is zero and no rate exists; the study says so (null)
    instead of writing NaN or failing."""
    import json

    data = yaml.safe_load(SQUARE_TEXT)
    data["boundary"]["top"] = "free"
    path = tmp_path / CASE_NAME
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    out = tmp_path / "out"
    result = invoke("converge", path, "--levels", "2", "--out", out, "--quiet")
    assert result.exit_code == 0, result.stderr
    study = json.loads((out / "convergence.json").read_text(encoding="utf-8"))
    assert all(rate is None for rates in study["rates"].values() for values in rates.values() for rate in values)


@pytest.mark.parametrize("content, problem", [(b"", "is empty"), (b"garbage", "is not an HDF5 file"),
                                              (b"\x89HDF\r\n\x1a\n" + b"\x00" * 64, "cannot be read as HDF5")])
def test_plot_on_a_corrupt_archive_is_one_line(tmp_path, content, problem):
    """A damaged archive is bad input: exit 2 (tests/test_damaged_archives.py has many more)."""
    (tmp_path / "solution.h5").write_bytes(content)
    assert_one_line(invoke("plot", tmp_path), f"solution.h5: {problem}", code=2)
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["solution.h5"]


def test_an_option_on_the_wrong_command_is_one_line(tmp_path):
    assert_one_line(invoke("check", _square(tmp_path), "--overwrite"), "--overwrite")
    assert_one_line(invoke("solve"), "CASE")
    assert_one_line(invoke("nonsense"), "nonsense")


SLIVER = """
geometry:
  polygon:
    vertices: [[0, 0], [1, 0], [0.5, 1.0e-8]]
    edges: [bottom, right, left]
mesh: {size: 0.05}
material: {E: 1.0e6, nu: 0.3}
boundary: {bottom: contact, left: clamped, right: {traction: [0, -1]}}
obstacle: {point: [0, 0], normal: [0, -1]}
"""


def a_machine_of(monkeypatch, memory: int) -> None:
    """This process as on a machine of ``memory`` bytes, with no cgroup or address-space limit
    (whatever limits the test runner has)."""
    import contactfem.estimate as estimate

    monkeypatch.setattr(estimate, "machine_memory", lambda: memory)
    monkeypatch.setattr(estimate, "_cgroup_limit", lambda proc, cgroups: None)
    monkeypatch.setattr(estimate, "_address_space_limit", lambda: None)


def test_a_sliver_that_needs_far_more_triangles_than_its_size_says_is_refused_within_memory(tmp_path, monkeypatch):
    """A triangle 1e-8 high: its size says about a thousand triangles, a 30-degree quality mesh
    needs millions. Triangle is capped at what the machine can solve (here a 1 GiB machine),
    and the case is refused in one line naming the key."""
    a_machine_of(monkeypatch, 2**30)
    path = tmp_path / CASE_NAME
    path.write_text(SLIVER, encoding="utf-8")
    assert_one_line(invoke("check", path), CASE_NAME, "geometry.polygon", "feature far smaller than the mesh size")


@pytest.mark.parametrize("refine", [3, 4, 5, 6, 7])
def test_the_size_guard_and_the_printed_estimate_are_one_model(tmp_path, monkeypatch, refine):
    """check refuses exactly the meshes whose estimated peak memory (the figure it prints for
    the others) exceeds the machine's memory with the backend auto takes for them (amg
    where a factorisation would not fit); here a machine of 4 GiB."""
    import json

    memory = 4 * 2**30
    a_machine_of(monkeypatch, memory)
    path = tmp_path / CASE_NAME
    path.write_text(SQUARE_TEXT.replace("divisions: 4", "divisions: 32"), encoding="utf-8")
    result = invoke("check", path, "--refine", refine, "--json")
    from contactfem.estimate import GUARD_SHARE, MemoryLimit, choose_backend, estimate_cost

    unknowns = 2 * 32 * 32 * 4**refine
    backend = choose_backend(unknowns, "auto", MemoryLimit(memory, "a machine of 4 GiB")).name
    expected = estimate_cost(unknowns, backend)["bytes"]
    if expected > GUARD_SHARE * memory:
        assert_one_line(result, CASE_NAME, "GiB", "more than this machine's 4 GiB allows (80% of it")
    else:
        assert result.exit_code == 0, result.stderr
        estimate = json.loads(result.stdout)["estimate"]
        assert estimate["backend"] == backend and estimate["bytes"] == pytest.approx(expected, rel=1e-2)
        assert estimate["bytes"] <= GUARD_SHARE * memory and memory == estimate["limit_bytes"]
        assert estimate["limit"] == "this machine's 4 GiB"


# --------------------------------------------------------------------------- memory limits


def write_lines(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="ascii")
    return path


def test_the_memory_limit_is_the_tightest_of_the_machine_and_its_cgroups(tmp_path, monkeypatch):
    """A batch job's or a container's cgroup limit, v2 (memory.max) or v1
    (memory.limit_in_bytes), on the process's own cgroup or any parent, bounds what a solve
    may use; 'max', v1's 2^63 and unreadable files are no limit."""
    import contactfem.estimate as estimate

    monkeypatch.setattr(estimate, "machine_memory", lambda: 64 * 2**30)
    monkeypatch.setattr(estimate, "_address_space_limit", lambda: None)
    proc, cgroups = tmp_path / "proc", tmp_path / "cgroup"
    # v2: the job's step says max, the job 2 GiB, the root nothing.
    write_lines(proc / "cgroup", "0::/job/step\n")
    write_lines(cgroups / "job" / "memory.max", f"{2 * 2**30}\n")
    write_lines(cgroups / "job" / "step" / "memory.max", "max\n")
    limit = estimate.memory_limit(proc, cgroups)
    assert limit.bytes == 2 * 2**30 and limit.source == "this process's cgroup memory limit of 2 GiB"
    # A tighter step wins; a limit above the machine's memory is the machine's.
    write_lines(cgroups / "job" / "step" / "memory.max", f"{2**30}\n")
    assert estimate.memory_limit(proc, cgroups).bytes == 2**30
    write_lines(cgroups / "job" / "memory.max", f"{128 * 2**30}\n")
    write_lines(cgroups / "job" / "step" / "memory.max", "max\n")
    assert estimate.memory_limit(proc, cgroups).source == "this machine's 64 GiB"
    # v1: the memory controller's hierarchy, unlimited written as 2^63 rounded to a page.
    write_lines(proc / "cgroup", "5:cpu,cpuacct:/other\n4:memory:/slurm/uid_1/job_7\n0::/\n")
    write_lines(cgroups / "memory" / "slurm" / "memory.limit_in_bytes", "9223372036854771712\n")
    write_lines(cgroups / "memory" / "slurm" / "uid_1" / "job_7" / "memory.limit_in_bytes", f"{3 * 2**30}\n")
    assert estimate.memory_limit(proc, cgroups).bytes == 3 * 2**30
    # Inside a container the path seen may not exist below the mount: its root file counts.
    write_lines(proc / "cgroup", "0::/seen/from/outside\n")
    write_lines(cgroups / "memory.max", f"{5 * 2**30}\n")
    assert estimate.memory_limit(proc, cgroups).bytes == 5 * 2**30
    # Nothing readable, or nonsense: the machine's memory.
    for text in ("", "garbage\n", "0::/job/step\n"):
        write_lines(proc / "cgroup", text)
        (cgroups / "memory.max").write_text("banana\n", encoding="ascii")
        (cgroups / "job" / "memory.max").write_text("-1\n", encoding="ascii")
        assert estimate.memory_limit(proc, cgroups).source == "this machine's 64 GiB"
    assert estimate.memory_limit(tmp_path / "no_proc", tmp_path / "no_cgroups").source == "this machine's 64 GiB"


@pytest.mark.parametrize("share, refused", [(0.7, False), (0.9, True), (0.99, True)])
def test_a_load_path_modelled_near_the_memory_is_refused_not_killed(tmp_path, monkeypatch, share, refused):
    """A load path factorises whatever its size (it cannot solve iteratively), so nothing
    but the guard stands between a peak modelled near the machine's memory and the kernel's
    out-of-memory killer. The model errs by up to a quarter: a path modelled above 80% of
    the memory is refused in one line before anything is written, one below it solves."""
    from contactfem.estimate import estimate_cost
    from contactfem.linalg import resolve_backend

    unknowns = 2 * 33 * 33
    memory = int(estimate_cost(unknowns, resolve_backend("auto"))["bytes"] / share)
    a_machine_of(monkeypatch, memory)
    path = tmp_path / CASE_NAME
    path.write_text(SQUARE_TEXT.replace("divisions: 4", "divisions: 32") + "load_path: {steps: 3}\n",
                    encoding="utf-8")
    out = tmp_path / "out"
    result = invoke("solve", path, "--out", out, "--quiet")
    if refused:
        assert_one_line(result, CASE_NAME, "allows (80% of it, the cost model's margin)")
        assert not out.exists()
    else:
        assert result.exit_code == 0, result.stderr


def test_a_cgroup_limit_refuses_a_mesh_the_machine_could_hold(tmp_path, monkeypatch):
    """check and solve refuse, in one line naming the limit, a mesh whose estimated peak
    exceeds the cgroup's limit though not the machine's memory; nothing is written."""
    import contactfem.estimate as estimate

    monkeypatch.setattr(estimate, "machine_memory", lambda: 64 * 2**30)
    monkeypatch.setattr(estimate, "_cgroup_limit", lambda proc, cgroups: 2**30)
    monkeypatch.setattr(estimate, "_address_space_limit", lambda: None)
    path = tmp_path / CASE_NAME
    # 2.1M unknowns: more than 1 GiB whatever the backend, amg included.
    path.write_text(SQUARE_TEXT.replace("divisions: 4", "divisions: 1024"), encoding="utf-8")
    assert_one_line(invoke("check", path), CASE_NAME, "more than this process's cgroup memory limit of 1 GiB")
    out = tmp_path / "out"
    assert_one_line(invoke("solve", path, "--out", out), CASE_NAME, "cgroup memory limit")
    assert not out.exists()


def test_an_address_space_limit_refuses_in_one_line_what_would_crash_the_solve(tmp_path):
    """Under ``ulimit -v`` a solve that does not fit used to die in a library: the square at
    400 x 400 (0.85 GiB estimated) crashed the process (SIGSEGV in CHOLMOD) at 0.6 GiB and
    failed to load VTK with a traceback at 1.2 GiB. The limit less the address space a solve
    maps beyond its peak (libraries, threads) now bounds the estimate: refused with exit
    code 2 in one line, nothing written; the shipped square still solves under it."""
    import resource
    import subprocess
    import sys

    from contactfem.estimate import address_space_overhead

    limit = int(address_space_overhead() + 0.5 * 2**30)

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    def command(*args: object) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "contactfem", *map(str, args)], capture_output=True,
                              text=True, timeout=600, preexec_fn=limited)

    big = tmp_path / "big.yaml"
    big.write_text(SQUARE_TEXT.replace("divisions: 4", "divisions: 400"), encoding="utf-8")
    out = tmp_path / "big_out"
    refused = command("solve", big, "--out", out)
    assert refused.returncode == 2, refused.stderr
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and "big.yaml" in lines[0] and "(ulimit -v)" in lines[0], refused.stderr
    assert not out.exists()
    solved = command("solve", ROOT / "cases" / "square.yaml", "--out", tmp_path / "square", "--quiet")
    assert solved.returncode == 0, solved.stderr
    assert (tmp_path / "square" / "report.json").is_file() and (tmp_path / "square" / "solution.vtu").is_file()


def test_an_adapt_budget_beyond_memory_is_refused_before_anything_starts(tmp_path, monkeypatch):
    """adapt refines its meshes itself (bisection), where the size guard does not look:
    --max-unknowns must fit the memory this process may use. On a machine of 2 GiB, 5
    million unknowns (about 11 GiB estimated) are refused in one line naming the option, the
    limit and the most that fit, and nothing is written."""
    from contactfem.estimate import GUARD_SHARE, estimate_cost
    from contactfem.linalg import resolve_backend

    a_machine_of(monkeypatch, 2 * 2**30)
    out = tmp_path / "out"
    line = assert_one_line(invoke("adapt", ROOT / "cases" / "square.yaml", "--max-unknowns", 5_000_000,
                                  "--out", out), "--max-unknowns 5000000", "more than this machine's 2 GiB")
    fit = int(line.rsplit("at most ", 1)[1].split()[0])
    backend = resolve_backend("auto")
    allowed = GUARD_SHARE * 2 * 2**30  # the guard keeps the cost model's margin
    assert estimate_cost(fit, backend)["bytes"] <= allowed < estimate_cost(fit + 1000, backend)["bytes"]
    assert not out.exists()


def test_a_mesh_past_superlus_32_bit_first_guess_is_refused_before_meshing(tmp_path, monkeypatch):
    """On a machine with room for it, the square at 1 900 x 1 900 (7.2 million unknowns, at
    least 72 million nonzeros) with SuperLU: SciPy's SuperLU cannot take that matrix whatever
    the memory, so the case is refused in one line before meshing; CHOLMOD's is not."""
    from contactfem.linalg import superlu_max_nonzeros

    if superlu_max_nonzeros() is None:
        pytest.skip("this SciPy's SuperLU counts in 64 bits")
    a_machine_of(monkeypatch, 2**40)
    path = tmp_path / CASE_NAME
    text = SQUARE_TEXT.replace("divisions: 4", "divisions: 1900").replace("method: positive", "method: positive\n  backend: superlu")
    assert "backend: superlu" in text
    path.write_text(text, encoding="utf-8")
    line = refuse_file(path, CASE_NAME, "mesh: about 7.22e+06 triangles", "SciPy's SuperLU cannot factorise",
                       "32-bit integer", "solver.backend: cholmod")
    assert "at least 72.2 million nonzeros" in line
    from contactfem.estimate import backend_refusal

    assert backend_refusal(7_220_000, "cholmod") is None and backend_refusal(7_000_000, "superlu") is None
    refused = invoke("adapt", path, "--max-unknowns", "8000000", "--out", tmp_path / "a")
    assert_one_line(refused, "--max-unknowns 8000000", "SciPy's SuperLU cannot factorise")
