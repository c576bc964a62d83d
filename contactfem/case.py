"""Read a YAML case file and validate it, once, into a frozen :class:`Case`.

Every refusal is a :class:`CaseError` whose message names the file, the key, the value
and what was expected, e.g. ``beam.yaml: material.nu = 0.5: must be in [0, 0.5)``.
The format is documented in README.md ("The case file"); ``cases/`` holds commented examples.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from contactfem.errors import CaseError
from contactfem.expressions import Expression, ExpressionError, compile_expression
from contactfem.linalg import BACKEND_CHOICES
from contactfem.methods import METHOD_NAMES
from contactfem.mesh.polygon import Arc, Loop, circle_loop, polygon_problems

if TYPE_CHECKING:
    from contactfem.exact import ExactSolution

PART_KINDS = ("clamped", "free", "contact", "symmetry")
PART_LOADS = ("traction", "pressure", "displacement")
DIAGONALS = ("right", "left", "alternate", "crossed")
OUTPUT_FILES = ("vtu", "h5", "json", "xdmf")
# Written unless the case lists its own: xdmf (an XDMF view of the HDF5 plus a companion
# file) is an extra a case asks for.
DEFAULT_OUTPUT_FILES = ("vtu", "h5", "json")
EXACT = "exact"  # the value that takes a load or a displacement from the exact: block
SIDES = ("bottom", "right", "top", "left")
#: Bound on the magnitude of coordinates, moduli and solver.c (and below it, of the
#: smallest body extent and modulus): products of six such numbers, as in the stiffness
#: times a displacement times a length, stay far inside float64's 1e±308.
SCALE_LIMIT = 1e50
#: The finest uniform mesh: the same bound as mesh.divisions (100 000 per side).
MAX_DIVISIONS = 100_000
#: Largest lambda/mu (plane strain): beyond it, nu = lambda/(2(lambda + mu)) > 0.499999995,
#: the P1 stiffness is singular to round-off (its condition number grows like lambda/mu) and
#: the solution is pure locking. A warning starts far earlier (report.LOCKING_WARNING_RATIO).
MAX_LAME_RATIO = 1e8


# --------------------------------------------------------------------------- the case


@dataclass(frozen=True)
class RectangleGeometry:
    lower: tuple[float, float]
    upper: tuple[float, float]
    side_names: dict[str, str]  # side -> part name


@dataclass(frozen=True)
class PolygonGeometry:
    outer: Loop
    holes: tuple[Loop, ...]


@dataclass(frozen=True)
class MeshFileGeometry:
    path: Path


Geometry = RectangleGeometry | PolygonGeometry | MeshFileGeometry


@dataclass(frozen=True)
class MeshSettings:
    """How to mesh. ``contact_size`` and ``grading`` grade a polygon mesh towards ΓC:
    h(x) = min(size, contact_size + grading · distance(x, ΓC))."""

    divisions: tuple[int, int] | None
    size: float | None
    diagonal: str
    refine: int
    min_angle: float
    contact_size: float | None = None
    grading: float = 0.25


@dataclass(frozen=True)
class Material:
    lame_lambda: float
    lame_mu: float
    plane: str  # "strain" | "stress"
    young: float
    poisson: float


@dataclass(frozen=True)
class BoundaryPart:
    """A named boundary part and what holds on it.

    ``kind`` is clamped | free | contact | traction | pressure | displacement. ``values``
    holds the two components of a traction or a displacement (None for a displacement
    component left free), or the single pressure. ``exact`` marks ``{traction: exact}``
    (``values`` empty: σ(u_exact) n depends on the edge's normal) and
    ``{displacement: exact}`` (``values`` are the exact block's two expressions).
    """

    name: str
    kind: str
    values: tuple[Expression | None, ...] = ()
    exact: bool = False

    @property
    def label(self) -> str:
        """The kind as the case file says it, e.g. ``traction (exact)``."""
        return f"{self.kind} (exact)" if self.exact else self.kind

    @property
    def is_dirichlet(self) -> bool:
        return self.kind in ("clamped", "displacement")


@dataclass(frozen=True)
class Obstacle:
    """The rigid half-plane {p : (p − point)·normal ≥ 0}; ``normal`` is a unit vector pointing into it."""

    point: tuple[float, float]
    normal: tuple[float, float]


@dataclass(frozen=True)
class ExactBlock:
    """The ``exact:`` block: a manufactured displacement and what is derived from it.

    ``displacement`` holds the two checked expressions; ``solution`` is the
    :class:`~contactfem.exact.ExactSolution` built from them once, at validation, with
    the case's plane law and obstacle normal (excluded from comparison and hashing).
    """

    displacement: tuple[Expression, Expression]
    solution: "ExactSolution" = field(compare=False, repr=False)


@dataclass(frozen=True)
class SolverSettings:
    method: str
    tolerance: float
    max_iterations: int
    c: float | None
    backend: str


@dataclass(frozen=True)
class OutputSettings:
    directory: Path
    files: tuple[str, ...]


@dataclass(frozen=True)
class Case:
    """A validated case. ``text`` is the file as read, ``digest`` its SHA-256.

    ``exact`` is the manufactured solution of an ``exact:`` block (None without one); the
    body force is then derived from it and ``body_force`` is None.
    """

    source: Path
    text: str
    digest: str
    title: str
    geometry: Geometry
    mesh: MeshSettings
    material: Material
    body_force: tuple[Expression, Expression] | None
    parts: tuple[BoundaryPart, ...]
    obstacle: Obstacle
    solver: SolverSettings
    output: OutputSettings
    exact: ExactBlock | None = None

    def part(self, name: str) -> BoundaryPart:
        return next(p for p in self.parts if p.name == name)

    def parts_of_kind(self, *kinds: str) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts if p.kind in kinds)

    @property
    def contact_parts(self) -> tuple[str, ...]:
        return self.parts_of_kind("contact")

    @property
    def dirichlet_parts(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts if p.is_dirichlet)

    def exact_solution(self) -> "ExactSolution | None":
        """The exact: block's derived solution (for the norms), or None without one."""
        return None if self.exact is None else self.exact.solution

    def with_solver(self, **changes: Any) -> "Case":
        """A copy with some solver settings replaced (validated like the file's)."""
        from dataclasses import replace

        return replace(self, solver=replace(self.solver, **changes))


# --------------------------------------------------------------------------- reading


class _Reader:
    """Typed access to a YAML mapping that reports errors with the file and dotted key."""

    def __init__(self, filename: str) -> None:
        self.filename = filename

    def fail(self, key: str, value: Any, expected: str) -> CaseError:
        shown = _show(value)
        where = f"{key} = {shown}" if key else shown
        return CaseError(f"{self.filename}: {where}: {expected}")

    def mapping(self, data: Any, key: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, data, "expected a mapping of keys to values")
        for name in data:
            if not isinstance(name, str) or name not in allowed:
                raise CaseError(
                    f"{self.filename}: {_join(key, str(name))}: unknown key; "
                    f"expected one of {', '.join(allowed)}"
                )
        for name in required:
            if name not in data:
                raise CaseError(f"{self.filename}: {_join(key, name)}: missing (required)")
        return data

    def number(self, value: Any, key: str, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, high_open: bool = False, expected: str | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            # YAML 1.1 reads "1e6" (no dot) as a string: accept plain numeric strings.
            if isinstance(value, str):
                try:
                    value = float(value)
                except ValueError:
                    raise self.fail(key, value, "expected a number") from None
            else:
                raise self.fail(key, value, "expected a number")
        rule = expected or _range_text(low, high, low_open, high_open)
        try:
            value = float(value)
        except OverflowError:
            raise self.fail(key, value, f"expected a finite number{', ' + rule if rule else ''}") from None
        if not math.isfinite(value):
            raise self.fail(key, value, f"expected a finite number{', ' + rule if rule else ''}")
        if low is not None and (value < low or (low_open and value == low)):
            raise self.fail(key, value, rule)
        if high is not None and (value > high or (high_open and value == high)):
            raise self.fail(key, value, rule)
        return value

    def integer(self, value: Any, key: str, *, low: int, high: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, value, f"expected an integer in [{low}, {high}]")
        if not low <= value <= high:
            raise self.fail(key, value, f"expected an integer in [{low}, {high}]")
        return value

    def choice(self, value: Any, key: str, choices: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in choices:
            raise self.fail(key, value, f"expected one of {', '.join(choices)}")
        return value

    def name(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value.strip() or len(value) > 64:
            raise self.fail(key, value, "expected a part name (a non-empty string of at most 64 characters)")
        return value

    def point(self, value: Any, key: str) -> tuple[float, float]:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise self.fail(key, value, "expected a point [x, y]")
        return (self.number(value[0], f"{key}[0]", low=-SCALE_LIMIT, high=SCALE_LIMIT),
                self.number(value[1], f"{key}[1]", low=-SCALE_LIMIT, high=SCALE_LIMIT))

    def expression(self, value: Any, key: str) -> Expression:
        try:
            return compile_expression(value)
        except ExpressionError as error:
            raise self.fail(key, value, str(error)) from None

    def vector_field(self, value: Any, key: str, *, allow_free: bool = False) -> tuple[Expression | None, ...]:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            what = "[x, y] components (numbers or expressions in x and y"
            what += ", or null for a free component)" if allow_free else ")"
            raise self.fail(key, value, f"expected two {what}")
        components = []
        for i, item in enumerate(value):
            if item is None and allow_free:
                components.append(None)
            else:
                components.append(self.expression(item, f"{key}[{i}]"))
        return tuple(components)


def load_case(path: str | Path) -> Case:
    """Read and validate a case file.

    Raises
    ------
    CaseError
        If the file cannot be read or any key is missing, unknown, mistyped or out of range.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise CaseError(f"{path}: cannot read the case file ({_reason(error)})") from None
    return parse_case(text, source=path)


def parse_case(text: str, source: str | Path = "<case>") -> Case:
    """Validate the YAML ``text`` of a case; ``source`` names it in messages and anchors relative paths."""
    source = Path(source)
    r = _Reader(source.name)
    if len(text) > 10_000_000:
        raise CaseError(f"{source.name}: the case file is larger than 10 MB")
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or "invalid YAML"
        raise CaseError(f"{source.name}: not valid YAML{where}: {problem}") from None
    except RecursionError:
        raise CaseError(f"{source.name}: not valid YAML: nested too deeply") from None
    if not isinstance(data, dict):
        raise r.fail("", data, "expected a mapping with geometry, material, boundary and obstacle")

    top = r.mapping(
        data, "",
        ("title", "description", "geometry", "mesh", "material", "body_force",
         "boundary", "obstacle", "solver", "output", "exact"),
        required=("geometry", "material", "boundary", "obstacle"),
    )
    title = top.get("title", source.stem)
    if not isinstance(title, str):
        raise r.fail("title", title, "expected a string")
    if "description" in top and not isinstance(top["description"], str):
        raise r.fail("description", top["description"], "expected a string")

    geometry, part_names = _geometry(r, top["geometry"], source)
    mesh = _mesh_settings(r, top.get("mesh", {}), geometry)
    material = _material(r, top["material"])
    exact_displacement = _exact_displacement(r, top["exact"]) if "exact" in top else None
    body_force = _body_force(r, top.get("body_force"), exact_displacement is not None)
    parts = _boundary(r, top["boundary"], part_names, exact_displacement)
    obstacle = _obstacle(r, top["obstacle"])
    exact = None if exact_displacement is None else _exact_block(r, exact_displacement, material, obstacle)
    solver = _solver(r, top.get("solver", {}))
    output = _output(r, top.get("output", {}), source)
    return Case(
        source=source,
        text=text,
        digest=hashlib.sha256(text.encode("utf-8")).hexdigest(),
        title=title,
        geometry=geometry,
        mesh=mesh,
        material=material,
        body_force=body_force,
        parts=parts,
        obstacle=obstacle,
        solver=solver,
        output=output,
        exact=exact,
    )


# --------------------------------------------------------------------------- sections


def _geometry(r: _Reader, data: Any, source: Path) -> tuple[Geometry, tuple[str, ...] | None]:
    """The geometry and the part names it defines (None when only the mesh file knows them)."""
    kinds = ("rectangle", "polygon", "mesh_file")
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
        _check_extent(r, f"{key}.upper", np.array([lower, upper]))
        names = r.mapping(spec.get("names", {}), f"{key}.names", SIDES)
        side_names = {side: r.name(names.get(side, side), f"{key}.names.{side}") for side in SIDES}
        return RectangleGeometry(lower, upper, side_names), tuple(dict.fromkeys(side_names.values()))
    if kind == "polygon":
        spec = r.mapping(spec, key, ("vertices", "edges", "holes"), required=("vertices", "edges"))
        outer = _loop(r, spec["vertices"], spec["edges"], key)
        holes = []
        hole_list = spec.get("holes", [])
        if not isinstance(hole_list, list):
            raise r.fail(f"{key}.holes", hole_list, "expected a list of holes")
        for i, hole in enumerate(hole_list):
            holes.append(_hole(r, hole, f"{key}.holes[{i}]", outer))
        names = [*outer.edge_names]
        for hole in holes:
            names.extend(hole.edge_names)
        return PolygonGeometry(outer, tuple(holes)), tuple(dict.fromkeys(names))
    if not isinstance(spec, str) or not spec:
        raise r.fail(key, spec, "expected the path of a gmsh .msh file")
    path = Path(spec)
    if not path.is_absolute():
        path = source.parent / path
    if not path.is_file():
        raise r.fail(key, spec, f"no such file ({path})")
    return MeshFileGeometry(path), None


def _loop(r: _Reader, vertices: Any, edges: Any, key: str) -> Loop:
    if not isinstance(vertices, list) or len(vertices) < 2:
        raise r.fail(f"{key}.vertices", vertices, "expected a list of at least 2 points [x, y]")
    points = np.array([r.point(v, f"{key}.vertices[{i}]") for i, v in enumerate(vertices)])
    if not isinstance(edges, list) or len(edges) != len(points):
        raise r.fail(
            f"{key}.edges", edges,
            f"expected a list of {len(points)} edges (one per vertex: edge i runs from vertex i to i+1)",
        )
    names, arcs = [], []
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
        arc = r.mapping(edge["arc"], f"{ekey}.arc", ("center", "direction"), required=("center",))
        center = r.point(arc["center"], f"{ekey}.arc.center")
        direction = r.choice(arc.get("direction", "ccw"), f"{ekey}.arc.direction", ("ccw", "cw"))
        start, end = points[i], points[(i + 1) % len(points)]
        r0, r1 = np.hypot(*(start - center)), np.hypot(*(end - center))
        if r0 == 0 or abs(r0 - r1) > 1e-9 * max(r0, r1):
            raise r.fail(
                f"{ekey}.arc.center", list(center),
                f"must be equally far from the edge's end points (distances {r0:g} and {r1:g})",
            )
        arcs.append(Arc(center=center, ccw=direction == "ccw"))
    has_arc = any(a is not None for a in arcs)
    # The straight polygon through the vertices must be simple; with arcs the chords are
    # checked, which catches crossings but leaves bulges to the mesher's own checks.
    if len(points) >= 3 or not has_arc:
        problem = polygon_problems(points)
        if problem is not None and not (has_arc and problem.startswith("zero area")):
            raise r.fail(f"{key}.vertices", points.tolist(), problem)
    _check_extent(r, f"{key}.vertices", points)
    return Loop(vertices=points, edge_names=tuple(names), edge_arcs=tuple(arcs))


def _hole(r: _Reader, data: Any, key: str, outer: Loop) -> Loop:
    data = r.mapping(data, key, ("circle", "vertices", "edges", "name"))
    if "circle" in data:
        if "vertices" in data or "edges" in data:
            raise r.fail(key, data, "a hole is either a circle or a polygon (vertices and edges), not both")
        circle = r.mapping(data["circle"], f"{key}.circle", ("center", "radius"), required=("center", "radius"))
        center = r.point(circle["center"], f"{key}.circle.center")
        radius = r.number(circle["radius"], f"{key}.circle.radius", low=0, low_open=True)
        name = r.name(data.get("name", "hole"), f"{key}.name")
        loop = circle_loop(center, radius, name)
    else:
        if "vertices" not in data or "edges" not in data:
            raise r.fail(key, data, "expected circle: {center, radius} or vertices and edges")
        if "name" in data:
            raise r.fail(f"{key}.name", data["name"], "a polygonal hole names each of its edges instead")
        loop = _loop(r, data["vertices"], data["edges"], key)
    inside = _points_inside(outer.vertices, loop.vertices)
    if not inside.all():
        raise r.fail(key, loop.vertices[~inside][0].tolist(), "hole vertex outside the outer polygon")
    return loop


def _check_extent(r: _Reader, key: str, points: np.ndarray) -> None:
    """The body must be resolvable in float64: both sides of its bounding box at least
    1/SCALE_LIMIT and 1e-9 of its distance from the origin (or the mesh degenerates)."""
    span = np.ptp(points, axis=0)
    far = float(np.abs(points).max())
    least = max(1.0 / SCALE_LIMIT, 1e-9 * far)
    if span.min() < least and not (len(points) < 3 and span.max() >= least):
        raise r.fail(key, points.tolist(), f"the body's extent {span.min():.3g} is too small: it must be at "
                     f"least {least:.3g} (1e-50, and 1e-9 of the distance from the origin)")


def _points_inside(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Even-odd rule, vectorised over points and edges."""
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    px, py = points[:, None, 0], points[:, None, 1]
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cross = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
    return (crosses & (px < x_cross)).sum(axis=1) % 2 == 1


def _mesh_settings(r: _Reader, data: Any, geometry: Geometry) -> MeshSettings:
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
        if extent is not None and size < extent / MAX_DIVISIONS:
            raise r.fail("mesh.size", size, f"must be at least the body's extent / {MAX_DIVISIONS} = "
                         f"{extent / MAX_DIVISIONS:g} (use mesh.refine for finer meshes)")
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
        least = _extent(geometry) / MAX_DIVISIONS
        contact_size = r.number(data["contact_size"], "mesh.contact_size", low=least, high=size,
                                expected=f"must be in [extent / {MAX_DIVISIONS} = {least:g}, mesh.size = {size:g}]")
    elif "grading" in data:
        raise r.fail("mesh.grading", data["grading"], "only meaningful with mesh.contact_size")
    grading = r.number(data.get("grading", 0.25), "mesh.grading", low=0.01, high=10.0,
                       expected="must be in [0.01, 10] (growth of h per unit distance from the contact parts)")
    return MeshSettings(divisions=divisions, size=size, diagonal=diagonal, refine=refine, min_angle=min_angle,
                        contact_size=contact_size, grading=grading)


def _extent(geometry: Geometry) -> float | None:
    if isinstance(geometry, RectangleGeometry):
        return max(geometry.upper[0] - geometry.lower[0], geometry.upper[1] - geometry.lower[1])
    if isinstance(geometry, PolygonGeometry):
        v = geometry.outer.vertices
        span = np.ptp(v, axis=0).max()
        radii = [np.hypot(*(v[i] - a.center)) for i, a in enumerate(geometry.outer.edge_arcs) if a is not None]
        return float(max([span, *(2 * rr for rr in radii)]))
    return None


def _material(r: _Reader, data: Any) -> Material:
    data = r.mapping(data, "material", ("E", "nu", "lambda", "mu", "plane"))
    plane = r.choice(data.get("plane", "strain"), "material.plane", ("strain", "stress"))
    has_young = "E" in data or "nu" in data
    has_lame = "lambda" in data or "mu" in data
    if has_young == has_lame:
        raise r.fail("material", data, "give either E and nu, or lambda and mu")
    if has_young:
        for key in ("E", "nu"):
            if key not in data:
                raise CaseError(f"{r.filename}: material.{key}: missing (required with {'nu' if key == 'E' else 'E'})")
        young = r.number(data["E"], "material.E", low=0, low_open=True, expected="must be > 0")
        if not 1 / SCALE_LIMIT <= young <= SCALE_LIMIT:
            raise r.fail("material.E", young, f"must be in [{1 / SCALE_LIMIT:g}, {SCALE_LIMIT:g}] (use other units)")
        nu = r.number(data["nu"], "material.nu", low=0, high=0.5, high_open=True, expected="must be in [0, 0.5)")
        lam = young * nu / ((1 + nu) * (1 - 2 * nu))
        mu = young / (2 * (1 + nu))
    else:
        for key in ("lambda", "mu"):
            if key not in data:
                raise CaseError(f"{r.filename}: material.{key}: missing (required with {'mu' if key == 'lambda' else 'lambda'})")
        mu = r.number(data["mu"], "material.mu", low=0, low_open=True, expected="must be > 0")
        if not 1 / SCALE_LIMIT <= mu <= SCALE_LIMIT:
            raise r.fail("material.mu", mu, f"must be in [{1 / SCALE_LIMIT:g}, {SCALE_LIMIT:g}] (use other units)")
        lam = r.number(data["lambda"], "material.lambda", low=0, expected="must be >= 0")
        young = mu * (3 * lam + 2 * mu) / (lam + mu)
        nu = lam / (2 * (lam + mu))
    if lam > MAX_LAME_RATIO * mu:
        key = "material.nu" if has_young else "material.lambda"
        raise r.fail(key, nu if has_young else lam,
                     f"lambda/mu = {lam / mu:.3g} exceeds {MAX_LAME_RATIO:g} (nu > 0.499999995): P1 triangles "
                     "lock and the stiffness is singular to round-off; the material is too close to incompressible")
    return Material(lame_lambda=lam, lame_mu=mu, plane=plane, young=young, poisson=nu)


def _exact_displacement(r: _Reader, data: Any) -> tuple[Expression, Expression]:
    data = r.mapping(data, "exact", ("displacement",), required=("displacement",))
    return r.vector_field(data["displacement"], "exact.displacement")  # type: ignore[return-value]


def _exact_block(r: _Reader, displacement: tuple[Expression, Expression], material: Material,
                 obstacle: Obstacle) -> ExactBlock:
    """Derive the exact fields once, with the plane law; refuse what sympy cannot differentiate or evaluate."""
    from contactfem.assembly import Elasticity
    from contactfem.exact import ExactSolution

    law = Elasticity.from_lame(material.lame_lambda, material.lame_mu, material.plane)
    try:
        solution = ExactSolution.from_expressions(displacement, law.lam, law.mu, obstacle.normal)
    except ExpressionError as error:
        texts = [e.text for e in displacement]
        raise r.fail("exact.displacement", texts, f"cannot derive the stress and body force: {error}") from None
    return ExactBlock(displacement=displacement, solution=solution)


def _body_force(r: _Reader, value: Any, has_exact: bool) -> tuple[Expression, Expression] | None:
    """The body force; with an exact: block it is derived (f = −div σ), so only `exact` or nothing is accepted."""
    if has_exact:
        if value is not None and value != EXACT:
            raise r.fail(
                "body_force", value,
                "with an exact: block the body force is derived from exact.displacement (f = -div sigma); "
                "give body_force: exact or leave it out",
            )
        return None
    if value == EXACT:
        raise r.fail("body_force", value, "'exact' needs an exact: block with the displacement")
    if value is None:
        return None
    return r.vector_field(value, "body_force")  # type: ignore[return-value]


def _boundary(r: _Reader, data: Any, part_names: tuple[str, ...] | None,
              exact: tuple[Expression, Expression] | None = None) -> tuple[BoundaryPart, ...]:
    if not isinstance(data, dict) or not data:
        raise r.fail("boundary", data, "expected a mapping of boundary part names to conditions")
    parts = []
    for name, spec in data.items():
        key = f"boundary.{name}"
        if not isinstance(name, str):
            raise r.fail("boundary", name, "part names must be strings")
        if part_names is not None and name not in part_names:
            raise CaseError(
                f"{r.filename}: {key}: the geometry has no part named {name!r}; "
                f"its parts are {', '.join(part_names)}"
            )
        if isinstance(spec, str):
            parts.append(BoundaryPart(name, r.choice(spec, key, PART_KINDS)))
            continue
        if not isinstance(spec, dict) or len(spec) != 1:
            raise r.fail(
                key, spec,
                f"expected one of {', '.join(PART_KINDS)}, or a mapping with one of {', '.join(PART_LOADS)}",
            )
        (kind, value), = spec.items()
        if kind not in PART_LOADS:
            raise CaseError(f"{r.filename}: {key}.{kind}: unknown key; expected one of {', '.join(PART_LOADS)}")
        if value == EXACT:
            if kind == "pressure":
                raise r.fail(f"{key}.pressure", value, "'exact' is for traction and displacement; use {traction: exact}")
            if exact is None:
                raise r.fail(f"{key}.{kind}", value, "'exact' needs an exact: block with the displacement")
            parts.append(BoundaryPart(name, kind, exact if kind == "displacement" else (), exact=True))
            continue
        if kind == "pressure":
            values: tuple[Expression | None, ...] = (r.expression(value, f"{key}.pressure"),)
        else:
            values = r.vector_field(value, f"{key}.{kind}", allow_free=kind == "displacement")
            if kind == "displacement" and all(v is None for v in values):
                raise r.fail(f"{key}.displacement", value, "at least one component must be prescribed")
        parts.append(BoundaryPart(name, kind, values))
    if not any(p.is_dirichlet or p.kind == "symmetry" for p in parts):
        raise CaseError(
            f"{r.filename}: boundary: no clamped, displacement or symmetry part; the body could move "
            "rigidly, so the problem is ill-posed (give at least one part: clamped)"
        )
    if not any(p.kind == "contact" for p in parts):
        raise CaseError(f"{r.filename}: boundary: no contact part; mark the part that may touch the obstacle: contact")
    return tuple(parts)


def _obstacle(r: _Reader, data: Any) -> Obstacle:
    data = r.mapping(data, "obstacle", ("point", "normal", "points"))
    if "points" in data:
        if "point" in data or "normal" in data:
            raise r.fail("obstacle", data, "give either point and normal, or points")
        points = data["points"]
        if not isinstance(points, list) or len(points) != 2:
            raise r.fail("obstacle.points", points, "expected two points [[x0, y0], [x1, y1]] on the obstacle's surface")
        p0 = np.array(r.point(points[0], "obstacle.points[0]"))
        p1 = np.array(r.point(points[1], "obstacle.points[1]"))
        d = p1 - p0
        length = np.hypot(*d)
        if not length > 0:
            raise r.fail("obstacle.points", points, "the two points must differ")
        # The obstacle lies to the right of the line walked from the first point to the second.
        normal = (d[1] / length, -d[0] / length)
        return Obstacle(point=tuple(p0), normal=normal)
    for key in ("point", "normal"):
        if key not in data:
            raise CaseError(f"{r.filename}: obstacle.{key}: missing (give point and normal, or points)")
    point = r.point(data["point"], "obstacle.point")
    normal = np.array(r.point(data["normal"], "obstacle.normal"))
    length = np.hypot(*normal)
    if abs(length - 1.0) > 1e-6:
        raise r.fail("obstacle.normal", normal.tolist(), "expected a unit vector pointing into the obstacle")
    return Obstacle(point=point, normal=tuple(normal / length))


def _solver(r: _Reader, data: Any) -> SolverSettings:
    data = r.mapping(data if data is not None else {}, "solver",
                     ("method", "tolerance", "max_iterations", "c", "backend"))
    method = r.choice(data.get("method", "positive"), "solver.method", METHOD_NAMES)
    tolerance = r.number(data.get("tolerance", 1e-10), "solver.tolerance", low=1e-15, high=1e-2,
                         expected="must be in [1e-15, 1e-2]")
    max_iterations = r.integer(data.get("max_iterations", 50), "solver.max_iterations", low=1, high=10_000)
    c = data.get("c", "auto")
    c = None if c == "auto" else r.number(c, "solver.c", low=1 / SCALE_LIMIT, high=SCALE_LIMIT,
                                          expected=f"must be in [{1 / SCALE_LIMIT:g}, {SCALE_LIMIT:g}] or auto")
    backend = r.choice(data.get("backend", "auto"), "solver.backend", BACKEND_CHOICES)
    return SolverSettings(method=method, tolerance=tolerance, max_iterations=max_iterations, c=c, backend=backend)


def _output(r: _Reader, data: Any, source: Path) -> OutputSettings:
    data = r.mapping(data if data is not None else {}, "output", ("directory", "files"))
    directory = data.get("directory", f"results/{source.stem}")
    if not isinstance(directory, str) or not directory.strip():
        raise r.fail("output.directory", directory, "expected a directory path")
    files = data.get("files", list(DEFAULT_OUTPUT_FILES))
    if not isinstance(files, list) or not files:
        raise r.fail("output.files", files, f"expected a non-empty list from {', '.join(OUTPUT_FILES)}")
    chosen = tuple(r.choice(f, f"output.files[{i}]", OUTPUT_FILES) for i, f in enumerate(files))
    return OutputSettings(directory=Path(directory), files=tuple(dict.fromkeys(chosen)))


# --------------------------------------------------------------------------- helpers


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _show(value: Any) -> str:
    text = repr(value) if isinstance(value, str) else str(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _range_text(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"must be in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"must be {'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f"must be {'<' if high_open else '<='} {high:g}"
    return ""


def _reason(error: BaseException) -> str:
    return getattr(error, "strerror", None) or str(error)
