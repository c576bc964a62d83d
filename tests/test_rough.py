"""Rough and measured contact surfaces: the profile geometry, the O(k log k) polygon checks
and the meshing of outlines with thousands of edges.

- ``geometry.profile`` from a CSV (two columns, or one with spacing), inline heights or an
  expression becomes the polygon it describes, part names included, and meshes;
- every bad profile is refused in one line naming the file, the key and the value;
- the sweep in ``polygon_problems`` and ``first_crossing`` agrees with the test of every
  pair of edges on thousands of small random (often degenerate) polygons;
- it runs in O(k log k) time and O(k) memory on profiles of 10^5 vertices and on
  outlines of thousands of x-monotone pieces crossing one vertical line;
- the graded boundary points of a 4 000-edge profile cost milliseconds, not seconds.
"""

from __future__ import annotations

import math
import os
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import make_runner

import contactfem.case as case_module
import contactfem.case.geometry as case_geometry
import contactfem.case.limits as case_limits
from contactfem.case import PolygonGeometry, parse_case
from contactfem.cli import main
from contactfem.discretize.meshing import build_mesh, estimate_triangles
from contactfem.errors import CaseError
from contactfem.case.crossings import _first_crossing_by_pairs
from contactfem.case.predicates import segments_intersect as _segments_intersect
from contactfem.mesh.boundary_points import _graded_parameters, _lines_points
from contactfem.mesh.polygon import (
    Loop,
    first_crossing,
    polygon_problems,
    triangulate_domain,
)

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from rough import self_affine_profile

CASE = {
    "geometry": {"profile": {"expression": "1e-3*(1 + sin(40*x))/2", "x": [0, 1], "points": 401, "depth": 0.5}},
    "material": {"E": 1.0e6, "nu": 0.3},
    "boundary": {"top": {"displacement": [0, -1.0e-3]}, "base": "contact"},
    "obstacle": {"point": [0, 0], "normal": [0, -1]},
}


def case_with(tmp_path: Path, profile: dict, csv: str | bytes | None = None, name: str = "surface.csv"):
    base, top = profile.get("name", "base"), profile.get("top", "top")
    data = {**CASE, "geometry": {"profile": profile}, "boundary": {top: {"displacement": [0, -1.0e-3]},
                                                                    base: "contact"}}
    if csv is not None:
        path = tmp_path / name
        path.write_bytes(csv if isinstance(csv, bytes) else csv.encode("utf-8"))
    return parse_case(yaml.safe_dump(data), source=tmp_path / "rough.yaml")


def refused(tmp_path: Path, profile: dict, *fragments: str, csv: str | bytes | None = None) -> str:
    with pytest.raises(CaseError) as error:
        case_with(tmp_path, profile, csv)
    message = str(error.value)
    assert "\n" not in message and message.startswith("rough.yaml: ")
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


# --------------------------------------------------------------------------- the syntax


def test_an_expression_profile_is_the_polygon_it_describes():
    case = parse_case(yaml.safe_dump(CASE), source="rough.yaml")
    geometry = case.geometry
    assert isinstance(geometry, PolygonGeometry) and geometry.holes == ()
    v = geometry.outer.vertices
    assert len(v) == 403
    x = np.linspace(0, 1, 401)
    assert np.array_equal(v[:401, 0], x)
    assert np.allclose(v[:401, 1], 1e-3 * (1 + np.sin(40 * x)) / 2, rtol=0, atol=1e-18)
    assert v[401].tolist() == [1.0, 0.5] and v[402].tolist() == [0.0, 0.5]
    assert geometry.outer.edge_names == ("base",) * 400 + ("right", "top", "left")
    mesh = build_mesh(case)
    assert mesh.part_names == ("base", "right", "top", "left")
    assert len(mesh.nodes_of("base")) == 401  # every profile point is a node, and no more
    assert mesh.triangle_areas().sum() == pytest.approx(0.5 - np.trapezoid(v[:401, 1], x), rel=1e-12)


