"""Sweep files: their validation, and the case text of each point with its values set.

Every point's case text is built and validated before the first solve, so the plan is
bounded by its size as well as by its number of points: the points times the base case's
size may not pass :data:`MAX_SWEEP_PLAN_BYTES`, checked from the sweep file and the base
case's size before anything is built. Building is linear in the plan's size: the base case
is dumped to YAML once, section by section (its top-level keys), and a point dumps anew only
the sections its values change; the rest of its text is the base's, as dumped. What remains
per point is validating its text (:func:`contactfem.case.parse_case`), which reads it whole.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
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
#: The most bytes of case text a sweep's points may make together: each point's text is built,
#: validated and held before the first solve, and travels to its worker. Validation time
#: grows with the inline numbers, so the bound keeps planning to about a minute and a half
#: (see docs/performance.md#measured-design-choices); 10 000 points of a 6 kB case fit.
MAX_SWEEP_PLAN_BYTES = 64 << 20
#: A plan larger than this is announced (``progress``) before it is built: it takes seconds.
PLAN_NOTE_BYTES = 4 << 20
SWEEP_KEYS = ("title", "description", "case", "grid", "points", "output")

_NAME = r"[^.\[\]\s][^.\[\]]*"
_KEY = re.compile(rf"{_NAME}(\[\d+\])*(\.{_NAME}(\[\d+\])*)*")
_STEP = re.compile(rf"({_NAME})|\[(\d+)\]")


@dataclass(frozen=True)
class SweepPoint:
    """One point: ``values`` by dotted key, its case ``text`` (None when the values could not
    be set) and its ``digest``, the case's (the text and the data files it reads), or the
    text's SHA-256 when it is refused; ``problem`` is its one-line refusal, if any; ``units``
    its case's units (length, force, stress; None when it is refused): a sweep may set them."""

    index: int  # 1-based, in the order of the grid or the list
    values: dict[str, Any]
    label: str
    source: str  # what parse_case is given: names the point in messages
    text: str | None
    digest: str | None
    problem: str | None = None
    units: dict[str, str] | None = None


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
    units: dict[str, str] = field(default_factory=dict)  # the base case's

    def pending(self, finished: Mapping[str, dict]) -> list[dict]:
        """The tasks still to solve: one per distinct case text that is valid and not finished."""
        tasks: dict[str, dict] = {}
        for point in self.points:
            if point.problem is None and point.digest not in finished and point.digest not in tasks:
                tasks[point.digest] = {"index": point.index, "label": point.label, "source": point.source,
                                       "text": point.text, "digest": point.digest}
        return list(tasks.values())


def load_sweep(path: str | Path, progress: Callable[[str], None] | None = None) -> Sweep:
    """Read and validate a sweep file and its base case, and build every point's case text.

    A point whose values make an invalid case is kept, with its refusal as ``problem``.
    ``progress`` is told, once, when the plan is large enough to take a while.

    Raises
    ------
    CaseError
        If the sweep file or the base case cannot be read or is malformed, or if its points
        would make more than :data:`MAX_SWEEP_PLAN_BYTES` of case text.
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
    except CaseError as error:
        raise CaseError(f"{r.filename}: case: {error}") from None

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

    # Bounded before the base case is even validated (which takes seconds for a large one): the
    # file's size stands for its text, then its YAML as dumped (aliases expanded) once it is read.
    values_bytes = sum(_value_bytes(value) for values in assignments for value in values.values())
    _refuse_large_plan(r, kind, top[kind], len(assignments), base, len(base_text.encode("utf-8")), values_bytes)
    try:
        base_case = parse_case(base_text, source=base)
    except CaseError as error:
        raise CaseError(f"{r.filename}: case: {error}") from None
    texts = _PointTexts(load_yaml(base_text, shortened(base.name)), base.parent)
    planned = len(assignments) * texts.base_bytes + values_bytes
    _refuse_large_plan(r, kind, top[kind], len(assignments), base, texts.base_bytes, values_bytes)
    if progress is not None and planned > PLAN_NOTE_BYTES:
        progress(f"planning {len(assignments)} points: {_size(planned)} of case text to build and validate")

    name = shortened(path.name, 80)
    points = tuple(_point(base, texts, values, index, f"{name} point {index}")
                   for index, values in enumerate(assignments, start=1))
    if all(point.problem is not None for point in points):
        # A mistyped key or a value outside the format refuses every point: the sweep file is wrong.
        raise CaseError(f"{r.filename}: {kind}: every point is refused, so nothing would be solved; "
                        f"{'the point' if len(points) == 1 else 'point 1'}: {points[0].problem}")
    return Sweep(source=path, digest=hashlib.sha256(text.encode("utf-8")).hexdigest(), title=title, base=base,
                 base_title=base_case.title, base_digest=base_case.digest, kind=kind, keys=keys, points=points,
                 directory=Path(directory), units=base_case.units.to_dict())


def _value_bytes(value: Any) -> int:
    """About the bytes ``value`` adds to a point's case text (its JSON; YAML is no longer)."""
    if isinstance(value, (dict, list)):
        return len(json.dumps(value, ensure_ascii=False).encode("utf-8"))
    return len(str(value).encode("utf-8")) + 2


