"""A body whose bottom edge is a height profile: from a file, a list of heights or an expression."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.case import limits
from contactfem.case.crossings import polygon_problems
from contactfem.case.files import data_file_lines
from contactfem.case.loops import Loop
from contactfem.case.model import Geometry, PolygonGeometry
from contactfem.case.outline import check_extent
from contactfem.case.reader import Reader
from contactfem.case.tables import parse_columns
from contactfem.errors import CaseError


PROFILE_SOURCES = ("file", "heights", "expression")


def profile_geometry(r: Reader, spec: Any, key: str, source: Path) -> tuple[Geometry, tuple[str, ...]]:
    """A body whose bottom edge is a height profile, closed by two straight sides and a top.

    The profile is a graph h(s) over the line through ``origin`` along ``direction``:
    point i is origin + s_i d + h_i n, d the unit direction and n its left normal (the
    body's side). The top runs at height ``depth`` over the line, the sides at the first
    and last s. With s strictly increasing and depth above every height the outline is a
    simple counter-clockwise polygon; it is still checked (in O(k log k)) like any other.
    """
    spec = r.mapping(spec, key, (*PROFILE_SOURCES, *GRAPH_OPTIONS, "name", "depth", "sides", "top"),
                     required=("depth",))
    s, h, origin, d, n = profile_graph(r, spec, key, source, limits.MAX_POLYGON_VERTICES - 2)
    depth = r.number(spec["depth"], f"{key}.depth", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT)
    if not depth > h.max():
        raise r.fail(f"{key}.depth", depth, f"the top must lie above the highest point of the profile, "
                     f"h = {h.max():.6g}; expected a depth greater than that")
    name = r.name(spec.get("name", "base"), f"{key}.name")
    top = r.name(spec.get("top", "top"), f"{key}.top")
    sides = spec.get("sides", ["left", "right"])
    if isinstance(sides, str):
        sides = [sides, sides]
    if not isinstance(sides, list) or len(sides) != 2:
        raise r.fail(f"{key}.sides", sides, "expected [first, last]: the names of the sides at the first and the "
                     "last point (or one name for both)")
    first_side, last_side = (r.name(v, f"{key}.sides[{i}]") for i, v in enumerate(sides))
    s_all = np.concatenate([s, [s[-1], s[0]]])
    h_all = np.concatenate([h, [depth, depth]])
    with np.errstate(over="ignore", invalid="ignore"):
        points = np.asarray(origin) + s_all[:, None] * d + h_all[:, None] * n
    if not np.all(np.isfinite(points)) or np.abs(points).max() > limits.SCALE_LIMIT:
        raise r.fail(key, f"<{len(h)} points>", f"the body's coordinates must lie within ±{limits.SCALE_LIMIT:g}")
    names = (name,) * (len(h) - 1) + (last_side, top, first_side)
    problem = polygon_problems(points)
    if problem is not None:  # e.g. points that coincide once placed, in float64
        raise r.fail(key, f"<{len(h)} points>", f"the outline it makes is not a simple polygon: {problem}")
    check_extent(r, key, points)
    loop = Loop(vertices=points, edge_names=names)
    return PolygonGeometry(loop, ()), tuple(dict.fromkeys(names))


#: The keys that place a profile's heights: where they are sampled and along which line.
GRAPH_OPTIONS = ("spacing", "start", "x", "points", "origin", "direction")


def profile_graph(r: Reader, spec: dict, key: str, source: Path,
                  limit: int) -> tuple[np.ndarray, np.ndarray, tuple[float, float], np.ndarray, np.ndarray]:
    """The graph h(s) a profile mapping gives (``file``, ``heights`` or ``expression``, at
    most ``limit`` points) over the line through ``origin`` along ``direction``: s (k,)
    strictly increasing, h (k,), the origin, the unit direction d and its left normal n.
    Point i is origin + s_i d + h_i n. The body's bottom edge (``geometry.profile``) and a
    rigid profile (``obstacle.profile``) are read by this one function."""
    given = [name for name in PROFILE_SOURCES if name in spec]
    if len(given) != 1:
        raise r.fail(key, {name: "..." for name in given} or spec,
                     f"expected exactly one of {', '.join(PROFILE_SOURCES)} (the heights)")
    (kind,) = given
    allowed = {"file": ("spacing", "start"), "heights": ("spacing", "start"), "expression": ("x", "points")}[kind]
    for option in ("spacing", "start", "x", "points"):
        if option in spec and option not in allowed:
            raise r.fail(f"{key}.{option}", spec[option], f"not used with {kind}; {kind} takes "
                         f"{' and '.join(allowed)}" + (" (a one-column file)" if kind == "file" else ""))
    if kind == "expression":
        s, h = _profile_expression(r, spec, key, limit)
    elif kind == "heights":
        values = spec["heights"]
        if not isinstance(values, list) or len(values) < 2:
            raise r.fail(f"{key}.heights", values, "expected a list of at least 2 heights")
        if len(values) > limit:
            raise r.fail(f"{key}.heights", f"<{len(values)} heights>", f"expected at most {limit} heights")
        h = np.array([r.number(v, f"{key}.heights[{i}]", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT)
                      for i, v in enumerate(values)])
        s = _equally_spaced(r, spec, key, len(h), "heights")
    else:
        s, h = _profile_file(r, spec, key, source, limit)
    origin = r.point(spec.get("origin", [0, 0]), f"{key}.origin")
    direction = r.point(spec.get("direction", [1, 0]), f"{key}.direction")
    norm = math.hypot(*direction)
    if not norm > 0 or not math.isfinite(norm):
        raise r.fail(f"{key}.direction", list(direction), "expected a nonzero vector [dx, dy] along the profile")
    d = np.array(direction) / norm
    return s, h, origin, d, np.array([-d[1], d[0]])


def _equally_spaced(r: Reader, spec: dict, key: str, count: int, what: str) -> np.ndarray:
    if "spacing" not in spec:
        raise CaseError(f"{r.filename}: {key}.spacing: missing (required with {what}: the distance between "
                        "consecutive heights)")
    spacing = r.number(spec["spacing"], f"{key}.spacing", low=0, low_open=True, high=limits.SCALE_LIMIT)
    start = r.number(spec.get("start", 0), f"{key}.start", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT)
    return start + spacing * np.arange(count)


def _profile_expression(r: Reader, spec: dict, key: str, limit: int) -> tuple[np.ndarray, np.ndarray]:
    for name in ("x", "points"):
        if name not in spec:
            raise CaseError(f"{r.filename}: {key}.{name}: missing (required with expression: the interval "
                            "[x0, x1] and the number of points sampled on it)")
    interval = spec["x"]
    if not isinstance(interval, list) or len(interval) != 2:
        raise r.fail(f"{key}.x", interval, "expected the interval [x0, x1] the profile spans")
    x0, x1 = (r.number(v, f"{key}.x[{i}]", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT) for i, v in enumerate(interval))
    if not x1 > x0:
        raise r.fail(f"{key}.x", interval, "expected x0 < x1")
    count = r.integer(spec["points"], f"{key}.points", low=2, high=limit)
    expression = r.expression(spec["expression"], f"{key}.expression")
    if "y" in expression.variables:
        raise r.fail(f"{key}.expression", expression.text, "expected the height as an expression in x only")
    s = np.linspace(x0, x1, count)
    h = expression(s, np.zeros_like(s))
    bad = np.flatnonzero(~np.isfinite(h) | (np.abs(h) > limits.SCALE_LIMIT))
    if bad.size:
        raise r.fail(f"{key}.expression", expression.text,
                     f"is {h[bad[0]]:g} at x = {float(s[bad[0]])!r}; expected finite heights within ±{limits.SCALE_LIMIT:g}")
    return s, h


def _profile_file(r: Reader, spec: dict, key: str, source: Path, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """The points of a CSV profile: two columns x, h, or one column of heights with ``spacing``."""
    fkey = f"{key}.file"
    text = spec["file"]
    lines = data_file_lines(r, fkey, text, source, "a CSV file (x, h per line, or h per line with spacing)")
    table, line_of_row = parse_columns(r, fkey, text, lines, limit)
    if table.shape[1] == 2:
        for option in ("spacing", "start"):
            if option in spec:
                raise r.fail(f"{key}.{option}", spec[option], "only for a one-column file; this one gives x and h")
        s, h = table[:, 0], table[:, 1]
        steps = np.flatnonzero(~(np.diff(s) > 0))
        if steps.size:
            line = line_of_row(int(steps[0]) + 1)
            raise r.fail(fkey, text, f"line {line}: x = {float(s[steps[0] + 1])!r} does not exceed the x before it, "
                         f"{float(s[steps[0]])!r}; expected x strictly increasing (a height profile h(x))")
    else:
        h = table[:, 0]
        s = _equally_spaced(r, spec, key, len(h), "a one-column file")
    return s, h