def test_file_heights_and_expression_give_the_same_body(tmp_path):
    x = np.linspace(0, 2, 201)
    h = 1e-3 * np.cos(7 * x) ** 2
    two = "# a measured profile\nx,h\n" + "\n".join(f"{a!r},{b!r}" for a, b in zip(x.tolist(), h.tolist())) + "\n"
    one = "height\n" + "\n".join(repr(b) for b in h.tolist()) + "\n"
    spaced = "\n".join(f"{a!r}\t{b!r}" for a, b in zip(x.tolist(), h.tolist()))  # tabs, no header, no final newline
    common = {"depth": 0.4, "name": "sole", "sides": "wall", "top": "lid"}
    cases = [
        case_with(tmp_path, {"file": "surface.csv", **common}, two),
        case_with(tmp_path, {"file": "one.csv", "spacing": 0.01, **common}, one, name="one.csv"),
        case_with(tmp_path, {"file": "tabs.csv", **common}, spaced, name="tabs.csv"),
        case_with(tmp_path, {"heights": h.tolist(), "spacing": 0.01, **common}),
        case_with(tmp_path, {"expression": "1e-3*cos(7*x)**2", "x": [0, 2], "points": 201, **common}),
    ]
    reference = cases[0].geometry.outer
    assert reference.edge_names == ("sole",) * 200 + ("wall", "lid", "wall")
    for case in cases[1:]:
        outer = case.geometry.outer
        assert outer.edge_names == reference.edge_names
        assert np.allclose(outer.vertices, reference.vertices, rtol=0, atol=1e-15)


def test_origin_and_direction_place_the_profile_along_any_line(tmp_path):
    angle = math.radians(30)
    d = [math.cos(angle), math.sin(angle)]
    case = case_with(tmp_path, {"heights": [0, 1e-3, 0], "spacing": 0.5, "depth": 0.2, "origin": [1, 2],
                                "direction": [2 * d[0], 2 * d[1]]})
    v = case.geometry.outer.vertices
    n = np.array([-d[1], d[0]])
    expected = np.array([1, 2]) + np.outer([0, 0.5, 1, 1, 0], d) + np.outer([0, 1e-3, 0, 0.2, 0.2], n)
    assert np.allclose(v, expected, rtol=0, atol=1e-15)
    assert polygon_problems(v) is None  # counter-clockwise, the body on the left of the walk


def test_the_shipped_rough_case():
    case = case_module.load_case(ROOT / "cases" / "rough.yaml")
    outline = case.geometry.outer
    assert len(outline.vertices) == 4003 and case.contact_parts == ("base",)
    assert np.ptp(outline.vertices[:4001, 1]) == pytest.approx(1e-3)
    mesh = build_mesh(case)
    assert len(mesh.nodes_of("base")) == 4001
    # The size guard's estimate counts the graded strip along the profile.
    assert mesh.n_triangles <= estimate_triangles(case) <= 2 * mesh.n_triangles


def test_the_size_guard_counts_every_polygon_case_within_half_again():
    """The guard's triangle estimate, taken before meshing from the size field the mesh is
    made with, is within 1.5 times the meshed count on every shipped polygon case and on a
    long strip under a rough profile (8 x 0.5, 8 000 points): from the bounding box's
    square it was 16 times the strip's triangles (a 64-long strip's was refused as needing
    33 GiB), and from a graded band π · extent long, 20 to 50 times a graded block's."""
    from fragmented import long_case

    cases = [case_module.load_case(path) for path in sorted((ROOT / "cases").glob("*.yaml"))]
    cases = [case for case in cases if isinstance(case.geometry, PolygonGeometry)] + [long_case(8000)]
    for case in cases:
        triangles = build_mesh(case).n_triangles
        estimate = estimate_triangles(case)
        assert triangles / 1.5 <= estimate <= 1.5 * triangles, (case.source, estimate, triangles)


# --------------------------------------------------------------------------- refusals


