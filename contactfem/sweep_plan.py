"""Sweep files: their validation, and the case text of each point with its values set."""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from contactfem.case import (
    OUTPUT_NAME_RESERVE,
    OUTPUT_PATH_RESERVE,
    parse_case,
    path_problem,
    read_text_file,
    shortened,
)
from contactfem.case.reader import Reader
from contactfem.case.yaml_loader import load_yaml
from contactfem.errors import CaseError

#: The most points a sweep may have (the product of a grid's list lengths).
MAX_SWEEP_POINTS = 10_000
SWEEP_KEYS = ("title", "description", "case", "grid", "points", "output")

_NAME = r"[^.\[\]\s][^.\[\]]*"
_KEY = re.compile(rf"{_NAME}(\[\d+\])*(\.{_NAME}(\[\d+\])*)*")
_STEP = re.compile(rf"({_NAME})|\[(\d+)\]")


@dataclass(frozen=True)
class SweepPoint:
    """One point: ``values`` by dotted key, its case ``text`` (None when the values could not
    be set) and its ``digest``, the case's (the text and the data files it reads), or the
    text's SHA-256 when it is refused; ``problem`` is its one-line refusal, if any."""

    index: int  # 1-based, in the order of the grid or the list
    values: dict[str, Any]
    label: str
    source: str  # what parse_case is given: names the point in messages
    text: str | None
    digest: str | None
    problem: str | None = None


