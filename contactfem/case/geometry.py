"""The ``geometry:`` and ``mesh:`` sections: the body, its holes and how finely to mesh it."""

from __future__ import annotations

import math
import stat
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.case import limits
from contactfem.case.crossings import first_crossing_among
from contactfem.case.files import file_digest, file_mode, path_problem
from contactfem.case.loops import Loop, circle_loop, coordinate_span, loop_outline
from contactfem.case.messages import shortened
from contactfem.case.model import Geometry, MeshFileGeometry, MeshSettings, PolygonGeometry, RectangleGeometry
from contactfem.case.outline import check_extent, listed_loop
from contactfem.case.profile import profile_geometry
from contactfem.case.reader import Reader
from contactfem.errors import MeshError


DIAGONALS = ("right", "left", "alternate", "crossed")
SIDES = ("bottom", "right", "top", "left")


def read_geometry(r: Reader, data: Any, source: Path) -> tuple[Geometry, tuple[str, ...] | None]:
    """The geometry and the part names it defines (None when only the mesh file knows them)."""
    kinds = ("rectangle", "polygon", "profile", "mesh_file")
    data = r.mapping(data, "geometry", kinds)
    if len(data) != 1:
        raise r.fail("geometry", data, f"expected exactly one of {', '.join(kinds)}")
    (kind, spec), = data.items()
    key = f"geometry.{kind}"
    if kind == "rectangle":
        spec = r.mapping(spec, key, ("lower", "upper", "names"), required=("lower", "upper"))
        lower = r.point(spec["lower"], f"{key}.lower")
        upper = r.point(spec["upper"], f"{key}.upper")
        if not (upper[0] > lower[0] and upper[1] > lower[1]):
            raise r.fail(f"{key}.upper", list(upper), f"must lie above and right of lower {list(lower)}")
        check_extent(r, f"{key}.upper", np.array([lower, upper]))
        names = r.mapping(spec.get("names", {}), f"{key}.names", SIDES)
        side_names = {side: r.name(names.get(side, side), f"{key}.names.{side}") for side in SIDES}
        return RectangleGeometry(lower, upper, side_names), tuple(dict.fromkeys(side_names.values()))
    if kind == "profile":
        return profile_geometry(r, spec, key, source)
    if kind == "polygon":
        spec = r.mapping(spec, key, ("vertices", "edges", "file", "holes"))
        outer = listed_loop(r, spec, key, source, limits.MAX_POLYGON_VERTICES)
        holes = []
        hole_list = spec.get("holes", [])
        if not isinstance(hole_list, list):
            raise r.fail(f"{key}.holes", hole_list, "expected a list of holes")
        total = len(outer.vertices)
        extent = _extent(PolygonGeometry(outer, ())) if hole_list else 0.0
        for i, hole in enumerate(hole_list):
            if isinstance(hole, dict) and "circle" in hole:
                total += 4
            elif isinstance(hole, dict) and isinstance(hole.get("vertices"), list):
                total += len(hole["vertices"])
            if total > limits.MAX_POLYGON_VERTICES:
                raise r.fail(f"{key}.holes[{i}]", f"<{len(hole_list)} holes>",
                             f"the polygon and its holes have more than {limits.MAX_POLYGON_VERTICES} vertices (a circle "
                             "counts 4); expected at most that many (use a gmsh mesh_file for more)")
            holes.append(_hole(r, hole, f"{key}.holes[{i}]", extent, source, limits.MAX_POLYGON_VERTICES - total))
            if isinstance(hole, dict) and "file" in hole:
                total += len(holes[-1].vertices)
        if holes:
            _check_holes_inside(r, key, outer, holes)
        names = [*outer.edge_names]
        for hole in holes:
            names.extend(hole.edge_names)
        return PolygonGeometry(outer, tuple(holes)), tuple(dict.fromkeys(names))
    if not isinstance(spec, str) or not spec:
        raise r.fail(key, spec, "expected the path of a gmsh .msh file")
    path = Path(spec)
    if not path.is_absolute():
        path = source.parent / path
    problem = path_problem(path)
    if problem is not None:
        raise r.fail(key, spec, f"the path {'' if path == Path(spec) else f'{shortened(str(path))} '}{problem}")
    mode = file_mode(r, key, spec, path)
    if not stat.S_ISREG(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
        raise r.fail(key, spec, f"{shortened(str(path))} is {kind}; expected a gmsh .msh file")
    r.inputs.append(file_digest(r, key, spec, path))
    r.input_paths.append(path)
    return MeshFileGeometry(path), None


def _hole(r: Reader, data: Any, key: str, extent: float, source: Path, limit: int) -> Loop:
    """One hole, valid on its own (``extent``: the body's, which bounds its size); where it
    lies is checked with all of them (:func:`_check_holes_inside`)."""
    data = r.mapping(data, key, ("circle", "vertices", "edges", "file", "name"))
    if "circle" in data:
        if "vertices" in data or "edges" in data or "file" in data:
            raise r.fail(key, data, "a hole is either a circle or a polygon (vertices and edges, or a file), "
                         "not both")
        circle = r.mapping(data["circle"], f"{key}.circle", ("center", "radius"), required=("center", "radius"))
        center = r.point(circle["center"], f"{key}.circle.center")
        radius = r.number(circle["radius"], f"{key}.circle.radius", low=0, low_open=True)
        name = r.name(data.get("name", "hole"), f"{key}.name")
        least = max(extent / (2 * limits.MAX_DIVISIONS), 1e-6 * math.hypot(*center),
                    1 / limits.SCALE_LIMIT)
        if radius < least:
            raise r.fail(f"{key}.circle.radius", radius,
                         f"must be at least {least:.3g}: the body's extent / {2 * limits.MAX_DIVISIONS}, and 1e-6 of the "
                         "centre's distance from the origin (so that float64 and the mesh resolve the circle)")
        try:
            loop = circle_loop(center, radius, name)
        except MeshError as error:
            raise r.fail(f"{key}.circle", circle, str(error)) from None
    else:
        if not ("vertices" in data or "edges" in data or "file" in data):
            raise r.fail(key, data, "expected circle: {center, radius}, vertices and edges, or file")
        if "name" in data:
            raise r.fail(f"{key}.name", data["name"], "a polygonal hole names each of its edges instead")
        loop = listed_loop(r, data, key, source, limit)
        least = extent / limits.MAX_DIVISIONS
        span = float(coordinate_span(loop_outline(loop)).min())  # the hole's, arcs included
        if span < least:
            raise r.fail(f"{key}.vertices", loop.vertices.tolist(),
                         f"the hole is {span:.3g} across; expected at least the body's extent / {limits.MAX_DIVISIONS} "
                         f"= {least:.3g}, the finest mesh size")
    return loop


def _check_holes_inside(r: Reader, key: str, outer: Loop, holes: list[Loop]) -> None:
    """Every hole inside the body, meeting neither its outer boundary nor another hole:
    one sweep over all the loops (a body with hundreds of holes read from files), against
    the curves themselves, arcs included (sampled every degree: within 4e-5 of a radius),
    so that a hole in a round body's bulge is allowed and one that crosses an arc is
    refused. (A hole inside another is left to the mesher's area check.)"""
    outlines = [loop_outline(outer), *(loop_outline(hole) for hole in holes)]
    found = first_crossing_among(outlines)
    if found is not None:
        point, i, j = found
        if i == 0:
            raise r.fail(f"{key}.holes[{j - 1}]", point.tolist(), "the hole's boundary meets the body's outer "
                         "boundary (arcs included) near this point; a hole must lie inside the body")
        raise r.fail(f"{key}.holes[{j - 1}]", point.tolist(), f"the hole's boundary meets that of holes[{i - 1}] "
                     "near this point; holes must not touch or overlap")
    outside = np.flatnonzero(~_points_inside(outlines[0], np.array([outline[0] for outline in outlines[1:]])))
    if outside.size:
        j = int(outside[0])
        raise r.fail(f"{key}.holes[{j}]", outlines[j + 1][0].tolist(),
                     "the hole lies outside the body's outer boundary (arcs included)")


def _points_inside(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd rule: whether each of ``points`` (q, 2) lies inside the closed ``polygon``.

    An edge is crossed by the ray from a point towards +x when the point's y lies in the
    edge's half-open y-range [min, max) and the point is left of the edge there. The
    points are sorted by y, so each edge meets only the points in its range (a slice of
    them) instead of all of them: a body's outline of 10^5 edges against the first points
    of hundreds of holes."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    low, high = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    order = np.argsort(points[:, 1], kind="stable")
    ys = points[order, 1]
    start, stop = np.searchsorted(ys, low, side="left"), np.searchsorted(ys, high, side="left")
    counts = stop - start
    edge = np.repeat(np.arange(len(a)), counts)
    point = order[np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts - start, counts)]
    px, py = points[point, 0], points[point, 1]
    x_cross = a[edge, 0] + (py - a[edge, 1]) * (b[edge, 0] - a[edge, 0]) / (b[edge, 1] - a[edge, 1])
    crossings = np.bincount(point[px < x_cross], minlength=len(points))
    return crossings % 2 == 1


#: The least mesh.contact_size, relative to the body's extent: what round-off imposes.
CONTACT_SIZE_ROUNDOFF = 1e-12


def read_mesh_settings(r: Reader, data: Any, geometry: Geometry) -> MeshSettings:
    data = r.mapping(data if data is not None else {}, "mesh",
                     ("divisions", "size", "diagonal", "refine", "min_angle", "contact_size", "grading"))
    divisions = None
    if "divisions" in data:
        if not isinstance(geometry, RectangleGeometry):
            raise r.fail("mesh.divisions", data["divisions"], "only a rectangle has divisions; give mesh.size")
        value = data["divisions"]
        if isinstance(value, int) and not isinstance(value, bool):
            value = [value, value]
        if not isinstance(value, list) or len(value) != 2:
            raise r.fail("mesh.divisions", value, "expected an integer or [nx, ny]")
        divisions = tuple(r.integer(v, f"mesh.divisions[{i}]", low=1, high=100_000) for i, v in enumerate(value))
    size = None
    if "size" in data:
        if divisions is not None:
            raise r.fail("mesh.size", data["size"], "give mesh.divisions or mesh.size, not both")
        size = r.number(data["size"], "mesh.size", low=0, low_open=True)
        extent = _extent(geometry)
        if extent is not None and size > extent:
            raise r.fail("mesh.size", size, f"must not exceed the body's extent {extent:g}")
        if extent is not None and size < extent / limits.MAX_DIVISIONS:
            raise r.fail("mesh.size", size, f"must be at least the body's extent / {limits.MAX_DIVISIONS} = "
                         f"{extent / limits.MAX_DIVISIONS:g} (use mesh.refine for finer meshes)")
    if isinstance(geometry, MeshFileGeometry) and (divisions or size):
        raise r.fail("mesh.size", data.get("size"), "a mesh file is used as it is; use mesh.refine to refine it")
    diagonal = r.choice(data.get("diagonal", "right"), "mesh.diagonal", DIAGONALS)
    refine = r.integer(data.get("refine", 0), "mesh.refine", low=0, high=12)
    min_angle = r.number(data.get("min_angle", 30.0), "mesh.min_angle", low=0, high=34,
                         expected="must be in [0, 34] degrees (Triangle may not terminate above 34)")
    if isinstance(geometry, RectangleGeometry) and divisions is None:
        width = geometry.upper[0] - geometry.lower[0]
        height = geometry.upper[1] - geometry.lower[1]
        h = size if size is not None else max(width, height) / 16
        divisions = (max(1, math.ceil(width / h - 1e-9)), max(1, math.ceil(height / h - 1e-9)))
    if isinstance(geometry, PolygonGeometry) and size is None:
        size = _extent(geometry) / 20
    contact_size = None
    if "contact_size" in data:
        if not isinstance(geometry, PolygonGeometry):
            raise r.fail("mesh.contact_size", data["contact_size"],
                         "graded meshes need a polygon geometry (Triangle); a rectangle can be given as a polygon")
        # Only round-off bounds it below (coordinates of nodes contact_size apart on a body
        # of this extent keep about 4 digits of their difference); memory bounds it through
        # the size guard, which counts the graded mesh's triangles before meshing.
        least = CONTACT_SIZE_ROUNDOFF * _extent(geometry)
        contact_size = r.number(data["contact_size"], "mesh.contact_size", low=least, high=size,
                                expected=f"must be in [extent × {CONTACT_SIZE_ROUNDOFF:g} = {least:g}, "
                                         f"mesh.size = {size:g}]")
    elif "grading" in data:
        raise r.fail("mesh.grading", data["grading"], "only meaningful with mesh.contact_size")
    grading = None
    if "grading" in data:
        grading = r.number(data["grading"], "mesh.grading", low=0.01, high=10.0,
                           expected="must be in [0.01, 10] (growth of h per unit distance from the contact parts)")
    return MeshSettings(divisions=divisions, size=size, diagonal=diagonal, refine=refine, min_angle=min_angle,
                        contact_size=contact_size, grading_key=grading)


def _extent(geometry: Geometry) -> float | None:
    """The larger side of the body's bounding box: its outer loop's outline, arcs included
    (the vertices of a half-disk's top lie on one line, and its arc gives it its height)."""
    if isinstance(geometry, RectangleGeometry):
        return max(geometry.upper[0] - geometry.lower[0], geometry.upper[1] - geometry.lower[1])
    if isinstance(geometry, PolygonGeometry):
        return float(coordinate_span(loop_outline(geometry.outer)).max())
    return None