@pytest.mark.parametrize("profile, fragments", [
    ({"x": [0, 1], "points": 10}, ("geometry.profile.depth", "missing")),
    ({"expression": "x", "heights": [0, 1], "depth": 1}, ("geometry.profile", "exactly one of file, heights")),
    ({"expression": "1e-3*x", "x": [0, 1], "points": 10, "depth": 1e-3}, ("geometry.profile.depth", "above the highest")),
    ({"expression": "1e-3*y", "x": [0, 1], "points": 10, "depth": 1}, ("geometry.profile.expression", "in x only")),
    ({"expression": "1/x", "x": [0, 1], "points": 10, "depth": 1}, ("geometry.profile.expression", "at x = 0")),
    ({"expression": "x", "x": [1, 0], "points": 10, "depth": 2}, ("geometry.profile.x", "x0 < x1")),
    ({"expression": "x", "x": [0, 1], "depth": 2}, ("geometry.profile.points", "missing")),
    ({"expression": "x", "x": [0, 1], "points": 1, "depth": 2}, ("geometry.profile.points", "integer in [2,")),
    ({"expression": "x", "x": [0, 1], "points": 10**6, "depth": 2}, ("geometry.profile.points", "999998")),
    ({"expression": "x", "x": [0, 1], "points": 10, "spacing": 1, "depth": 2}, ("geometry.profile.spacing", "not used")),
    ({"heights": [0, 1e-3], "depth": 1}, ("geometry.profile.spacing", "missing")),
    ({"heights": [0, 1e-3], "spacing": 0, "depth": 1}, ("geometry.profile.spacing",)),
    ({"heights": [0, "a"], "spacing": 1, "depth": 1}, ("geometry.profile.heights[1]", "number")),
    ({"heights": [0], "spacing": 1, "depth": 1}, ("geometry.profile.heights", "at least 2")),
    ({"heights": [0, 0], "spacing": 1, "depth": 1, "direction": [0, 0]}, ("geometry.profile.direction", "nonzero")),
    ({"heights": [0, 0], "spacing": 1, "depth": 1, "sides": [1, 2, 3]}, ("geometry.profile.sides",)),
    ({"heights": [0, 0], "spacing": 1e-60, "depth": 1}, ("geometry.profile", "too small")),
    ({"heights": [0, 0], "spacing": 1, "depth": 1, "colour": "red"}, ("geometry.profile.colour", "unknown key")),
    ({"heights": [0, 0], "spacing": 1e-20, "start": 1e6, "depth": 1}, ("geometry.profile", "not a simple polygon")),
])
def test_bad_profiles_are_refused_naming_the_key(tmp_path, profile, fragments):
    refused(tmp_path, profile, *fragments)


@pytest.mark.parametrize("csv, fragments", [
    ("x,h\n0,0\n1,1e-3\n1,0\n", ("line 4", "strictly increasing")),
    ("0,0\n0.5,abc\n1,0\n", ("line 2", "'abc' is not a number")),
    ("0,0\n0.5\n1,0\n", ("line 2", "1 columns; expected 2")),
    ("0,0,0\n1,0,0\n", ("line 1 has 3 columns",)),
    ("0,0\n1,nan\n", ("line 2", "finite")),
    ("0,0\n1,1e999\n", ("line 2", "finite")),
    ("# only a comment\n\n", ("no numbers",)),
    ("x,h\n0,0\n", ("1 data lines", "at least 2")),
    (b"0,0\n1,\xff\n", ("byte 0xff on line 2", "not UTF-8")),
])
def test_bad_profile_files_are_refused_naming_the_line(tmp_path, csv, fragments):
    refused(tmp_path, {"file": "surface.csv", "depth": 1}, "geometry.profile.file = 'surface.csv'", *fragments, csv=csv)


def test_profile_file_paths_and_kinds(tmp_path):
    refused(tmp_path, {"file": "missing.csv", "depth": 1}, "geometry.profile.file", "no such file")
    (tmp_path / "folder").mkdir()
    refused(tmp_path, {"file": "folder", "depth": 1}, "is a directory")
    refused(tmp_path, {"file": "a\x00b.csv", "depth": 1}, "NUL")
    refused(tmp_path, {"file": "x" * 300 + ".csv", "depth": 1}, "bytes per file or directory name")
    refused(tmp_path, {"file": "surface.csv", "spacing": 1, "depth": 1}, "geometry.profile.spacing",
            "this one gives x and h", csv="0,0\n1,0\n")
    refused(tmp_path, {"file": "surface.csv", "depth": 1}, "geometry.profile.spacing", "missing", csv="0\n0\n")
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "pipe.csv")
        refused(tmp_path, {"file": "pipe.csv", "depth": 1}, "not a regular file")  # never blocks on it


def test_profile_files_are_read_within_their_bounds(tmp_path, monkeypatch):
    monkeypatch.setattr(case_limits, "MAX_DATA_FILE_BYTES", 100)
    refused(tmp_path, {"file": "surface.csv", "depth": 1}, "larger than 100 bytes", csv="0,0\n" * 40)
    monkeypatch.setattr(case_limits, "MAX_POLYGON_VERTICES", 12)
    refused(tmp_path, {"file": "surface.csv", "depth": 1}, "11 data lines; expected at most 10",
            csv="".join(f"{i},0\n" for i in range(11)))


