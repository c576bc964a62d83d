"""Hostile input, property-based: whatever the case file holds, ``contactfem solve`` either
succeeds or refuses it with exit code 2 and one line naming the file and the key, with no
traceback, no partial output and the existing result directory untouched.

Exit 1 is allowed only for a well-formed case the solver cannot finish (e.g. a fuzzed
solver.max_iterations of 1), and then with one line too.
"""

from __future__ import annotations

import copy
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import make_runner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from contactfem.cli import main

BASE = {
    "title": "fuzz",
    "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1]}},
    "mesh": {"divisions": 4},
    "material": {"E": 1.0e6, "nu": 0.3},
    "boundary": {"left": "clamped", "top": {"traction": [1.0e4, "-1e4*(1-1.5*x)"]},
                 "right": "free", "bottom": "contact"},
    "obstacle": {"point": [0, 0], "normal": [0, -1]},
    "solver": {"method": "positive", "tolerance": 1.0e-10, "max_iterations": 50, "c": "auto"},
    "output": {"files": ["vtu", "h5", "json"]},
}
CASE_NAME = "fuzzed.yaml"
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)




def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


class Results:
    """A result directory solved once; every refused run must leave it byte for byte."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.out = root / "results"
        case = root / "base.yaml"
        case.write_text(yaml.safe_dump(BASE), encoding="utf-8")
        result = make_runner().invoke(main, ["solve", str(case), "--out", str(self.out), "--quiet"])
        assert result.exit_code == 0, result.stderr
        self.before = snapshot(self.out)


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Results:
    return Results(tmp_path_factory.mktemp("fuzz"))


def check(results: Results, text: str | bytes, key: str | tuple[str, ...] | None,
          files: dict[str, bytes] | None = None) -> int:
    """Run ``solve`` on the case ``text`` (or raw bytes) into the existing results with --overwrite;
    a refusal must name ``key`` (or one of them)."""
    with tempfile.TemporaryDirectory(dir=results.root) as tmp:
        case = Path(tmp) / CASE_NAME
        case.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
        for name, data in (files or {}).items():
            (Path(tmp) / name).write_bytes(data)
        fresh = Path(tmp) / "fresh"
        first = make_runner().invoke(main, ["solve", str(case), "--out", str(fresh), "--quiet"])
        assert first.exception is None or isinstance(first.exception, SystemExit), repr(first.exception)
        for stream in (first.stdout, first.stderr):
            assert "Traceback" not in stream and "Warning" not in stream, stream
        if first.exit_code == 0:
            # A valid case: solve it over the existing results too, which must then change together.
            result = make_runner().invoke(main, ["solve", str(case), "--out", str(results.out), "--quiet", "--overwrite"])
            assert result.exit_code == 0, result.stderr
            results.before = snapshot(results.out)
            return 0
        assert first.exit_code in (1, 2), (first.exit_code, first.stderr)
        lines = first.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), first.stderr
        assert not fresh.exists(), "a refused run created its output directory"
        if first.exit_code == 2:
            assert CASE_NAME in lines[0] or "msh" in lines[0], lines[0]
            if key is not None:
                assert any(k in lines[0] for k in ((key,) if isinstance(key, str) else key)), (key, lines[0])
        # The same case over existing results leaves them untouched.
        again = make_runner().invoke(main, ["solve", str(case), "--out", str(results.out), "--quiet", "--overwrite"])
        assert again.exit_code == first.exit_code, (again.exit_code, again.stderr)
        assert snapshot(results.out) == results.before
        assert not list(results.root.glob(".tmp-*"))
        return first.exit_code


# --------------------------------------------------------------------------- strategies

finite = st.floats(allow_nan=False, allow_infinity=False)
hostile_numbers = st.one_of(
    st.integers(min_value=-10**400, max_value=10**400), st.floats(), st.sampled_from(
        [0, -1, 1e-320, 1e308, -1e308, float("nan"), float("inf"), "nan", ".inf", "1e999", "0x10", True]))
scalars = st.one_of(st.none(), st.booleans(), hostile_numbers, st.text(max_size=12),
                    st.sampled_from(["auto", "exact", "clamped", "contact", "free", "x", "__import__('os')"]))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=8)


def paths(data, prefix=()):
    """Every key path of the nested case (dict keys and list indices)."""
    if isinstance(data, dict):
        items = data.items()
    elif isinstance(data, list):
        items = enumerate(data)
    else:
        return
    for key, value in items:
        yield (*prefix, key)
        yield from paths(value, (*prefix, key))


PATHS = sorted(paths(BASE), key=str)


def set_path(data, path, value, delete=False):
    node = data
    for key in path[:-1]:
        node = node[key]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value


def dump(data) -> str:
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


# --------------------------------------------------------------------------- properties


@FUZZ
@given(path=st.sampled_from(PATHS), value=values)
def test_any_value_anywhere(results, path, value):
    data = copy.deepcopy(BASE)
    set_path(data, path, value)
    check(results, dump(data), str(path[0]))


@FUZZ
@given(path=st.sampled_from(PATHS))
def test_any_key_missing(results, path):
    data = copy.deepcopy(BASE)
    set_path(data, path, None, delete=True)
    check(results, dump(data), None)


@FUZZ
@given(text=st.text(max_size=200))
def test_arbitrary_text(results, text):
    check(results, text, None)


tokens = st.sampled_from(["x", "y", "1", "9", "1e308", "0", "pi", "(", ")", "+", "-", "*", "/", "**", "%", ".",
                          ",", "__import__", "'os'", "lambda", ":", "[", "]", "sin", "exp", "log", "where",
                          "__class__", "x<y", "and", "if", "else", "not", "open", "eval", " "])


@FUZZ
@given(parts=st.lists(tokens, min_size=1, max_size=14), where=st.sampled_from(
    [("boundary", "top", "traction", 1), ("body_force", 0), ("boundary", "right", "pressure")]))
def test_expressions(results, parts, where):
    data = copy.deepcopy(BASE)
    text = "".join(parts)
    if where[0] == "body_force":
        data["body_force"] = [0, text]
    elif where[-1] == "pressure":
        data["boundary"]["right"] = {"pressure": text}
    else:
        data["boundary"]["top"]["traction"][1] = text
    check(results, dump(data), where[0])


@pytest.mark.parametrize("text", ["9**9**9*x", "x**(10**10)", "(x+y)**200000"])
def test_expressions_that_would_run_long_in_the_exact_block(results, text):
    data = copy.deepcopy(BASE)
    data["exact"] = {"displacement": [text, "0"]}
    data["boundary"]["top"] = {"traction": "exact"}
    check(results, dump(data), "exact")


small = st.integers(min_value=-2, max_value=3)


@FUZZ
@given(vertices=st.lists(st.lists(small, min_size=2, max_size=2), min_size=0, max_size=6))
def test_degenerate_polygons(results, vertices):
    data = copy.deepcopy(BASE)
    names = ["bottom", "right", "top", "left", "left", "left"][: len(vertices)]
    data["geometry"] = {"polygon": {"vertices": vertices, "edges": names}}
    data["mesh"] = {"size": 0.5}
    check(results, dump(data), "geometry" if len(vertices) < 3 else None)


@FUZZ
@given(lower=st.lists(finite, min_size=2, max_size=2), upper=st.lists(finite, min_size=2, max_size=2),
       divisions=st.integers(min_value=1, max_value=6))
def test_rectangles_of_any_size(results, lower, upper, divisions):
    data = copy.deepcopy(BASE)
    data["geometry"]["rectangle"] = {"lower": lower, "upper": upper}
    data["mesh"] = {"divisions": divisions}
    data["obstacle"]["point"] = [0, lower[1] if math.isfinite(lower[1]) else 0]
    check(results, dump(data), None)


def forbid(monkeypatch, name: str, replacement) -> None:
    """Replace ``name`` in every discretisation module that looks it up (a module or a package)."""
    import importlib
    import pkgutil

    package = importlib.import_module("contactfem.discretize")
    modules = [package]
    if hasattr(package, "__path__"):
        modules += [importlib.import_module(f"{package.__name__}.{info.name}")
                    for info in pkgutil.iter_modules(package.__path__)]
    patched = [m for m in modules if hasattr(m, name)]
    assert patched, f"no discretisation module uses {name}"
    for module in patched:
        monkeypatch.setattr(module, name, replacement)


@pytest.mark.parametrize("mesh", [{"divisions": 100_000}, {"divisions": [100_000, 3_000]}, {"divisions": 64, "refine": 12},
                                  {"size": 1e-5}, {"divisions": 2000, "refine": 4}])
def test_oversized_meshes_are_refused_before_meshing(results, monkeypatch, mesh):
    def no_meshing(*args, **kwargs):
        raise AssertionError("meshing started")

    forbid(monkeypatch, "_mesh_geometry", no_meshing)
    data = copy.deepcopy(BASE)
    data["mesh"] = mesh
    assert check(results, dump(data), "mesh") == 2


def test_an_oversized_refinement_of_a_mesh_file_is_refused_before_refining(results, monkeypatch):
    def no_refinement(*args, **kwargs):
        raise AssertionError("refinement started")

    forbid(monkeypatch, "refine_uniform", no_refinement)
    data = copy.deepcopy(BASE)
    data["geometry"] = {"mesh_file": "square.msh"}
    data["mesh"] = {"refine": 12}
    assert check(results, dump(data), "mesh", files={"square.msh": square_msh()}) == 2


def square_msh() -> bytes:
    return (
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n5\n1 1 \"bottom\"\n1 2 \"right\"\n"
        "1 3 \"top\"\n1 4 \"left\"\n2 5 \"body\"\n$EndPhysicalNames\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n"
        "4 0 1 0\n$EndNodes\n$Elements\n6\n1 1 2 1 1 1 2\n2 1 2 2 2 2 3\n3 1 2 3 3 3 4\n4 1 2 4 4 4 1\n"
        "5 2 2 5 5 1 2 3\n6 2 2 5 5 1 3 4\n$EndElements\n"
    ).encode()


def test_the_mesh_file_fixture_is_valid(results):
    data = copy.deepcopy(BASE)
    data["geometry"] = {"mesh_file": "square.msh"}
    data.pop("mesh")
    assert check(results, dump(data), None, files={"square.msh": square_msh()}) == 0


@FUZZ
@given(content=st.one_of(
    st.binary(max_size=300),
    st.integers(min_value=0, max_value=len(square_msh()) - 1).map(lambda n: square_msh()[:n]),
    st.sampled_from([b"<?xml version='1.0'?><VTKFile/>", b"{\"json\": 1}", b"\x89HDF\r\n\x1a\n" + bytes(64),
                     square_msh().replace(b"1 0 0 0", b"1 nan 0 0"), square_msh().replace(b"2 1 0 0", b"2 0 0 0"),
                     square_msh().replace(b"5 2 2 5 5 1 2 3", b"5 2 2 5 5 1 2 9")])))
def test_unreadable_mesh_files(results, content):
    data = copy.deepcopy(BASE)
    data["geometry"] = {"mesh_file": "part.msh"}
    data.pop("mesh")
    check(results, dump(data), None, files={"part.msh": content})


def test_a_mesh_file_that_is_a_directory(results):
    data = copy.deepcopy(BASE)
    data["geometry"] = {"mesh_file": "."}
    data.pop("mesh")
    assert check(results, dump(data), "geometry.mesh_file") == 2


def test_numbers_at_the_edge_of_float64(results):
    for value in (1e308, -1e308, 5e-324, np.nextafter(0.5, 0)):
        data = copy.deepcopy(BASE)
        data["material"]["nu"] = float(value)
        check(results, dump(data), "material")


def test_control_characters_in_keys_stay_on_one_line(tmp_path):
    """Found by the fuzzer: a key holding U+001E (a record separator, which splitlines()
    breaks at) made the refusal two lines. Messages escape such characters."""
    from conftest import CASES, make_runner

    data = yaml.safe_load((CASES / "square.yaml").read_text(encoding="utf-8"))
    data["boundary"]["bottom"] = {"\x1e": None}
    case = tmp_path / "fuzzed.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = make_runner().invoke(main, ["solve", str(case), "--out", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "\\x1e" in lines[0] and "boundary.bottom" in lines[0]


# --------------------------------------------------------------------------- the reader's bounds


def _anchored(width: int, depth: int, leaf: str) -> list[str]:
    """Lines of a chain of anchors, each a list of ``width`` aliases of the one before."""
    lines = [f"a0: &a0 [{', '.join([leaf] * width)}]"]
    lines += [f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * width)}]" for k in range(1, depth)]
    return lines


@FUZZ
@given(width=st.integers(min_value=1, max_value=12), depth=st.integers(min_value=1, max_value=12),
       leaf=st.sampled_from(["lol", "0", "1.0e4", "x", "{a: 1}", "[1, 2]"]),
       use=st.sampled_from(["title", "material: {E", "boundary: {top: {traction", "body_force", "geometry"]))
def test_alias_chains_of_any_size(results, width, depth, leaf, use):
    """Aliases expanding to anything from one value to 12**12: refused in one line, fast."""
    import time

    chain = _anchored(width, depth, leaf)
    last = f"*a{depth - 1}"
    closing = "}" * use.count("{")
    text = dump(BASE).replace("title: fuzz\n", "") + "\n".join(chain) + f"\n{use}: {last}{closing}\n"
    started = time.process_time()
    check(results, text, None)
    assert time.process_time() - started < 10


KEY_LINE = __import__("re").compile(r"^\s*[A-Za-z_][A-Za-z_]*:( |$)")


@FUZZ
@given(line=st.integers(min_value=0, max_value=200), extra=st.sampled_from(["", " 1", " x", " [1, 2]"]))
def test_a_repeated_key_anywhere(results, line, extra):
    """Any key line of the case written twice: refused, naming the key and both lines."""
    lines = dump(BASE).splitlines()
    candidates = [i for i, text in enumerate(lines) if KEY_LINE.match(text)]
    i = candidates[line % len(candidates)]
    key = lines[i].split(":")[0].strip()
    copy_line = lines[i] if lines[i].rstrip().endswith(":") or not extra else lines[i].split(":")[0] + ":" + extra
    text = "\n".join(lines[: i + 1] + [copy_line] + lines[i + 1:]) + "\n"
    assert check(results, text, key) == 2


@FUZZ
@given(position=st.integers(min_value=0, max_value=10_000), data=st.binary(min_size=1, max_size=4),
       prefix=st.sampled_from([b"", b"\xef\xbb\xbf", b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff", b"---\n"]))
def test_bytes_spliced_into_the_file(results, position, data, prefix):
    """Arbitrary bytes (invalid UTF-8, NULs, control characters, BOMs) at any place."""
    raw = dump(BASE).encode("utf-8")
    position %= len(raw) + 1
    check(results, prefix + raw[:position] + data + raw[position:], None)


@FUZZ
@given(value=st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=20),
       where=st.sampled_from(["title", "names", "output", "mesh_file", "part"]))
def test_any_unicode_in_names_and_paths(results, value, where):
    """Control characters, separators, BOMs, direction marks in the strings that end up in files."""
    data = copy.deepcopy(BASE)
    if where == "title":
        data["title"] = value
    elif where == "names":
        data["geometry"]["rectangle"]["names"] = {"top": value}
    elif where == "output":
        data["output"]["directory"] = value
    elif where == "mesh_file":
        data["geometry"] = {"mesh_file": value}
        data.pop("mesh")
    else:
        data["boundary"][value] = "free"
    check(results, dump(data), None)


path_parts = st.sampled_from(["a", "a" * 255, "a" * 256, "b" * 40, ".", "..", "", "\x00", " ", "~", "\\", "é"])


@FUZZ
@given(parts=st.lists(path_parts, min_size=1, max_size=40), repeat=st.integers(min_value=1, max_value=40),
       key=st.sampled_from(["output.directory", "geometry.mesh_file"]))
def test_paths_of_any_length(results, parts, repeat, key):
    """Paths up to ~400 000 characters, overlong components, NULs: one line, no traceback."""
    path = "/".join(parts * repeat)
    data = copy.deepcopy(BASE)
    if key == "output.directory":
        data["output"]["directory"] = path
    else:
        data["geometry"] = {"mesh_file": path}
        data.pop("mesh")
    check(results, dump(data), None)


raw_numbers = st.sampled_from([".inf", "-.inf", ".nan", ".NaN", "1e400", "1.0e400", "-1.0e400", "1.0e-400", "0x10",
                               "0o17", "017", "0b101", "1_2", "+.5", "1:30", "190:20:30", "yes", "no", "on", "~",
                               "null", "2001-12-14", "!!binary aGVsbG8=", "!!float 1", "!!int 3", "!!str 1",
                               "0x" + "f" * 200, "9" * 400, "1" + "0" * 99, "[]", "{}", "'1e6'", '"\\x00"',
                               "&a 1", "!!set {a}", "!!omap [a: 1]", "- 1"])


@FUZZ
@given(value=raw_numbers, target=st.sampled_from(["E: 1000000.0", "nu: 0.3", "divisions: 4", "tolerance: 1.0e-10",
                                                    "max_iterations: 50", "c: auto"]))
def test_raw_yaml_scalars_where_numbers_belong(results, value, target):
    """YAML 1.1's spellings of numbers, booleans, dates and tags, written as they are (not quoted)."""
    text = dump(BASE)
    name = target.split(":")[0]
    check(results, text.replace(target, f"{name}: {value}"), None)


