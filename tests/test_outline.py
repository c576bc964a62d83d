"""Polygon outlines read from a file: ``geometry.polygon.file`` (and a hole's ``file``).

A digitised outline of 10^5 vertices does not fit a case file (1 MiB, 100 000 YAML
values), so a polygon's loop may come from a CSV of x, y, part, the part naming the edge
from that vertex to the next and an empty part continuing the one above. Checked here:

- the file gives exactly the loop its YAML listing gives (vertices and every edge's part),
  in any delimiter, with a header and comments, and a clockwise file the same loop read
  backwards; a hole from a file cuts the body as a listed hole does;
- a case solved from the file and from the listing gives the same displacement to the
  last bit (the same polygon, the same mesh, the same kernel);
- every bad file is refused in one line naming the key, the file and the line;
- the file is bounded like a profile's and changes the case's hash.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import contactfem.case as case_module
import contactfem.case.limits as case_limits
from contactfem.case import PolygonGeometry, parse_case
from contactfem.discretize.meshing import build_mesh
from contactfem.errors import CaseError
from contactfem.solve import solve_case

ROOT = Path(__file__).resolve().parents[1]


def rough_half_disk(points: int, seed: int = 7) -> tuple[np.ndarray, list[str]]:
    """A half-disk of radius 1 under the line y = 1 whose rim has ``points`` vertices and a
    random radial roughness of 2e-4, largest at the bottom; parts left, rim, right (the
    lower third of the rim is ``rim``) and the straight top. Counter-clockwise."""
    rng = np.random.default_rng(seed)
    theta = np.linspace(np.pi, 2 * np.pi, points)
    t = (theta - np.pi) / np.pi
    radius = 1 + 2e-4 * rng.uniform(0, 1, points) * np.sin(np.pi * t) ** 2
    vertices = np.stack([radius * np.cos(theta), 1 + radius * np.sin(theta)], axis=1)
    vertices[0], vertices[-1] = (-1.0, 1.0), (1.0, 1.0)
    lower, upper = np.searchsorted(t, [1 / 3, 2 / 3])
    parts = ["left"] * lower + ["rim"] * (upper - lower) + ["right"] * (points - 1 - upper) + ["top"]
    return vertices, parts


def outline_csv(vertices: np.ndarray, parts: list[str], delimiter: str = ",", continued: bool = True,
                header: str | None = "x,y,part") -> str:
    """The CSV of a loop: a part only where it changes when ``continued``."""
    lines = [] if header is None else [header]
    for i, ((x, y), part) in enumerate(zip(vertices.tolist(), parts)):
        shown = part if not continued or i == 0 or parts[i - 1] != part else ""
        lines.append(delimiter.join([repr(x), repr(y)] + ([shown] if shown or delimiter != " " else [])))
    return "\n".join(lines) + "\n"


CASE = {
    "material": {"E": 1.0e6, "nu": 0.3},
    "mesh": {"size": 0.2},
    "boundary": {"top": {"displacement": [0, -3.0e-4]}, "rim": "contact", "left": "free", "right": "free"},
    "obstacle": {"point": [0, 0], "normal": [0, -1]},
}


def case_from(tmp_path: Path, polygon: dict, files: dict[str, str | bytes] | None = None, **changes):
    for name, text in (files or {}).items():
        (tmp_path / name).write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    data = {**CASE, "geometry": {"polygon": polygon}, **changes}
    return parse_case(yaml.safe_dump(data), source=tmp_path / "body.yaml")


def refused(tmp_path: Path, polygon: dict, files: dict[str, str | bytes], *fragments: str) -> str:
    with pytest.raises(CaseError) as error:
        case_from(tmp_path, polygon, files)
    message = str(error.value)
    assert "\n" not in message and message.startswith("body.yaml: "), message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


# --------------------------------------------------------------------------- the loop


@pytest.mark.parametrize("delimiter", [",", ";", "\t", " "])
def test_an_outline_file_is_the_loop_its_listing_gives(tmp_path, delimiter):
    vertices, parts = rough_half_disk(301)
    listed = case_from(tmp_path, {"vertices": vertices.tolist(), "edges": parts})
    text = "# digitised rim\n" + outline_csv(vertices, parts, delimiter, header="x y part".replace(" ", delimiter))
    read = case_from(tmp_path, {"file": "rim.csv"}, {"rim.csv": text})
    assert isinstance(read.geometry, PolygonGeometry) and read.geometry.holes == ()
    assert np.array_equal(read.geometry.outer.vertices, listed.geometry.outer.vertices)
    assert read.geometry.outer.edge_names == listed.geometry.outer.edge_names == tuple(parts)
    assert read.contact_parts == ("rim",)


def test_every_line_may_name_its_part_and_comments_are_skipped(tmp_path):
    vertices, parts = rough_half_disk(41)
    text = outline_csv(vertices, parts, continued=False, header=None).replace("\n", "  # measured\n", 3)
    read = case_from(tmp_path, {"file": "rim.csv"}, {"rim.csv": text})
    assert read.geometry.outer.edge_names == tuple(parts)


def test_a_clockwise_outline_is_read_backwards(tmp_path):
    vertices, parts = rough_half_disk(101)
    # The same loop walked clockwise from (1, 1): edge j runs from vertex k-1-j to k-2-j,
    # the counter-clockwise edge k-2-j.
    k = len(vertices)
    backwards = vertices[::-1]
    backward_parts = [parts[(k - 2 - j) % k] for j in range(k)]
    ccw = case_from(tmp_path, {"file": "ccw.csv"}, {"ccw.csv": outline_csv(vertices, parts)})
    cw = case_from(tmp_path, {"file": "cw.csv"}, {"cw.csv": outline_csv(backwards, backward_parts)})
    assert np.array_equal(cw.geometry.outer.vertices, ccw.geometry.outer.vertices)
    assert cw.geometry.outer.edge_names == ccw.geometry.outer.edge_names


def test_a_hole_from_a_file_cuts_the_body_like_a_listed_hole(tmp_path):
    square = {"vertices": [[-1, 0], [1, 0], [1, 1], [-1, 1]], "edges": ["rim", "right", "top", "left"]}
    angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    hole = np.stack([0.2 * np.cos(angles), 0.5 + 0.2 * np.sin(angles)], axis=1)
    names = ["bore"] * 64
    listed = case_from(tmp_path, {**square, "holes": [{"vertices": hole.tolist(), "edges": names}]})
    read = case_from(tmp_path, {**square, "holes": [{"file": "bore.csv"}]}, {"bore.csv": outline_csv(hole, names)})
    assert np.array_equal(read.geometry.holes[0].vertices, listed.geometry.holes[0].vertices)
    assert read.geometry.holes[0].edge_names == listed.geometry.holes[0].edge_names
    mesh = build_mesh(read)
    polygon_area = 0.5 * np.sum(hole[:, 0] * np.roll(hole[:, 1], -1) - hole[:, 1] * np.roll(hole[:, 0], -1))
    assert mesh.triangle_areas().sum() == pytest.approx(2.0 - polygon_area, rel=1e-12)
    assert "bore" in mesh.part_names


def test_a_case_solved_from_the_file_is_the_case_solved_from_the_listing(tmp_path):
    vertices, parts = rough_half_disk(801)
    listed = case_from(tmp_path, {"vertices": vertices.tolist(), "edges": parts})
    read = case_from(tmp_path, {"file": "rim.csv"}, {"rim.csv": outline_csv(vertices, parts)})
    a, b = solve_case(listed), solve_case(read)
    assert a.kernel.certificate.passed and b.kernel.certificate.passed
    assert np.array_equal(a.solution.displacement, b.solution.displacement)
    contact = b.solution.contact
    active = contact.active
    # Pressed 3e-4 onto the plane: the rough bottom touches in a zone around x = 0 only.
    touching = b.problem.mesh.points[contact.nodes[active]]
    assert active.sum() >= 3 and np.abs(touching[:, 0]).max() < 0.1


# --------------------------------------------------------------------------- refusals


GOOD = "x,y,part\n0,0,base\n1,0,\n1,1,top\n0,1,left\n"


@pytest.mark.parametrize("text, fragments", [
    ("0,0\n1,0,base\n1,1,top\n", ("line 1 names no part",)),
    ("0,0,,\n1,0,base\n1,1,top\n", ("line 1 has 4 columns", "x, y, part")),
    ("0,0,base\n1\n1,1,top\n", ("line 2 has 1 columns",)),
    ("0,0,base\n1,abc,\n1,1,top\n", ("line 2", "'abc' is not a number")),
    ("0,0,base\n1,inf,\n1,1,top\n", ("line 2", "finite")),
    ("0,0,base\n1,1,\n1,0,\n0,1,top\n", ("not a simple polygon", "edges 0 (line 1) and 2 (line 3) intersect")),
    ("0,0,base\n1,0,\n1,0,\n0,1,top\n", ("not a simple polygon", "repeated vertex")),
    ("0,0,base\n1,0,\n2,0,top\n", ("not a simple polygon", "zero area")),
    ("0,0,base\n1,0,\n1,1," + "p" * 65 + "\n", ("line 3: part 'ppp", "expected a part name")),
    ("x,y,part\n", ("0 data lines", "at least 2")),
    (b"0,0,base\n1,0,\xff\n", ("byte 0xff on line 2", "not UTF-8")),
])
def test_bad_outline_files_are_refused_naming_the_line(tmp_path, text, fragments):
    refused(tmp_path, {"file": "outline.csv"}, {"outline.csv": text}, "geometry.polygon.file = 'outline.csv'",
            *fragments)


def test_outline_keys_and_paths(tmp_path):
    refused(tmp_path, {"file": "outline.csv", "edges": ["a"]}, {"outline.csv": GOOD}, "geometry.polygon.edges",
            "not with file")
    refused(tmp_path, {"edges": ["a", "b", "c"]}, {}, "geometry.polygon.vertices", "missing")
    refused(tmp_path, {"file": "absent.csv"}, {}, "geometry.polygon.file", "no such file")
    refused(tmp_path, {"file": 3}, {}, "geometry.polygon.file", "expected the path of a CSV file")
    square = {"vertices": [[0, 0], [4, 0], [4, 4], [0, 4]], "edges": ["base", "right", "top", "left"]}
    refused(tmp_path, {**square, "holes": [{"file": "hole.csv", "name": "bore"}]}, {"hole.csv": GOOD},
            "geometry.polygon.holes[0].name", "names each of its edges")
    refused(tmp_path, {**square, "holes": [{"file": "hole.csv"}]},
            {"hole.csv": "3,3,bore\n5,3,\n5,5,\n3,5,\n"}, "geometry.polygon.holes[0]", "meets the body's outer")
    # Two holes that overlap: named by both, before any meshing.
    refused(tmp_path, {**square, "holes": [{"file": "a.csv"}, {"file": "b.csv"}]},
            {"a.csv": "1,1,a\n2,1,\n2,2,\n1,2,\n", "b.csv": "1.5,1.5,b\n2.5,1.5,\n2.5,2.5,\n1.5,2.5,\n"},
            "geometry.polygon.holes[1]", "meets that of holes[0]")
    refused(tmp_path, {**square, "holes": [{"file": "a.csv"}, {"file": "out.csv"}]},
            {"a.csv": "1,1,a\n2,1,\n2,2,\n1,2,\n", "out.csv": "5,5,b\n6,5,\n6,6,\n5,6,\n"},
            "geometry.polygon.holes[1]", "lies outside the body's outer boundary")


def test_outline_files_are_bounded_like_profiles(tmp_path, monkeypatch):
    monkeypatch.setattr(case_limits, "MAX_DATA_FILE_BYTES", 100)
    refused(tmp_path, {"file": "outline.csv"}, {"outline.csv": GOOD * 10}, "larger than 100 bytes")
    # The bound is for all of a case's data files: an outline and a hole within it alone
    # but not together are refused at the hole, before it is read whole.
    outer = "0,0,base\n9,0,right\n9,9,top\n0,9,left\n"
    hole = "4,4,bore\n5,4,\n5,5,\n4,5,\n" + "#" * 40 + "\n"
    assert len(outer) < 100 and len(hole) < 100 < len(outer) + len(hole)
    refused(tmp_path, {"file": "outer.csv", "holes": [{"file": "hole.csv"}]}, {"outer.csv": outer, "hole.csv": hole},
            "geometry.polygon.holes[0].file", f"the {100 - len(outer)} bytes left of the 100 bytes")
    monkeypatch.setattr(case_limits, "MAX_DATA_FILE_BYTES", 1 << 20)
    monkeypatch.setattr(case_limits, "MAX_POLYGON_VERTICES", 10)
    ring = "".join(f"{float(np.cos(a))!r},{float(np.sin(a))!r},{'r' if i == 0 else ''}\n"
                   for i, a in enumerate(np.linspace(0, 2 * np.pi, 11, endpoint=False)))
    refused(tmp_path, {"file": "outline.csv"}, {"outline.csv": ring}, "11 data lines; expected at most 10")
    # The outer loop's vertices count against a hole's.
    square = "0,0,base\n9,0,right\n9,9,top\n0,9,left\n"
    hole = "".join(f"{float(4 + np.cos(a))!r},{float(4 + np.sin(a))!r},{'b' if i == 0 else ''}\n"
                   for i, a in enumerate(np.linspace(0, 2 * np.pi, 7, endpoint=False)))
    refused(tmp_path, {"file": "outer.csv", "holes": [{"file": "hole.csv"}]},
            {"outer.csv": square, "hole.csv": hole}, "geometry.polygon.holes[0].file", "expected at most 6")


def test_the_case_hash_covers_the_outline_file(tmp_path):
    vertices, parts = rough_half_disk(31)
    first = case_from(tmp_path, {"file": "rim.csv"}, {"rim.csv": outline_csv(vertices, parts)})
    vertices[15, 1] -= 1e-5
    second = case_from(tmp_path, {"file": "rim.csv"}, {"rim.csv": outline_csv(vertices, parts)})
    assert first.digest != second.digest


def test_the_shipped_rough_rim_case_is_what_the_benchmark_writes(tmp_path):
    """cases/rough_rim.csv is the benchmark's seeded outline (so the sweep's smallest
    sizes and the shipped case are one family), and the case reads it as that loop."""
    import sys

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from rough import SHIPPED_OUTLINE_POINTS, rim_outline, write_outline

    written = tmp_path / "rim.csv"
    write_outline(written, SHIPPED_OUTLINE_POINTS)
    assert written.read_bytes() == (ROOT / "cases" / "rough_rim.csv").read_bytes()
    case = case_module.load_case(ROOT / "cases" / "rough_rim.yaml")
    vertices, parts = rim_outline(SHIPPED_OUTLINE_POINTS)
    assert np.array_equal(case.geometry.outer.vertices, vertices)
    assert case.geometry.outer.edge_names == tuple(parts) and case.contact_parts == ("rim",)


def test_an_outline_too_long_to_list_points_to_the_file(tmp_path):
    """Listed inline, 40 000 vertices pass the case's bound on YAML values: the refusal says
    where a long outline goes."""
    angles = np.linspace(0, 2 * np.pi, 40_000, endpoint=False)
    vertices = "[" + ",".join(f"[{np.cos(a):.5f},{np.sin(a):.5f}]" for a in angles) + "]"
    text = f"geometry:\n  polygon:\n    vertices: {vertices}\n    edges: [rim]\n"
    with pytest.raises(CaseError) as error:
        parse_case(text, source=tmp_path / "body.yaml")
    message = str(error.value)
    assert "more than 100000 values" in message and "geometry.polygon.file" in message and "\n" not in message


def test_check_says_what_the_body_is_and_where_it_was_read():
    from conftest import make_runner

    from contactfem.cli import main

    runner = make_runner()
    shown = runner.invoke(main, ["check", str(ROOT / "cases" / "rough_rim.yaml")])
    assert shown.exit_code == 0, shown.output
    assert "  geometry   polygon of 2001 vertices (read from rough_rim.csv)\n" in shown.stdout
    figures = json.loads(runner.invoke(main, ["check", str(ROOT / "cases" / "rough_rim.yaml"), "--json"]).stdout)
    figures = figures["geometry"]
    assert figures == {"kind": "polygon", "vertices": 2001, "holes": 0, "arcs": 0,
                       "files": [str(ROOT / "cases" / "rough_rim.csv")]}
    square = runner.invoke(main, ["check", str(ROOT / "cases" / "square.yaml")])
    assert "  geometry   rectangle [0, 1] x [0, 1]\n" in square.stdout


def test_the_case_hash_covers_a_mesh_file(tmp_path):
    """report.json's case.sha256 (and a sweep point's identity) covers every data file the
    case reads, a gmsh mesh file too: the same text over another mesh is another case."""
    from test_fuzz_input import square_msh

    text = ("geometry: {mesh_file: body.msh}\nmaterial: {E: 1.0e6, nu: 0.3}\n"
            "boundary: {left: clamped, bottom: contact}\nobstacle: {point: [0, 0], normal: [0, -1]}\n")
    (tmp_path / "body.msh").write_bytes(square_msh())
    first = parse_case(text, source=tmp_path / "body.yaml")
    assert first.data_files == (tmp_path / "body.msh",)
    assert parse_case(text, source=tmp_path / "body.yaml").digest == first.digest
    (tmp_path / "body.msh").write_bytes(square_msh().replace(b"3 1 1 0", b"3 1 1.5 0"))
    assert parse_case(text, source=tmp_path / "body.yaml").digest != first.digest


def test_every_result_file_names_the_data_files_it_was_solved_from(tmp_path):
    """report.json (as compare.json, convergence.json and adapt.json, through one record)
    lists the data files beside the hash that covers them, and follows its schema."""
    import jsonschema

    from contactfem.cli import main
    from contactfem.report import case_record

    case = case_module.load_case(ROOT / "cases" / "rough_rim.yaml")
    assert case_record(case)["data_files"] == [str(ROOT / "cases" / "rough_rim.csv")]
    from conftest import make_runner

    out = tmp_path / "out"
    assert make_runner().invoke(main, ["solve", str(ROOT / "cases" / "rough_rim.yaml"), "--out", str(out),
                                       "--quiet"]).exit_code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["case"] == {**case_record(case), "file": report["case"]["file"]}
    schema = json.loads((ROOT / "contactfem" / "schemas" / "report.schema.json").read_text())
    jsonschema.validate(report, schema)
    assert case_record(case_module.load_case(ROOT / "cases" / "square.yaml"))["data_files"] == []


def test_a_body_with_many_holes_from_files_is_checked_in_one_sweep(tmp_path):
    """Forty holes read from files in a body whose base has 4 000 vertices: validated
    together (the loops in one sweep, the holes' first points against the outline's edges
    by sorted slices), meshed with every hole, and `check` names three files and counts
    the rest."""
    from conftest import make_runner

    from contactfem.cli import main

    x = np.linspace(0, 4, 4000)
    h = 1e-4 * np.sin(37 * x)
    base = [f"{a!r},{b!r},{'base' if i == 0 else ''}" for i, (a, b) in enumerate(zip(x.tolist(), h.tolist()))]
    base[-1] = f"{float(x[-1])!r},{float(h[-1])!r},right"
    (tmp_path / "outer.csv").write_text("\n".join(base + ["4.0,1.0,top", "0.0,1.0,left"]) + "\n")
    holes = []
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    for i in range(40):
        cx, cy = 0.25 + 0.5 * (i % 8), 0.15 + 0.17 * (i // 8)
        ring = [f"{cx + 0.05 * math.cos(a)!r},{cy + 0.05 * math.sin(a)!r},{'pore' if j == 0 else ''}"
                for j, a in enumerate(angles.tolist())]
        (tmp_path / f"pore{i}.csv").write_text("\n".join(ring) + "\n")
        holes.append({"file": f"pore{i}.csv"})
    data = {**CASE, "geometry": {"polygon": {"file": "outer.csv", "holes": holes}}, "mesh": {"size": 0.1},
            "boundary": {"top": {"displacement": [0, -1e-4]}, "base": "contact", "left": "free", "right": "free",
                         "pore": "free"}}
    (tmp_path / "porous.yaml").write_text(yaml.safe_dump(data))
    case = case_module.load_case(tmp_path / "porous.yaml")
    assert len(case.geometry.holes) == 40 and len(case.data_files) == 41
    mesh = build_mesh(case)
    pores = 40 * (0.5 * 40 * 0.05**2 * np.sin(2 * np.pi / 40))  # forty regular 40-gons
    body = 4.0 - np.trapezoid(h, x)
    assert mesh.triangle_areas().sum() == pytest.approx(body - pores, rel=1e-9)
    shown = make_runner().invoke(main, ["check", str(tmp_path / "porous.yaml")])
    assert shown.exit_code == 0, shown.output
    assert "polygon of 5602 vertices, 40 holes (read from outer.csv, pore0.csv, pore1.csv, 38 more files)" in shown.stdout