def test_a_bad_profile_through_the_cli_is_one_line(tmp_path):
    (tmp_path / "surface.csv").write_text("0,0\n1,x\n")
    data = {**CASE, "geometry": {"profile": {"file": "surface.csv", "depth": 1}}}
    (tmp_path / "rough.yaml").write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(tmp_path / "rough.yaml"), "--out", str(out), "--quiet"])
    assert result.exit_code == 2
    assert result.stderr.count("\n") == 1 and "geometry.profile.file" in result.stderr and "line 2" in result.stderr
    assert not out.exists()


# --------------------------------------------------------------------------- the sweep


def all_pairs(v: np.ndarray) -> list[tuple[int, int]]:
    """Every pair of non-adjacent edges that share a point (the test the sweep replaces)."""
    k = len(v)
    i, j = np.triu_indices(k, 2)
    keep = ~((i == 0) & (j == k - 1))
    i, j = i[keep], j[keep]
    nxt = np.roll(v, -1, axis=0)
    hit = _segments_intersect(v[i], nxt[i], v[j], nxt[j])
    return list(zip(i[hit].tolist(), j[hit].tolist()))


def random_polygon(rng: np.random.Generator) -> np.ndarray:
    """Distinct points of a small integer grid (many collinear and touching cases), in
    random order or sorted by angle (mostly simple), sometimes with two swapped."""
    grid = int(rng.integers(2, 8))
    k = int(rng.integers(3, min(14, grid * grid) + 1))
    cells = rng.choice(grid * grid, size=k, replace=False)
    v = np.column_stack([cells // grid, cells % grid]).astype(float)
    if rng.random() < 0.6:
        c = v.mean(axis=0) + rng.random(2) * 0.01
        v = v[np.argsort(np.arctan2(v[:, 1] - c[1], v[:, 0] - c[0]))]
        if rng.random() < 0.5:
            a, b = rng.integers(0, k, 2)
            v[[a, b]] = v[[b, a]]
    return v * rng.choice([1.0, 0.1, 1e-7, 3e5])


def test_the_sweep_finds_exactly_what_every_pair_finds():
    rng = np.random.default_rng(7)
    verdicts = {"intersect": 0, "simple": 0}
    for _ in range(2000):
        v = random_polygon(rng)
        reason = polygon_problems(v) or "simple"
        if reason.startswith(("repeated", "zero", "fewer")):
            continue
        if reason.startswith("edges"):
            i, j = (int(w) for w in reason.split()[1::2])
            # A pair that really meets; folds of adjacent edges are found before the sweep.
            assert (i, j) in all_pairs(v) or (j - i) % len(v) in (1, len(v) - 1), (v.tolist(), reason)
            verdicts["intersect"] += 1
        else:
            assert all_pairs(v) == [], (v.tolist(), reason)
            verdicts["simple"] += 1
    assert min(verdicts.values()) > 300, verdicts


def random_star(rng: np.random.Generator, center, scale: float, most: int) -> np.ndarray:
    """A star-shaped polygon of 3 to ``most`` - 1 vertices around ``center``, half the time
    rounded to a grid of 1/4 (shared vertices and touching edges with its neighbours)."""
    k = int(rng.integers(3, most))
    angle = np.sort(rng.random(k)) * 2 * np.pi
    r = scale * (1 + rng.random(k))
    p = np.column_stack([center[0] + r * np.cos(angle), center[1] + r * np.sin(angle)])
    return np.round(p * 4) / 4 if rng.random() < 0.5 else p


def test_first_crossing_agrees_with_the_pairs():
    rng = np.random.default_rng(3)
    met = 0
    for _ in range(1000):
        a = random_star(rng, (0, 0), 3, 30)
        b = random_star(rng, rng.random(2) * 8 - 4, rng.random() * 2 + 0.1, 30)
        if polygon_problems(a) or polygon_problems(b):
            continue
        expected = _first_crossing_by_pairs(a, b)
        found = first_crossing(a, b)
        assert (expected is None) == (found is None), (a.tolist(), b.tolist())
        met += found is not None
    assert met > 60


def test_one_sweep_over_many_loops_finds_what_their_pairs_find():
    """first_crossing_among (a body and all its holes in one sweep) meets a pair exactly
    when some pair of the loops meets, and names a pair that does, on thousands of random
    sets of 2 to 6 small stars, half of them on a coarse grid (shared vertices, touching
    edges)."""
    from contactfem.mesh.polygon import first_crossing_among

    rng = np.random.default_rng(11)
    met = 0
    for _ in range(600):
        loops = [random_star(rng, rng.random(2) * 10 - 5, rng.random() * 1.5 + 0.2, 20)
                 for _ in range(int(rng.integers(2, 7)))]
        if any(polygon_problems(loop) for loop in loops):
            continue
        pairs = [(i, j) for j in range(len(loops)) for i in range(j)
                 if _first_crossing_by_pairs(loops[i], loops[j]) is not None]
        found = first_crossing_among(loops)
        assert (found is None) == (not pairs), [loop.tolist() for loop in loops]
        if found is not None:
            _, i, j = found
            assert (i, j) in pairs
            met += 1
    assert met > 100


def test_points_inside_a_polygon_by_sorted_slices_match_every_edge():
    """The even-odd test of each point against only the edges whose y-range holds it gives
    what the test against every edge gives, on random star polygons and points, half of
    them on a grid (points on vertices and edges, horizontal edges)."""
    rng = np.random.default_rng(5)

    def every_edge(polygon, points):
        a, b = polygon, np.roll(polygon, -1, axis=0)
        px, py = points[:, None, 0], points[:, None, 1]
        crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
        return (crosses & (px < x)).sum(axis=1) % 2 == 1

    for trial in range(400):
        k = int(rng.integers(3, 40))
        angle = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = rng.uniform(0.3, 1, k)
        polygon = np.stack([r * np.cos(angle), r * np.sin(angle)], axis=1)
        points = rng.uniform(-1.2, 1.2, (60, 2))
        if trial % 2:
            polygon, points = np.round(polygon * 4) / 4, np.round(points * 4) / 4
        np.testing.assert_array_equal(case_geometry._points_inside(polygon, points), every_edge(polygon, points))


def profile_polygon(points: int) -> np.ndarray:
    x, h = self_affine_profile(points)
    return np.vstack([np.column_stack([x, h]), [[1, 0.5], [0, 0.5]]])


def stacked_teeth(teeth: int) -> np.ndarray:
    """A comb of long horizontal teeth: 2 x-monotone chains per tooth, all crossing the
    vertical line x = 0.5 at once (the sweep's worst case for its ordered list)."""
    y = np.arange(teeth) / teeth
    tooth = np.stack([np.column_stack([np.full(teeth, 0.1), y]), np.column_stack([np.ones(teeth), y + 0.1 / teeth]),
                      np.column_stack([np.ones(teeth), y + 0.4 / teeth]),
                      np.column_stack([np.full(teeth, 0.1), y + 0.5 / teeth])], axis=1).reshape(-1, 2)
    return np.vstack([[[0.0, 1.0], [0.0, -0.01], [0.1, -0.01]], tooth])


def test_the_checks_scale_like_k_log_k():
    small, large = profile_polygon(10_000), profile_polygon(100_000)
    for v in (small, large):
        assert polygon_problems(v) is None  # warm
    times = []
    for v in (small, large):
        started = time.process_time()
        assert polygon_problems(v) is None
        times.append(time.process_time() - started)
    assert times[1] < 1.5, times  # 0.1 s measured; the pairs took 146 s at 16 000
    assert times[1] < 40 * max(times[0], 1e-3), times  # 10x the vertices: about 10x the time, not 100x

    comb = stacked_teeth(5000)
    started = time.process_time()
    assert polygon_problems(comb) is None
    assert time.process_time() - started < 3.0
    broken = comb.copy()
    broken[2000, 1] = broken[2004, 1] + 0.2 / 5000  # a tooth's corner pushed into the next tooth
    assert polygon_problems(broken).startswith("edges ")


def test_the_checks_take_memory_linear_in_the_vertices():
    peaks = []
    for points in (20_000, 80_000):
        v = profile_polygon(points)
        tracemalloc.start()
        assert polygon_problems(v) is None
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    per_vertex = [p / n for p, n in zip(peaks, (20_000, 80_000))]
    assert max(per_vertex) < 2000, per_vertex  # bytes per vertex; all pairs would be k bytes per vertex
    assert per_vertex[1] < 1.5 * per_vertex[0], per_vertex


# --------------------------------------------------------------------------- meshing


def test_graded_points_of_many_edges_match_the_one_edge_rule():
    def size(p: np.ndarray) -> np.ndarray:
        return np.minimum(0.05, 0.002 + 0.2 * np.abs(p[:, 1]))

    start, end = np.array([0.0, 0.0]), np.array([0.3, 0.4])
    t = _graded_parameters(lambda t: start + t[:, None] * (end - start), 0.5, size)
    points, counts = _lines_points(start[None], end[None], 0.05, size)
    assert abs(counts[0] - len(t)) <= 1
    if counts[0] == len(t):
        assert np.allclose(points, start + t[:, None] * (end - start), atol=1e-4)
    # Many short edges at once: one point each, at their starts.
    x = np.linspace(0, 1, 4001)
    starts = np.column_stack([x[:-1], np.zeros(4000)])
    ends = np.column_stack([x[1:], np.zeros(4000)])
    started = time.process_time()
    points, counts = _lines_points(starts, ends, 0.05, size)
    assert time.process_time() - started < 0.2
    assert np.all(counts == 1) and np.array_equal(points, starts)


def test_meshing_a_rough_profile_is_triangle_bound():
    v = profile_polygon(16_000)
    loop = Loop(v, ("base",) * 15_999 + ("right", "top", "left"))
    triangulate_domain(loop, [], max_edge=0.05)  # warm
    started = time.process_time()
    mesh = triangulate_domain(loop, [], max_edge=0.05)
    seconds = time.process_time() - started
    assert len(mesh.nodes_of("base")) == 16_000
    assert seconds < 0.15 * mesh.n_triangles / 1e4 + 0.5, (seconds, mesh.n_triangles)  # measured 0.1 s for 89k


def test_the_case_hash_covers_the_profile_file(tmp_path):
    """report.json's case.sha256 identifies the data solved: a changed CSV changes it, the
    same CSV gives the same hash."""
    from contactfem.case import load_case

    case_text = (
        "geometry:\n  profile: {file: surface.csv, depth: 0.5}\n"
        "material: {E: 1.0e6, nu: 0.3}\n"
        "boundary: {top: {displacement: [0, -1.0e-4]}, base: contact}\n"
        "obstacle: {point: [0, -1.0e-3], normal: [0, -1]}\n"
    )
    (tmp_path / "case.yaml").write_text(case_text, encoding="utf-8")
    (tmp_path / "surface.csv").write_text("0,0\n0.5,1e-4\n1,0\n", encoding="utf-8")
    first = load_case(tmp_path / "case.yaml").digest
    assert load_case(tmp_path / "case.yaml").digest == first
    (tmp_path / "surface.csv").write_text("0,0\n0.5,2e-4\n1,0\n", encoding="utf-8")
    assert load_case(tmp_path / "case.yaml").digest != first


def test_the_benchmark_times_contact_and_linear_solves_in_alternation(tmp_path, monkeypatch):
    """benchmarks/rough.py's record for a small profile: as many linear solves as contact
    solves (the first contact solve before them, the others between), between its floor
    and its cap, the fastest of each and the ratio of their medians, and the solve's
    Newton steps, factorisations and active nodes."""
    import rough

    monkeypatch.setattr(rough, "REPEAT_SECONDS", 1e9)  # as many as the cap allows
    monkeypatch.setattr(rough, "MAX_REPEAT", 4)
    record = rough.measure(300, tmp_path, "positive", repeat=3)
    solves, baselines = record["solve_samples_s"], record["baseline_samples_s"]
    assert len(solves) == len(baselines) == 4
    assert record["solve_s"] == min(solves) and record["baseline_s"] == min(baselines)
    assert record["solve_over_baseline"] == pytest.approx(min(solves) / min(baselines), rel=1e-12)
    assert record["median_solve_over_baseline"] == pytest.approx(np.median(solves) / np.median(baselines),
                                                                 rel=1e-12)
    assert record["newton_steps"] >= 1 and record["factorizations"] >= 1 and record["active_nodes"] > 0
    monkeypatch.setattr(rough, "REPEAT_SECONDS", 0.0)  # a single slow solve: the floor
    assert len(rough.measure(300, tmp_path, "positive", repeat=3)["baseline_samples_s"]) == 3


def test_the_sweep_keeps_each_size_from_its_best_round_with_every_round_s_ratio():
    """benchmarks/rough.py's rounds: a size's record is its run with the lowest ratio, with
    the ratios of every run that measured one and their median; a failed run counts for
    nothing unless every run failed, and then the first failure is the record."""
    import rough

    runs = [{"points": 8, "solve_over_baseline": 3.5, "round": 0}, {"points": 8, "error": "timed out"},
            {"points": 8, "solve_over_baseline": 2.5, "round": 2}, {"points": 8, "solve_over_baseline": 4.0}]
    best = rough.best_of_rounds(runs)
    assert best["round"] == 2 and best["solve_over_baseline"] == 2.5
    assert best["round_ratios"] == [3.5, 2.5, 4.0] and best["round_median_ratio"] == 3.5
    assert "round_ratios" not in runs[2]  # the run's own record is left as it was
    failed = [{"points": 8, "error": "exit code 1"}, {"points": 8, "error": "timed out"}]
    assert rough.best_of_rounds(failed) is failed[0]
    assert rough._median_ratio(best) == "3.5" and rough._median_ratio({"median_solve_over_baseline": 2.94}) == "2.9"


def _patches_by_union_find(abscissa, active, pairs):
    """The zone's intervals the slow, obvious way: union-find over the joined pairs, then
    each group's lowest and highest abscissa (ties: the lower position) and size."""
    parent = list(range(len(active)))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for a, b in pairs:
        if active[a] and active[b]:
            parent[root(a)] = root(b)
    groups = {}
    for i in np.flatnonzero(active):
        groups.setdefault(root(int(i)), []).append(int(i))
    found = []
    for members in groups.values():
        s = [abscissa[i] for i in members]
        found.append((members[int(np.argmin(s))], members[int(np.argmax(s))], len(members)))
    return found


@pytest.mark.parametrize("seed", range(40))
def test_contact_patches_are_the_connected_active_runs(seed):
    """The report's and the pictures' contact intervals (contact_patches, by sorting) are
    union-find's on random zones: nodes in shuffled order, edges given either way round
    and some missing (a ΓC of several parts), repeated abscissae, from no active node to
    all of them."""
    from contactfem.discretize.contact import contact_patches, node_pairs

    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 300))
    along = np.sort(rng.integers(0, m, m)).astype(float) if seed % 3 == 0 else np.sort(rng.random(m))
    mesh_index = rng.permutation(10 * m)[:m]  # contact nodes' mesh indices, in ΓC order
    edges = np.column_stack([mesh_index[:-1], mesh_index[1:]])
    edges = edges[rng.random(len(edges)) > 0.05]
    flip = rng.random(len(edges)) < 0.5
    edges[flip] = edges[flip][:, ::-1]
    edges = np.vstack([edges, [[10 * m + 1, mesh_index[0]]]])  # an edge leaving ΓC's nodes
    active = rng.random(m) < rng.choice([0.0, 0.2, 0.7, 1.0])
    shuffle = rng.permutation(m)  # positions need not follow the abscissa
    nodes, abscissa, active = mesh_index[shuffle], along[shuffle], active[shuffle]
    pairs = node_pairs(nodes, edges)
    first, last, counts = contact_patches(abscissa, active, pairs)
    expected = _patches_by_union_find(abscissa, active, pairs)
    found = [(abscissa[a], abscissa[b], c) for a, b, c in zip(first, last, counts)]
    assert sorted(found) == sorted((abscissa[a], abscissa[b], c) for a, b, c in expected)
    assert all(low <= next_low for (low, _, _), (next_low, _, _) in zip(found, found[1:]))
    assert counts.sum() == active.sum()
    assert np.all(abscissa[first] <= abscissa[last])


def test_contact_zone_of_a_rough_profile_takes_one_sort():
    """A zone of 25 000 intervals over 200 000 contact nodes (alternate runs of 4 active and
    4 inactive nodes): its intervals in one sort, about 20 ms here. A pass over ΓC per
    interval, as the report made them before, takes 44 µs each at this size: 1.1 s."""
    from contactfem.discretize.contact import contact_patches

    m = 200_000
    active = (np.arange(m) // 4) % 2 == 0
    pairs = np.column_stack([np.arange(m - 1), np.arange(1, m)])
    started = time.process_time()
    first, last, counts = contact_patches(np.arange(m, dtype=float), active, pairs)
    elapsed = time.process_time() - started
    assert len(first) == 25_000 and np.all(counts == 4) and np.all(last - first == 3)
    assert np.array_equal(first, np.arange(0, m, 8))
    assert elapsed < 0.5