exact_tokens = st.sampled_from(["x", "y", "0", "1", "2", "-1", "1e308", "1e-308", "pi", "(", ")", "+", "-", "*", "/",
                                "**", "%", "sin", "exp", "log", "sqrt", "abs", "where", "atan2", "floor", ",", "<",
                                "0.5", "9**9**9", " "])


@FUZZ
@given(ux=st.lists(exact_tokens, min_size=1, max_size=16), uy=st.lists(exact_tokens, min_size=1, max_size=6))
def test_expressions_in_the_exact_block(results, ux, uy):
    """Modulo by zero, 0/0, 0**-1, huge powers: refused by name or evaluated, never a traceback."""
    data = copy.deepcopy(BASE)
    data["exact"] = {"displacement": ["".join(ux), "".join(uy)]}
    data["boundary"]["top"] = {"traction": "exact"}
    check(results, dump(data), None)


@FUZZ
@given(radius=st.floats(min_value=1e-320, max_value=0.6), cx=st.floats(min_value=-1, max_value=2),
       scale=st.sampled_from([1.0, 1e-6, 1e6, 1e40]))
def test_circular_holes_of_any_size(results, radius, cx, scale):
    """From subnormal to larger than the body: refused naming the hole's key, or solved."""
    data = copy.deepcopy(BASE)
    corners = [[0, 0], [1, 0], [1, 1], [0, 1]]
    data["geometry"] = {"polygon": {
        "vertices": [[scale * a, scale * b] for a, b in corners], "edges": ["bottom", "right", "top", "left"],
        "holes": [{"circle": {"center": [scale * cx, scale * 0.5], "radius": scale * radius}}]}}
    data["mesh"] = {"size": 0.25 * scale}
    data["boundary"]["top"] = "free"
    check(results, dump(data), None)