def _refuse_large_plan(r: Reader, kind: str, spec: Any, count: int, base: Path, base_bytes: int,
                       values_bytes: int) -> None:
    """Refuse (CaseError) a sweep whose points would make more than MAX_SWEEP_PLAN_BYTES of case text."""
    total = count * base_bytes + values_bytes
    if total <= MAX_SWEEP_PLAN_BYTES:
        return
    if kind == "grid":
        shape = " x ".join(str(len(values)) for values in spec.values())
        what = f"grid: {shape} = {count} points" if len(spec) > 1 else f"grid: {count} points"
    else:
        what = f"points: {count} points"
    largest = MAX_SWEEP_PLAN_BYTES // max(base_bytes, 1)
    raise CaseError(f"{r.filename}: {what} of a {_size(base_bytes)} base case ({shortened(base.name, 80)}) "
                    f"make {_size(total)} of case text to build and validate before the first solve; "
                    f"expected at most {MAX_SWEEP_PLAN_BYTES >> 20} MiB (at most {largest} points of this case): "
                    "fewer points, or a smaller base case (a profile's heights, an outline or a mesh read from "
                    "a file rather than written inline)")


def _size(size: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if size >= 0.1 * scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size} bytes"


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


class _Dumper(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):  # libyaml's emitter when PyYAML has it
    """YAML as ``yaml.safe_dump`` writes it (libyaml's emitter writes the same text, faster),
    without anchors: a value used twice is written twice, as a point's copy of it would be."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


class _Section(dict):
    """One top-level entry of a case, dumped as it is within the whole case's block mapping
    (alone, a mapping of one scalar would be written in flow style, ``{title: x}``)."""


_Dumper.add_representer(_Section, lambda dumper, data: dumper.represent_mapping(
    "tag:yaml.org,2002:map", data, flow_style=False))


def _dump(data: dict) -> str:
    return yaml.dump(data, Dumper=_Dumper, sort_keys=False, allow_unicode=True, default_flow_style=None,
                     width=100)


class _PointTexts:
    """The case texts of a sweep's points, from the base case's YAML mapping: each top-level
    section of the base dumped once (its data files made absolute), a point's own sections
    copied, set and dumped anew. A point's text is the same as dumping its whole mapping."""

    def __init__(self, base_data: dict, directory: Path) -> None:
        self.directory = directory
        self.base = dict(base_data)
        if "geometry" in self.base:
            # The text must say which files it reads wherever it is solved (a worker elsewhere).
            self.base["geometry"] = _unshared(self.base["geometry"])
            _absolute_data_paths(self.base["geometry"], directory)
        self.sections = {key: _dump(_Section({key: value})) for key, value in self.base.items()}
        self.base_text = _text_of(self.base, self.sections, set())
        self.base_bytes = len(self.base_text.encode("utf-8"))

    def text(self, values: dict[str, Any]) -> str:
        """The case text with ``values`` set (raises _Unassignable)."""
        data = dict(self.base)
        changed: set[str] = set()
        for key, value in values.items():
            section = _STEP.match(key).group(1)
            if section not in changed:
                changed.add(section)
                if section in data:
                    data[section] = _unshared(data[section])
            _assign(data, key, _unshared(value))
        if "geometry" in changed:
            _absolute_data_paths(data.get("geometry"), self.directory)
        return _text_of(data, self.sections, changed)


def _text_of(data: dict, sections: dict[str, str], changed: set[str]) -> str:
    if not any(isinstance(value, (dict, list)) for value in data.values()):
        return _dump(data)  # a mapping of scalars alone is dumped on one line, as {a: 1, b: 2}
    return "".join(sections[key] if key not in changed else _dump(_Section({key: value}))
                   for key, value in data.items())


def _point(base: Path, texts: _PointTexts, values: dict[str, Any], index: int, name: str) -> SweepPoint:
    label = ", ".join(f"{key}={_shown_value(value)}" for key, value in values.items())
    source = str(base.parent / name)
    try:
        text = texts.text(values)
    except _Unassignable as problem:
        return SweepPoint(index, values, label, source, None, None, f"{name}: {problem}")
    try:
        case = parse_case(text, source=source)
    except CaseError as error:
        return SweepPoint(index, values, label, source, text, hashlib.sha256(text.encode("utf-8")).hexdigest(),
                          str(error))
    # The case's own digest covers the data files it reads (a profile, an outline, a mesh):
    # a point whose surface file changed is another point, never a stored one reused.
    return SweepPoint(index, values, label, source, text, case.digest, units=case.units.to_dict())


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