@dataclass(frozen=True)
class Sweep:
    source: Path
    digest: str
    title: str
    base: Path
    base_title: str
    base_digest: str
    kind: str  # "grid" | "points"
    keys: tuple[str, ...]
    points: tuple[SweepPoint, ...]
    directory: Path

    def pending(self, finished: Mapping[str, dict]) -> list[dict]:
        """The tasks still to solve: one per distinct case text that is valid and not finished."""
        tasks: dict[str, dict] = {}
        for point in self.points:
            if point.problem is None and point.digest not in finished and point.digest not in tasks:
                tasks[point.digest] = {"index": point.index, "label": point.label, "source": point.source,
                                       "text": point.text, "digest": point.digest}
        return list(tasks.values())


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file and its base case, and build every point's case text.

    A point whose values make an invalid case is kept, with its refusal as ``problem``.

    Raises
    ------
    CaseError
        If the sweep file or the base case cannot be read or is malformed.
    """
    path = Path(path)
    text = read_text_file(path, what="sweep")
    r = Reader(shortened(path.name))
    data = load_yaml(text, r.filename)
    if data is None:
        raise CaseError(f"{r.filename}: the sweep file is empty (or only comments); expected a mapping with "
                        "case and grid or points")
    top = r.mapping(data, "", SWEEP_KEYS, required=("case",))
    for key in ("title", "description"):
        if key in top and not isinstance(top[key], str):
            raise r.fail(key, top[key], "expected a string")
    # A file name's bytes that are not UTF-8 as \xNN: the default title is shown and written as text.
    title = top.get("title", os.fsencode(path.stem).decode("utf-8", "backslashreplace"))
    if len(title) > 200 or not title.isprintable():
        raise r.fail("title", title, "expected one line of at most 200 printable characters")

    reference = top["case"]
    if not isinstance(reference, str) or not reference.strip():
        raise r.fail("case", reference, "expected the path of the base case file, relative to the sweep file")
    if path_problem(reference) is not None:
        raise r.fail("case", reference, f"the path {path_problem(reference)}")
    base = path.parent / reference
    try:
        base_text = read_text_file(base)
        base_case = parse_case(base_text, source=base)
    except CaseError as error:
        raise CaseError(f"{r.filename}: case: {error}") from None
    base_data = load_yaml(base_text, shortened(base.name))

    if ("grid" in top) == ("points" in top):
        raise CaseError(f"{r.filename}: grid, points: {'both are' if 'grid' in top else 'neither is'} given; "
                        "expected exactly one: grid (a cartesian product) or points (a list)")
    kind = "grid" if "grid" in top else "points"
    assignments = _grid(r, top["grid"]) if kind == "grid" else _point_list(r, top["points"])
    keys = tuple(dict.fromkeys(key for values in assignments for key in values))

    output = r.mapping(top.get("output") or {}, "output", ("directory",))
    directory = output.get("directory", f"results/{path.stem}")
    if not isinstance(directory, str) or not directory.strip():
        raise r.fail("output.directory", directory, "expected a directory path")
    problem = path_problem(directory, name_reserve=OUTPUT_NAME_RESERVE, path_reserve=OUTPUT_PATH_RESERVE)
    if problem is not None:
        raise r.fail("output.directory", directory, f"the path {problem}")

    name = shortened(path.name, 80)
    points = tuple(_point(base, base_data, values, index, f"{name} point {index}")
                   for index, values in enumerate(assignments, start=1))
    if all(point.problem is not None for point in points):
        # A mistyped key or a value outside the format refuses every point: the sweep file is wrong.
        raise CaseError(f"{r.filename}: {kind}: every point is refused, so nothing would be solved; "
                        f"{'the point' if len(points) == 1 else 'point 1'}: {points[0].problem}")
    return Sweep(source=path, digest=hashlib.sha256(text.encode("utf-8")).hexdigest(), title=title, base=base,
                 base_title=base_case.title, base_digest=base_case.digest, kind=kind, keys=keys, points=points,
                 directory=Path(directory))


def _grid(r: Reader, grid: Any) -> list[dict[str, Any]]:
    expected = "expected a mapping of dotted case keys (e.g. mesh.divisions) to non-empty lists of values"
    if not isinstance(grid, dict) or not grid:
        raise r.fail("grid", grid, expected)
    columns = []
    for key, values in grid.items():
        _check_key(r, key, "grid")
        where = f"grid.{key}"
        if not isinstance(values, list) or not values:
            raise r.fail(where, values, "expected a non-empty list of values")
        for i, value in enumerate(values):
            _check_value(r, value, f"{where}[{i}]")
        columns.append([(key, value) for value in values])
    count = math.prod(len(c) for c in columns)
    if count > MAX_SWEEP_POINTS:
        raise r.fail("grid", f"{' x '.join(str(len(c)) for c in columns)} = {count} points",
                     f"expected at most {MAX_SWEEP_POINTS} points")
    return [dict(combination) for combination in itertools.product(*columns)]


def _point_list(r: Reader, points: Any) -> list[dict[str, Any]]:
    if not isinstance(points, list) or not points:
        raise r.fail("points", points, "expected a non-empty list of mappings of dotted case keys to values")
    if len(points) > MAX_SWEEP_POINTS:
        raise r.fail("points", f"{len(points)} points", f"expected at most {MAX_SWEEP_POINTS}")
    for i, point in enumerate(points):
        where = f"points[{i}]"
        if not isinstance(point, dict) or not point:
            raise r.fail(where, point, "expected a non-empty mapping of dotted case keys to values")
        for key, value in point.items():
            _check_key(r, key, where)
            _check_value(r, value, f"{where}.{key}")
    return [dict(point) for point in points]


def _check_key(r: Reader, key: Any, where: str) -> None:
    if not isinstance(key, str) or len(key) > 200 or not key.isprintable() or not _KEY.fullmatch(key):
        shown = shortened(key if isinstance(key, str) else repr(key), 64)
        raise CaseError(f"{r.filename}: {where}.{shown}: expected a dotted case key such as mesh.divisions "
                        "or boundary.top.traction[1]")


def _check_value(r: Reader, value: Any, where: str) -> None:
    """Values are what a case file holds and JSON can carry: numbers, strings, booleans, null,
    lists and mappings of them."""
    if isinstance(value, float) and not math.isfinite(value):
        raise r.fail(where, value, "expected a finite number")
    if isinstance(value, list):
        for i, item in enumerate(value):
            _check_value(r, item, f"{where}[{i}]")
    elif isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise r.fail(where, value, "expected a mapping with string keys")
            _check_value(r, item, f"{where}.{key}")
    elif value is not None and not isinstance(value, (bool, int, float, str)):
        raise r.fail(where, str(value), "expected a number, a string, a boolean, null, a list or a mapping")


def _point(base: Path, base_data: dict, values: dict[str, Any], index: int, name: str) -> SweepPoint:
    label = ", ".join(f"{key}={_shown_value(value)}" for key, value in values.items())
    source = str(base.parent / name)
    data = _unshared(base_data)
    try:
        for key, value in values.items():
            _assign(data, key, _unshared(value))
    except _Unassignable as problem:
        return SweepPoint(index, values, label, source, None, None, f"{name}: {problem}")
    # The text must say which files it reads wherever it is solved (a worker elsewhere).
    _absolute_data_paths(data.get("geometry"), base.parent)
    text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None, width=100)
    try:
        case = parse_case(text, source=source)
    except CaseError as error:
        return SweepPoint(index, values, label, source, text, hashlib.sha256(text.encode("utf-8")).hexdigest(),
                          str(error))
    # The case's own digest covers the data files it reads (a profile, an outline, a mesh):
    # a point whose surface file changed is another point, never a stored one reused.
    return SweepPoint(index, values, label, source, text, case.digest)


def _absolute_data_paths(geometry: Any, directory: Path) -> None:
    """Make the data files a geometry names (mesh_file, a profile's or a polygon's or a
    hole's file) absolute against ``directory``, in place; values of other types are left
    to the case's validation."""
    if not isinstance(geometry, dict):
        return

    def absolute(holder: Any, key: str) -> None:
        if isinstance(holder, dict) and isinstance(holder.get(key), str) and holder[key]:
            holder[key] = str((directory / holder[key]).resolve())

    absolute(geometry, "mesh_file")
    absolute(geometry.get("profile"), "file")
    polygon = geometry.get("polygon")
    absolute(polygon, "file")
    if isinstance(polygon, dict) and isinstance(polygon.get("holes"), list):
        for hole in polygon["holes"]:
            absolute(hole, "file")


class _Unassignable(Exception):
    pass


def _assign(data: dict, key: str, value: Any) -> None:
    """Set ``data`` at the dotted ``key``: missing (or scalar) mappings on the way are created,
    list elements must exist."""
    steps: list[str | int] = [int(number) if number else name for name, number in _STEP.findall(key)]
    node: Any = data
    walked = ""
    for step, following in zip(steps, steps[1:] + [None]):
        last = following is None
        if isinstance(step, int):
            if not isinstance(node, list) or step >= len(node):
                size = f"a list of {len(node)}" if isinstance(node, list) else f"{_shown_value(node)}, not a list"
                raise _Unassignable(f"{key}: {walked} is {size}; cannot set element [{step}]")
            walked += f"[{step}]"
            if last:
                node[step] = value
            else:
                node = node[step]
            continue
        if not isinstance(node, dict):
            raise _Unassignable(f"{key}: {walked} is {_shown_value(node)}, not a mapping; cannot set {step}")
        walked = f"{walked}.{step}" if walked else step
        if last:
            node[step] = value
        else:
            child = node.get(step)
            if not isinstance(child, (dict, list)):
                if isinstance(following, int):
                    raise _Unassignable(f"{key}: {walked} is {_shown_value(child)}, not a list; "
                                        f"cannot set element [{following}]")
                child = node[step] = {}
            node = child


def _unshared(value: Any) -> Any:
    """A copy in which no container is shared: a YAML alias stands for a copy, so that setting a
    value reached through one use of an anchor leaves the others as they were."""
    if isinstance(value, dict):
        return {k: _unshared(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_unshared(v) for v in value]
    return copy.copy(value)


def _shown_value(value: Any) -> str:
    if isinstance(value, str):
        text = value
    else:
        try:
            text = json.dumps(value, separators=(",", ":"), ensure_ascii=False)
        except (TypeError, ValueError):
            text = str(value)
    return shortened(text, 60)