OUTLINE = b"x,y,part\n0,0,bottom\n0.5,0,\n1,0,right\n1,1,top\n0,1,left\n"


@FUZZ
@given(position=st.integers(min_value=0, max_value=200), data=st.one_of(
    st.binary(min_size=1, max_size=6),
    st.sampled_from([b",", b";", b"\t", b" ", b"\n", b"#", b",,", b"nan", b"1e999", b"-", b"0x1", b"\xff", b"\x00",
                     b"bottom", b",top\n", b"\r\n", b"1,1,x\n", b"0.5,0.5,\n", b"\xef\xbb\xbf"])),
    delete=st.integers(min_value=0, max_value=3))
def test_outline_files_of_any_bytes(results, position, data, delete):
    """An outline file (geometry.polygon.file) with bytes spliced in and some cut out: a
    valid loop solves; anything else is one line naming geometry.polygon.file, or the
    boundary when the file is a valid loop whose part names changed."""
    position %= len(OUTLINE) + 1
    outline = OUTLINE[:position] + data + OUTLINE[position + delete:]
    case = copy.deepcopy(BASE)
    case["geometry"] = {"polygon": {"file": "outline.csv"}}
    case["mesh"] = {"size": 0.5}
    check(results, dump(case), ("geometry.polygon.file", "boundary"), files={"outline.csv": outline})
