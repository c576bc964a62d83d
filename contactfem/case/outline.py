"""Outlines as the case gives them: vertices and edges (straight or arcs), or a CSV file."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.case import limits
from contactfem.case.crossings import CLOCKWISE, polygon_problems
from contactfem.case.files import data_file_lines
from contactfem.case.loops import Arc, Loop, coordinate_span, loop_outline
from contactfem.case.messages import shortened
from contactfem.case.reader import Reader
from contactfem.case.tables import DataLines, checked_numbers, is_number
from contactfem.errors import CaseError, MeshError


OUTLINE_EXPECTED = "lines x, y, part (the part of the edge to the next point; empty: the part above)"


def outline_file(r: Reader, text: Any, key: str, source: Path, limit: int) -> Loop:
    """A closed straight-edged loop from a CSV file: per line a vertex x, y and the part of
    the edge from it to the next vertex (the last to the first), which may be left empty
    after the first line to continue the part above. Either orientation is accepted; the
    loop is returned counter-clockwise (a clockwise file read backwards), and is simple."""
    fkey = f"{key}.file"
    lines = data_file_lines(r, fkey, text, source, f"a CSV file of {OUTLINE_EXPECTED}")
    data = DataLines(r, fkey, text, lines, limit, 2, OUTLINE_EXPECTED)
    # The numbers through loadtxt (C, reading the first two columns of every line); the
    # names, one string per line, by counting delimiters: no split of the whole file.
    texts = [lines[i] for i in data.indices]
    if any("#" in line for line in texts):
        texts = [line.split("#", 1)[0] for line in texts]
    if data.delimiter is None:
        rows = [line.split() for line in texts]
        widths = np.fromiter(map(len, rows), dtype=np.int64, count=len(rows))
        names = [row[2] if len(row) == 3 else "" for row in rows]
    else:
        delimiter = data.delimiter
        widths = np.fromiter((line.count(delimiter) for line in texts), dtype=np.int64, count=len(texts)) + 1
        names = [line.rpartition(delimiter)[2].strip() if width == 3 else ""
                 for line, width in zip(texts, widths.tolist())]
    wrong = np.flatnonzero((widths < 2) | (widths > 3))
    if wrong.size:
        raise r.fail(fkey, text, f"line {data.line_of(int(wrong[0]))} has {int(widths[wrong[0]])} columns; "
                     f"expected {OUTLINE_EXPECTED}")
    try:
        table = np.loadtxt(texts, delimiter=data.delimiter, usecols=(0, 1), ndmin=2, dtype=np.float64)
    except ValueError:
        for row, line in enumerate(texts):
            bad = next((f for f in data.fields(line)[:2] if not is_number(f)), None)
            if bad is not None:
                raise r.fail(fkey, text, f"line {data.line_of(row)}: {shortened(bad, 40)!r} is not a number") from None
        raise r.fail(fkey, text, f"cannot read the numbers; expected {OUTLINE_EXPECTED}") from None
    vertices = checked_numbers(r, fkey, text, table, data)
    names = np.array(names, dtype=object)
    named = np.flatnonzero(names != "")
    if named.size == 0 or named[0] != 0:
        raise r.fail(fkey, text, f"line {data.line_of(0)} names no part; expected {OUTLINE_EXPECTED}")
    for first in np.unique(names[named], return_index=True)[1]:
        row = int(named[first])
        if not r.is_name(names[row]):
            raise r.fail(fkey, text, f"line {data.line_of(row)}: part {shortened(names[row], 40)!r}: expected "
                         f"{r.NAME_EXPECTED}")
    # An empty part continues the last named one above it.
    names = names[named[np.searchsorted(named, np.arange(len(names)), side="right") - 1]]
    problem = polygon_problems(vertices)
    if problem == CLOCKWISE:
        # Edge i of the reversed loop runs from vertex k-1-i to k-2-i: the file's edge k-2-i.
        vertices = vertices[::-1].copy()
        names = names[(len(names) - 2 - np.arange(len(names))) % len(names)]
    elif problem is not None:
        # Vertex i, and edge i from it to the next, are given on data line i.
        located = re.sub(r"(?<=vertex )\d+|(?<=edges )\d+|(?<= and )\d+",
                         lambda m: f"{m[0]} (line {data.line_of(int(m[0]))})", problem)
        raise r.fail(fkey, text, f"the outline is not a simple polygon: {located}")
    check_extent(r, fkey, vertices)
    return Loop(vertices=vertices, edge_names=tuple(names.tolist()))


def _loop(r: Reader, vertices: Any, edges: Any, key: str) -> Loop:
    if not isinstance(vertices, list) or len(vertices) < 2:
        raise r.fail(f"{key}.vertices", vertices, "expected a list of at least 2 points [x, y]")
    if len(vertices) > limits.MAX_POLYGON_VERTICES:
        raise r.fail(f"{key}.vertices", f"<{len(vertices)} vertices>",
                     f"expected at most {limits.MAX_POLYGON_VERTICES} vertices (use a gmsh mesh_file for finer outlines)")
    # A vertex may be null at an end of an arc given by its angles: the arc then places it.
    points = np.array([(np.nan, np.nan) if v is None else r.point(v, f"{key}.vertices[{i}]")
                       for i, v in enumerate(vertices)])
    if not isinstance(edges, list) or len(edges) != len(points):
        raise r.fail(
            f"{key}.edges", edges,
            f"expected a list of {len(points)} edges (one per vertex: edge i runs from vertex i to i+1)",
        )
    names, arcs, by_center = [], [], []
    for i, edge in enumerate(edges):
        ekey = f"{key}.edges[{i}]"
        if isinstance(edge, str):
            names.append(r.name(edge, ekey))
            arcs.append(None)
            continue
        edge = r.mapping(edge, ekey, ("name", "arc"), required=("name",))
        names.append(r.name(edge["name"], f"{ekey}.name"))
        if "arc" not in edge:
            arcs.append(None)
            continue
        arc = r.mapping(edge["arc"], f"{ekey}.arc", ("center", "direction", "radius", "angles"), required=("center",))
        center = r.point(arc["center"], f"{ekey}.arc.center")
        if "radius" in arc or "angles" in arc:
            arcs.append(_arc_by_angles(r, arc, f"{ekey}.arc", center, points, i, key))
            continue
        direction = r.choice(arc.get("direction", "ccw"), f"{ekey}.arc.direction", ("ccw", "cw"))
        arcs.append(Arc(center=center, ccw=direction == "ccw"))
        by_center.append((i, ekey, center))
    missing = np.flatnonzero(np.isnan(points[:, 0]))
    if missing.size:
        raise r.fail(f"{key}.vertices[{missing[0]}]", None,
                     "expected a point [x, y] (null only at an end of an arc given by radius and angles)")
    for i, ekey, center in by_center:
        start, end = points[i], points[(i + 1) % len(points)]
        r0, r1 = np.hypot(*(start - center)), np.hypot(*(end - center))
        if r0 == 0 or abs(r0 - r1) > 1e-9 * max(r0, r1):
            raise r.fail(
                f"{ekey}.arc.center", list(center),
                f"must be equally far from the edge's end points (distances {r0:g} and {r1:g})",
            )
    has_arc = any(a is not None for a in arcs)
    # The straight polygon through the vertices must be simple; with arcs the chords are
    # checked, which catches crossings but leaves bulges to the mesher's own checks.
    if len(points) >= 3 or not has_arc:
        problem = polygon_problems(points)
        if problem is not None and not (has_arc and problem.startswith("zero area")):
            raise r.fail(f"{key}.vertices", points.tolist(), problem)
    # With arcs the vertices may lie on one line (a half-disk's straight side, split by a
    # vertex or not): the arcs give the body its other side, checked on its outline below.
    check_extent(r, f"{key}.vertices", points, one_side=has_arc)
    try:
        loop = Loop(vertices=points, edge_names=tuple(names), edge_arcs=tuple(arcs))
    except MeshError as error:
        raise r.fail(f"{key}.vertices", points.tolist(), str(error)) from None
    if has_arc:
        # The body's extent, not its vertices': a half-disk's straight side split by a vertex
        # has three vertices on one line, and its arc gives it its height.
        check_extent(r, f"{key}.vertices", loop_outline(loop), listed=points)
    return loop


#: How far (relative to the radius) a listed vertex may lie from the end of an arc given by its
#: angles; it is then moved onto the arc.
ARC_END_TOLERANCE = 1e-6


def _arc_by_angles(r: Reader, arc: dict, key: str, center: tuple[float, float], points: np.ndarray,
                   index: int, loop_key: str) -> Arc:
    """An arc given by ``{center, radius, angles: [from, to]}`` (degrees, counter-clockwise when
    to > from): places its end points in ``points`` (vertices ``index`` and ``index + 1``)."""
    for name in ("radius", "angles"):
        if name not in arc:
            raise CaseError(f"{r.filename}: {key}.{name}: missing (an arc by angles needs radius and angles)")
    radius = r.number(arc["radius"], f"{key}.radius", low=1 / limits.SCALE_LIMIT, high=limits.SCALE_LIMIT)
    angles = arc["angles"]
    if not isinstance(angles, list) or len(angles) != 2:
        raise r.fail(f"{key}.angles", angles, "expected [from, to] in degrees (counter-clockwise when to > from)")
    first, last = (r.number(a, f"{key}.angles[{j}]", low=-3600, high=3600) for j, a in enumerate(angles))
    if not 0 < abs(last - first) < 360:
        raise r.fail(f"{key}.angles", angles, "the arc must sweep more than 0 and less than 360 degrees")
    ccw = last > first
    if "direction" in arc and r.choice(arc["direction"], f"{key}.direction", ("ccw", "cw")) != ("ccw" if ccw else "cw"):
        raise r.fail(f"{key}.direction", arc["direction"],
                     f"contradicts the angles {angles} (from < to is ccw); leave direction out")
    k = len(points)
    for j, degrees in ((index, first), ((index + 1) % k, last)):
        # Exact multiples of 90 degrees land exactly on the axes.
        turns = degrees / 90
        if turns == round(turns):
            offset = [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][round(turns) % 4]
        else:
            offset = (math.cos(math.radians(degrees)), math.sin(math.radians(degrees)))
        end = np.array([center[0] + radius * offset[0], center[1] + radius * offset[1]])
        given = points[j]
        if np.isnan(given[0]):
            points[j] = end
        elif np.hypot(*(given - end)) > ARC_END_TOLERANCE * radius:
            raise r.fail(f"{loop_key}.vertices[{j}]", given.tolist(),
                         f"is not the end of the arc of {key} at {degrees:g} degrees, {end.tolist()} (within "
                         f"{ARC_END_TOLERANCE:g} of the radius); write it as null to take the arc's end")
        elif np.hypot(*(given - np.asarray(center))) != radius:
            points[j] = end
    return Arc(center=center, ccw=ccw)


def listed_loop(r: Reader, spec: dict, key: str, source: Path, limit: int) -> Loop:
    """A polygonal loop as the case gives it: ``vertices`` and ``edges``, or an outline ``file``."""
    if "file" in spec:
        for listed in ("vertices", "edges"):
            if listed in spec:
                raise r.fail(f"{key}.{listed}", "...", "not with file: the file lists the vertices and their "
                             "edges' parts")
        return outline_file(r, spec["file"], key, source, limit)
    for listed in ("vertices", "edges"):
        if listed not in spec:
            raise CaseError(f"{r.filename}: {key}.{listed}: missing (a polygon is vertices and edges, or a file)")
    return _loop(r, spec["vertices"], spec["edges"], key)


def check_extent(r: Reader, key: str, points: np.ndarray, listed: np.ndarray | None = None,
                 one_side: bool = False) -> None:
    """The body must be resolvable in float64: both sides of its bounding box at least
    1/limits.SCALE_LIMIT and 1e-9 of its distance from the origin (or the mesh degenerates).

    ``points`` are the body's outline (its arcs' points included), or with ``one_side`` the
    vertices of a loop with arcs, of which only the larger side is checked (they may lie on
    one line); ``listed``, when given, the vertices as the case lists them, which the
    message quotes."""
    span = coordinate_span(points)
    far = float(np.abs(points).max())
    least = max(1.0 / limits.SCALE_LIMIT, 1e-9 * far)
    side = span.max() if one_side or len(points) < 3 and span.max() >= least else span.min()
    if side < least:
        raise r.fail(key, (points if listed is None else listed).tolist(), f"the body's extent {side:.3g} is "
                     f"too small: it must be at least {least:.3g} (1e-50, and 1e-9 of the distance from the origin)")
