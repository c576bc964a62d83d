"""Read a YAML case file and validate it, once, into a frozen :class:`Case`.

Every refusal is a :class:`CaseError` whose message names the file, the key, the value
and what was expected, e.g. ``beam.yaml: material.nu = 0.5: must be in [0, 0.5)``.
The format is documented in README.md ("The case file"); ``cases/`` holds commented examples.

What is read is bounded before it is built, so that no file makes the reader run long or
take much memory, and every refusal stays one line:

- the file must be a regular file (not a directory, FIFO or device) of at most
  :data:`MAX_CASE_BYTES`; at most that many bytes plus one are ever read from it;
- it must be UTF-8 (a leading BOM is allowed) holding one YAML document, a mapping;
- the YAML is composed node by node under a count: at most :data:`MAX_YAML_VALUES` values
  and :data:`MAX_YAML_DEPTH` levels of nesting, with every alias counted at each of its
  uses, as the data would be once expanded. Anchors and aliases are allowed (one traction
  given to several parts), but an alias bomb ("billion laughs": a few hundred bytes that
  expand to billions of values) or an alias to its own enclosing node is refused while
  composing, before any Python object is built;
- a key may appear only once in a mapping (YAML's merge key ``<<`` may still be overridden);
- paths (the case file, ``geometry.mesh_file``, ``output.directory``) are checked as
  text against the file system's limits (:data:`NAME_MAX` bytes per component,
  :data:`PATH_MAX` in all) and for NUL characters before anything opens them;
- a polygon geometry has at most :data:`MAX_POLYGON_VERTICES` vertices over all its loops;
  a profile or outline file (``geometry.profile.file``, ``geometry.polygon.file``) is read
  like the case file, regular files of at most :data:`MAX_DATA_FILE_BYTES` in all, holding
  at most that many points.
"""

from __future__ import annotations

import difflib
import hashlib
import math
import os
import re
import stat
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from contactfem.errors import CaseError, MeshError
from contactfem.expressions import Expression, ExpressionError, compile_expression
from contactfem.io.registry import DEFAULT_FORMATS, FORMAT_NAMES, missing_needs
from contactfem.linalg import BACKEND_CHOICES
from contactfem.case.crossings import CLOCKWISE, first_crossing_among, polygon_problems
from contactfem.case.loops import Arc, Loop, circle_loop, coordinate_span, loop_outline
from contactfem.methods import METHOD_NAMES

if TYPE_CHECKING:
    from contactfem.exact import ExactSolution

PART_KINDS = ("clamped", "free", "contact", "symmetry")
PART_LOADS = ("traction", "pressure", "displacement", "platen")
#: How a platen is driven: the force it presses with, or how far it advances into the body.
PLATEN_CONTROLS = ("force", "displacement")
#: The most steps a load path may have (each is a solve and a time step of the outputs).
MAX_LOAD_STEPS = 1000
DIAGONALS = ("right", "left", "alternate", "crossed")
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
#: The largest case file, in bytes. Cases are a few kB (a polygon of 2000 vertices is
#: under 100 kB; longer outlines come from an outline or profile file); the bound keeps a mistaken argument (a log, /dev/zero) from
#: being read whole.
MAX_CASE_BYTES = 1 << 20
#: The most YAML values (scalars, lists and mappings) a case may hold, each alias counted
#: at every use. A full-size polygon needs under 10 000.
MAX_YAML_VALUES = 100_000
#: The deepest nesting of YAML values; the deepest key of the format
#: (geometry.polygon.holes[i].edges[j].arc.center[k]) is 10 levels down.
MAX_YAML_DEPTH = 32
#: The most vertices of a polygon geometry, its holes included, or of a profile's outline.
#: The simplicity check is a sweep, O(k log k) in time and O(k) in memory (about 2 s and
#: 0.5 GB at this bound); inline YAML lists stay far below it (MAX_YAML_VALUES), a profile
#: or an outline read from a file may reach it.
MAX_POLYGON_VERTICES = 1_000_000


def _os_limit(name: str, fallback: int) -> int:
    try:
        value = os.pathconf("/", name)
    except (AttributeError, OSError, ValueError):
        return fallback
    return value if isinstance(value, int) and value > 0 else fallback


#: Longest file name (one path component), in bytes of the file-system encoding.
NAME_MAX = _os_limit("PC_NAME_MAX", 255)
#: Longest path, in bytes, including the terminating NUL of the system call.
PATH_MAX = _os_limit("PC_PATH_MAX", 4096)
#: Room kept in an output directory's path for what is written under it: the staging
#: sibling ``.tmp-<pid>-<8 hex>.<name>`` adds up to 22 bytes to the last component, and the
#: files inside it (``.tmp-<pid>-<8 hex>.solution-xdmf.h5`` and the like) about 64 bytes.
OUTPUT_NAME_RESERVE = 32
OUTPUT_PATH_RESERVE = 128


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

    ``kind`` is clamped | free | contact | symmetry | traction | pressure | displacement |
    platen. ``values`` holds the two components of a traction or a displacement (None for
    a displacement component left free), or the single pressure. ``exact`` marks
    ``{traction: exact}`` (``values`` empty: σ(u_exact) n depends on the edge's normal)
    and ``{displacement: exact}`` (``values`` are the exact block's two expressions).
    ``platen`` is the drive of a platen part.
    """

    name: str
    kind: str
    values: tuple[Expression | None, ...] = ()
    exact: bool = False
    platen: "Platen | None" = None

    @property
    def label(self) -> str:
        """The kind as the case file says it, e.g. ``traction (exact)`` or ``platen (force 2000)``."""
        if self.platen is not None:
            return f"{self.kind} ({self.platen.control} {self.platen.value:g})"
        return f"{self.kind} (exact)" if self.exact else self.kind

    @property
    def is_dirichlet(self) -> bool:
        return self.kind in ("clamped", "displacement")

    @property
    def is_support(self) -> bool:
        """Whether the part holds the body somewhere (a prescribed motion, a symmetry line, a platen)."""
        return self.is_dirichlet or self.kind in ("symmetry", "platen")


@dataclass(frozen=True)
class Platen:
    """A rigid, frictionless platen on a straight boundary part: the part's normal
    displacement is one unknown δ (its advance into the body, along the inward normal),
    its tangential motion free. ``control`` is ``force`` (δ unknown, the platen presses
    with ``value`` per unit thickness; negative pulls) or ``displacement`` (δ = ``value``).
    """

    control: str
    value: float


@dataclass(frozen=True)
class LoadPath:
    """Load factors applied in turn (``factors``, each > 0): every load, prescribed
    displacement and platen drive of the case is multiplied by the factor; the obstacle
    stays where it is."""

    factors: tuple[float, ...]


@dataclass(frozen=True)
class Obstacle:
    """The rigid half-plane {p : (p − point)·normal ≥ 0}; ``normal`` is a unit vector pointing into it.

    ``ends`` are the two end points of a finite obstacle (a segment: a table, a punch), None
    for an infinite one: only the part of the surface between them exists.
    """

    point: tuple[float, float]
    normal: tuple[float, float]
    ends: tuple[tuple[float, float], tuple[float, float]] | None = None


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
    max_iterations: int | None  # None: auto (see contactfem.kernel.default_max_iterations)
    c: float | None
    backend: str


@dataclass(frozen=True)
class OutputSettings:
    directory: Path
    files: tuple[str, ...]


#: Stress units named by their (force, length) pair; any other pair is written force/length².
_STRESS_UNITS = {("N", "m"): "Pa", ("kN", "m"): "kPa", ("MN", "m"): "MPa", ("N", "mm"): "MPa",
                 ("kN", "mm"): "GPa", ("lbf", "in"): "psi", ("kip", "in"): "ksi"}


@dataclass(frozen=True)
class Units:
    """The case's unit system, used for labels (pictures, report.json, VTU metadata); the
    solver itself is unit-free. Forces are per unit thickness in 2D."""

    length: str = "m"
    force: str = "N"

    @property
    def stress(self) -> str:
        """Stresses and contact pressures: force / length²."""
        return _STRESS_UNITS.get((self.force, self.length), f"{self.force}/{self.length}²")

    def to_dict(self) -> dict[str, str]:
        return {"length": self.length, "force": self.force, "stress": self.stress}


@dataclass(frozen=True)
class Case:
    """A validated case. ``text`` is the file as read, ``digest`` the SHA-256 of it and of the data files it reads.

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
    units: Units = Units()
    load_path: LoadPath | None = None
    #: The data files the geometry was read from (a profile, an outline and its holes' files,
    #: a mesh), in the order read.
    data_files: tuple[Path, ...] = ()

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
        #: The SHA-256 of each data file the case reads (a profile, an outline, a mesh),
        #: hashed with its text, and their paths.
        self.inputs: list[bytes] = []
        self.input_paths: list[Path] = []
        #: Bytes read from data files so far, against MAX_DATA_FILE_BYTES for all of them.
        self.data_bytes = 0

    def fail(self, key: str, value: Any, expected: str) -> CaseError:
        shown = _show(value)
        where = f"{key} = {shown}" if key else shown
        return CaseError(f"{self.filename}: {where}: {expected}")

    def mapping(self, data: Any, key: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, data, "expected a mapping of keys to values")
        for name in data:
            if not isinstance(name, str) or name not in allowed:
                shown = shortened(name if isinstance(name, str) else _show(name), 64)
                close = difflib.get_close_matches(name, allowed, n=1) if isinstance(name, str) else []
                hint = f" (did you mean {close[0]}?)" if close else ""
                raise CaseError(
                    f"{self.filename}: {_join(key, shown)}: unknown key{hint}; "
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

    NAME_EXPECTED = "a part name (a non-empty string of at most 64 printable characters)"

    @staticmethod
    def is_name(value: Any) -> bool:
        return isinstance(value, str) and bool(value.strip()) and len(value) <= 64 and value.isprintable()

    def name(self, value: Any, key: str) -> str:
        if not self.is_name(value):
            raise self.fail(key, value, f"expected {self.NAME_EXPECTED}")
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

    At most :data:`MAX_CASE_BYTES` + 1 bytes are read; directories, FIFOs and devices are
    refused from their status, before anything is read (a FIFO is opened non-blocking).

    Raises
    ------
    CaseError
        If the file cannot be read or any key is missing, unknown, mistyped or out of range.
    """
    path = Path(path)
    return parse_case(read_text_file(path), source=path)


def read_text_file(path: str | os.PathLike[str], what: str = "case") -> str:
    """A YAML input (a case or a sweep file) as text: its path checked as text, a regular
    file, at most :data:`MAX_CASE_BYTES` read, UTF-8; refusals say which ``what`` file."""
    path = Path(path)
    shown = shortened(str(path))
    problem = path_problem(path)
    if problem is not None:
        raise CaseError(f"{shown}: the {what} file's path {problem}")
    data = _read_bounded(path, shown, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise CaseError(f"{shortened(path.name)}: {_not_utf8(data, error)}") from None


def path_problem(path: str | os.PathLike[str], *, name_reserve: int = 0, path_reserve: int = 0) -> str | None:
    """Why the file system would refuse ``path`` before looking at it, or None.

    Checked as text only (nothing is opened or looked up): no NUL character, encodable as
    a file name, every component at most :data:`NAME_MAX` bytes (the last one at most
    ``NAME_MAX - name_reserve``) and the whole at most ``PATH_MAX - 1 - path_reserve``
    bytes. The result completes "the path ...", e.g. "contains a NUL character".
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        raw = text
    else:
        if "\x00" in text:
            return "contains a NUL character"
        try:
            raw = os.fsencode(text)
        except UnicodeEncodeError:
            return "cannot be encoded as a file name (it holds a lone surrogate)"
    if b"\x00" in raw:
        return "contains a NUL character"
    separators = {os.sep, os.altsep} - {None}
    for separator in separators - {"/"}:
        raw = raw.replace(os.fsencode(separator), b"/")
    parts = raw.split(b"/")
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        limit = NAME_MAX - (name_reserve if last else 0)
        if len(part) > limit:
            kept = f" ({NAME_MAX} less {name_reserve} kept for the names made from it)" if last and name_reserve else ""
            return (f"has a component of {len(part)} bytes ({shortened(os.fsdecode(part), 40)!r}); "
                    f"expected at most {limit} bytes per file or directory name{kept}")
    limit = PATH_MAX - 1 - path_reserve
    if len(raw) > limit:
        kept = f" ({PATH_MAX - 1} less {path_reserve} kept for the files written under it)" if path_reserve else ""
        return f"is {len(raw)} bytes long; expected at most {limit} bytes{kept}"
    return None


def _read_bounded(path: Path, shown: str, what: str = "case") -> bytes:
    """The bytes of a regular file of at most MAX_CASE_BYTES, reading no more than one byte past it."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError) as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({_reason(error)})") from None
    _refuse_special(mode, shown, what)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        fd = os.open(path, flags)
    except (OSError, ValueError) as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({_reason(error)})") from None
    chunks, size = [], 0
    try:
        info = os.fstat(fd)  # the file opened, which may differ from the one looked at
        _refuse_special(info.st_mode, shown, what)
        if info.st_size > MAX_CASE_BYTES:
            size = info.st_size
        while size <= MAX_CASE_BYTES:
            chunk = os.read(fd, MAX_CASE_BYTES + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise CaseError(f"{shown}: cannot read the {what} file ({_reason(error)})") from None
    finally:
        os.close(fd)
    if size > MAX_CASE_BYTES:
        raise CaseError(f"{shown}: the {what} file is larger than {MAX_CASE_BYTES} bytes (1 MiB); "
                        f"expected a YAML {what} file of a few kB" +
                        (" (long outlines and profiles go in files of their own: geometry.polygon.file, "
                         "geometry.profile.file)" if what == "case" else ""))
    return b"".join(chunks)


def _refuse_special(mode: int, shown: str, what: str = "case") -> None:
    if stat.S_ISDIR(mode):
        raise CaseError(f"{shown}: is a directory; expected a YAML {what} file")
    if not stat.S_ISREG(mode):
        kinds = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                 (stat.S_ISSOCK, "a socket"))
        kind = next((name for test, name in kinds if test(mode)), "not a regular file")
        raise CaseError(f"{shown}: is {kind}, not a regular file; expected a YAML {what} file")


def _not_utf8(data: bytes, error: UnicodeDecodeError) -> str:
    for bom, encoding in ((b"\xff\xfe\x00\x00", "UTF-32"), (b"\x00\x00\xfe\xff", "UTF-32"),
                          (b"\xff\xfe", "UTF-16"), (b"\xfe\xff", "UTF-16")):
        if data.startswith(bom):
            return f"the case file is {encoding} (it starts with a {encoding} byte order mark); expected UTF-8"
    line = data.count(b"\n", 0, error.start) + 1
    column = error.start - (data.rfind(b"\n", 0, error.start) + 1) + 1
    return (f"byte 0x{data[error.start]:02x} at line {line}, column {column} is not UTF-8 ({error.reason}); "
            "expected a UTF-8 text file")


def parse_case(text: str, source: str | Path = "<case>") -> Case:
    """Validate the YAML ``text`` of a case; ``source`` names it in messages and anchors relative paths."""
    source = Path(source)
    r = _Reader(shortened(source.name))
    if not isinstance(text, str):
        raise CaseError(f"{r.filename}: expected the case as text, got {type(text).__name__}")
    if len(text) > MAX_CASE_BYTES:
        raise CaseError(f"{r.filename}: the case file is larger than {MAX_CASE_BYTES} bytes (1 MiB)")
    try:
        encoded = text.encode("utf-8")
    except UnicodeEncodeError as error:
        line = text.count("\n", 0, error.start) + 1
        raise CaseError(f"{r.filename}: line {line}: {text[error.start]!r} is a lone surrogate, "
                        "not a character; expected Unicode text") from None
    if len(encoded) > MAX_CASE_BYTES:
        raise CaseError(f"{r.filename}: the case file is larger than {MAX_CASE_BYTES} bytes (1 MiB)")
    data = _load_yaml(text, r.filename)
    if data is None:
        raise CaseError(f"{r.filename}: the case file is empty (or only comments); expected a mapping "
                        "with geometry, material, boundary and obstacle")
    if not isinstance(data, dict):
        raise r.fail("", data, "expected a mapping with geometry, material, boundary and obstacle")

    top = r.mapping(
        data, "",
        ("title", "description", "geometry", "mesh", "material", "body_force",
         "boundary", "obstacle", "solver", "output", "exact", "units", "load_path"),
        required=("geometry", "material", "boundary", "obstacle"),
    )
    title = top.get("title", source.stem)
    if not isinstance(title, str):
        raise r.fail("title", title, "expected a string")
    if "title" in top and (len(title) > 200 or not title.isprintable()):
        raise r.fail("title", title, "expected one line of at most 200 printable characters")
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
    units = _units(r, top.get("units", {}))
    load_path = _load_path(r, top["load_path"]) if "load_path" in top else None
    if load_path is not None and exact is not None:
        raise r.fail("load_path", top["load_path"], "a manufactured solution (exact:) is the answer to one load; "
                                                    "drop load_path or the exact: block")
    if load_path is not None and "path" not in output.files:
        files = [name for name in output.files if name != "json"]
        output = replace(output, files=(*files, "path", *(("json",) if "json" in output.files else ())))
    return Case(
        source=source,
        text=text,
        digest=_digest(encoded, r.inputs),
        data_files=tuple(r.input_paths),
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
        units=units,
        load_path=load_path,
    )


# --------------------------------------------------------------------------- YAML


try:  # libyaml's parser: the events in C, about 20 times faster than PyYAML's own
    from yaml._yaml import CParser as _Events
except ImportError:  # pragma: no cover - PyYAML built without libyaml
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Events(Reader, Scanner, Parser):  # type: ignore[no-redef]
        def __init__(self, stream: str) -> None:
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)


class _Limit(Exception):
    """Raised from inside the composer: the message, with the file name still to prepend."""


class _CaseLoader(yaml.composer.Composer, _Events, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
    """PyYAML's safe loader, with composition counted and mappings checked for repeated keys.

    Each node is composed with its expanded size (the values it stands for once every
    alias in it is replaced by a copy) and height; an alias adds its target's size to the
    running count at every use. The count is the size of the document as any consumer
    walking it would see it, and composing stops as soon as it passes MAX_YAML_VALUES, or
    the expanded nesting passes MAX_YAML_DEPTH. An alias to a node still being composed
    (a recursive structure) is refused: its target has no size yet.
    """

    def __init__(self, text: str) -> None:
        _Events.__init__(self, text)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self._measure: dict[int, tuple[int, int]] = {}  # id(node) -> (expanded values, height)
        self._values = 0
        self._path: list[str] = []
        self._mapping_paths: dict[int, str] = {}
        self.keys_at: dict[tuple[int, int], str] = {}  # (line, column) where a node starts -> its key path

    def _key(self) -> str:
        return "".join(self._path).lstrip(".")

    def _where(self) -> str:
        return self._key() or "the document"

    def compose_node(self, parent: Any, index: Any) -> Any:
        self._path.append(_path_step(parent, index))
        try:
            if self.check_event(yaml.AliasEvent):
                return self._compose_alias(parent, index)
            if len(self._path) > MAX_YAML_DEPTH:
                raise _Limit(f"{self._where()}: nested more than {MAX_YAML_DEPTH} levels deep (line "
                             f"{self.peek_event().start_mark.line + 1}); expected the case format's few levels")
            self._values += 1
            if self._values > MAX_YAML_VALUES:
                where = self._where()
                # A long outline or profile listed inline is what reaches the bound in practice.
                hint = (" (list a long outline in a file: geometry.polygon.file, or geometry.profile.file)"
                        if where.startswith("geometry.") else "")
                raise _Limit(f"{where}: the document holds more than {MAX_YAML_VALUES} values (line "
                             f"{self.peek_event().start_mark.line + 1}); expected a case of at most that many{hint}")
            start = self.peek_event().start_mark
            self.keys_at.setdefault((start.line, start.column), self._key())
            node = super().compose_node(parent, index)
            if isinstance(node, yaml.ScalarNode):
                self._measure[id(node)] = (1, 1)
                try:
                    node.value.encode("utf-8")
                except UnicodeEncodeError:
                    raise _Limit(f"{self._where()}: line {node.start_mark.line + 1}: a lone surrogate escape "
                                 "is not a character; expected Unicode text") from None
                return node
            is_mapping = isinstance(node, yaml.MappingNode)
            children = [c for pair in node.value for c in pair] if is_mapping else node.value
            sizes = [self._measure[id(c)] for c in children]
            self._measure[id(node)] = (1 + sum(n for n, _ in sizes), 1 + max((h for _, h in sizes), default=0))
            return node
        finally:
            self._path.pop()

    def compose_mapping_node(self, anchor: Any) -> Any:
        path = self._key()
        node = super().compose_mapping_node(anchor)
        self._mapping_paths[id(node)] = path
        return node

    def _compose_alias(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        target = self.anchors.get(event.anchor)
        if target is not None and id(target) not in self._measure:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: the "
                         "alias refers to a node that contains it; expected a value that does not contain itself")
        node = super().compose_node(parent, index)  # the target; refuses an undefined alias
        size, height = self._measure[id(node)]
        self._values += size
        if self._values > MAX_YAML_VALUES:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: with "
                         f"its aliases expanded the document holds more than {MAX_YAML_VALUES} values; expected at "
                         "most that many (an alias counts as a copy at every use)")
        if len(self._path) - 1 + height > MAX_YAML_DEPTH:
            raise _Limit(f"{self._where()} = *{shortened(event.anchor, 40)}: line {event.start_mark.line + 1}: with "
                         f"its aliases expanded the document is nested more than {MAX_YAML_DEPTH} levels deep; "
                         "expected the case format's few levels")
        return node

    def construct_yaml_int(self, node: Any) -> Any:
        # int() of a long decimal text is quadratic (Python refuses past 4300 digits) and a
        # sexagesimal one (1:2:3) is parsed digit group by digit group: no coordinate needs 100.
        if len(str(node.value)) > 100:
            where = self.keys_at.get((node.start_mark.line, node.start_mark.column)) or "the document"
            raise _Limit(f"{where} = {shortened(str(node.value), 40)}: line {node.start_mark.line + 1}: an integer of "
                         f"{len(str(node.value))} characters; expected a number of at most 100")
        return super().construct_yaml_int(node)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, Any] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:
                    continue  # unhashable: PyYAML refuses it below
                if first is not key_node:
                    where = _join(self._mapping_paths.get(id(node), ""), shortened(str(key), 64))
                    raise _Limit(f"{where}: the key appears twice in one mapping (lines {first.start_mark.line + 1} "
                                 f"and {key_node.start_mark.line + 1}); expected each key once")
        return super().construct_mapping(node, deep=deep)


_CaseLoader.add_constructor("tag:yaml.org,2002:int", _CaseLoader.construct_yaml_int)


def _path_step(parent: Any, index: Any) -> str:
    """The key path step to a node composed under ``parent`` at ``index`` (PyYAML's resolver arguments)."""
    if isinstance(parent, yaml.SequenceNode):
        return f"[{index}]"
    if isinstance(parent, yaml.MappingNode):
        if index is None:
            return ".<key>"
        if isinstance(index, yaml.ScalarNode):
            return "." + shortened(str(index.value), 64)
        return ".<key>"
    return ""


def _load_yaml(text: str, filename: str) -> Any:
    """One YAML document of ``text`` as Python data, counted while composed (see :class:`_CaseLoader`)."""
    loader = _CaseLoader(text)
    try:
        return loader.get_single_data()
    except _Limit as limit:
        raise CaseError(f"{filename}: {limit}") from None
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        key = loader.keys_at.get((mark.line, mark.column)) if mark is not None else None
        raise CaseError(f"{filename}: {key + ': ' if key else ''}{_yaml_problem(error, text)}") from None
    except RecursionError:
        raise CaseError(f"{filename}: not valid YAML: nested too deeply") from None
    finally:
        loader.dispose()


def _yaml_problem(error: yaml.YAMLError, text: str) -> str:
    """A one-line reason for PyYAML's error, with the line and column where it has them."""
    character = getattr(error, "character", None)  # a ReaderError: where in the text is not kept
    if isinstance(character, int):
        at = text.find(chr(character))
        where = ""
        if at >= 0:
            line = text.count("\n", 0, at) + 1
            where = f" at line {line}, column {at - (text.rfind(chr(10), 0, at) + 1) + 1}"
        return (f"not valid YAML{where}: character U+{character:04X} is not allowed in YAML text "
                "(control characters must be written as escapes in double quotes)")
    mark = getattr(error, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    problem = getattr(error, "problem", None) or str(error).splitlines()[0] or "invalid YAML"
    context = getattr(error, "context", None)
    if context == "expected a single document in the stream":
        return (f"holds more than one YAML document (another one starts{where}); "
                "expected a single mapping")
    if mark is not None:
        lines = text.split("\n")
        if mark.line < len(lines) and "\t" in lines[mark.line][: mark.column + 1]:
            return f"not valid YAML{where}: {problem} (a tab: YAML indents with spaces only)"
    reason = f"{context}: {problem}" if context and context not in problem else problem
    return f"not valid YAML{where}: {reason}"


# --------------------------------------------------------------------------- sections


def _geometry(r: _Reader, data: Any, source: Path) -> tuple[Geometry, tuple[str, ...] | None]:
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
        _check_extent(r, f"{key}.upper", np.array([lower, upper]))
        names = r.mapping(spec.get("names", {}), f"{key}.names", SIDES)
        side_names = {side: r.name(names.get(side, side), f"{key}.names.{side}") for side in SIDES}
        return RectangleGeometry(lower, upper, side_names), tuple(dict.fromkeys(side_names.values()))
    if kind == "profile":
        return _profile(r, spec, key, source)
    if kind == "polygon":
        spec = r.mapping(spec, key, ("vertices", "edges", "file", "holes"))
        outer = _listed_loop(r, spec, key, source, MAX_POLYGON_VERTICES)
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
            if total > MAX_POLYGON_VERTICES:
                raise r.fail(f"{key}.holes[{i}]", f"<{len(hole_list)} holes>",
                             f"the polygon and its holes have more than {MAX_POLYGON_VERTICES} vertices (a circle "
                             "counts 4); expected at most that many (use a gmsh mesh_file for more)")
            holes.append(_hole(r, hole, f"{key}.holes[{i}]", extent, source, MAX_POLYGON_VERTICES - total))
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
    mode = _file_mode(r, key, spec, path)
    if not stat.S_ISREG(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
        raise r.fail(key, spec, f"{shortened(str(path))} is {kind}; expected a gmsh .msh file")
    r.inputs.append(_file_digest(r, key, spec, path))
    r.input_paths.append(path)
    return MeshFileGeometry(path), None


def _file_mode(r: _Reader, key: str, spec: Any, path: Path) -> int:
    """``os.stat(path).st_mode`` of a file a case names, or a one-line refusal naming ``key``."""
    try:
        return os.stat(path).st_mode
    except FileNotFoundError:
        raise r.fail(key, spec, f"no such file ({shortened(str(path))})") from None
    except (OSError, ValueError) as error:
        raise r.fail(key, spec, f"cannot read {shortened(str(path))} ({_reason(error)})") from None


PROFILE_SOURCES = ("file", "heights", "expression")


def _profile(r: _Reader, spec: Any, key: str, source: Path) -> tuple[Geometry, tuple[str, ...]]:
    """A body whose bottom edge is a height profile, closed by two straight sides and a top.

    The profile is a graph h(s) over the line through ``origin`` along ``direction``:
    point i is origin + s_i d + h_i n, d the unit direction and n its left normal (the
    body's side). The top runs at height ``depth`` over the line, the sides at the first
    and last s. With s strictly increasing and depth above every height the outline is a
    simple counter-clockwise polygon; it is still checked (in O(k log k)) like any other.
    """
    spec = r.mapping(spec, key, (*PROFILE_SOURCES, "spacing", "start", "x", "points", "name", "depth", "sides",
                                 "top", "origin", "direction"), required=("depth",))
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
    limit = MAX_POLYGON_VERTICES - 2  # the top's two corners complete the polygon
    if kind == "expression":
        s, h = _profile_expression(r, spec, key, limit)
    elif kind == "heights":
        values = spec["heights"]
        if not isinstance(values, list) or len(values) < 2:
            raise r.fail(f"{key}.heights", values, "expected a list of at least 2 heights")
        if len(values) > limit:
            raise r.fail(f"{key}.heights", f"<{len(values)} heights>", f"expected at most {limit} heights")
        h = np.array([r.number(v, f"{key}.heights[{i}]", low=-SCALE_LIMIT, high=SCALE_LIMIT)
                      for i, v in enumerate(values)])
        s = _equally_spaced(r, spec, key, len(h), "heights")
    else:
        s, h = _profile_file(r, spec, key, source, limit)
    depth = r.number(spec["depth"], f"{key}.depth", low=-SCALE_LIMIT, high=SCALE_LIMIT)
    if not depth > h.max():
        raise r.fail(f"{key}.depth", depth, f"the top must lie above the highest point of the profile, "
                     f"h = {h.max():.6g}; expected a depth greater than that")
    origin = r.point(spec.get("origin", [0, 0]), f"{key}.origin")
    direction = r.point(spec.get("direction", [1, 0]), f"{key}.direction")
    norm = math.hypot(*direction)
    if not norm > 0 or not math.isfinite(norm):
        raise r.fail(f"{key}.direction", list(direction), "expected a nonzero vector [dx, dy] along the profile")
    d = np.array(direction) / norm
    n = np.array([-d[1], d[0]])
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
    if not np.all(np.isfinite(points)) or np.abs(points).max() > SCALE_LIMIT:
        raise r.fail(key, f"<{len(h)} points>", f"the body's coordinates must lie within ±{SCALE_LIMIT:g}")
    names = (name,) * (len(h) - 1) + (last_side, top, first_side)
    problem = polygon_problems(points)
    if problem is not None:  # e.g. points that coincide once placed, in float64
        raise r.fail(key, f"<{len(h)} points>", f"the outline it makes is not a simple polygon: {problem}")
    _check_extent(r, key, points)
    loop = Loop(vertices=points, edge_names=names)
    return PolygonGeometry(loop, ()), tuple(dict.fromkeys(names))


def _equally_spaced(r: _Reader, spec: dict, key: str, count: int, what: str) -> np.ndarray:
    if "spacing" not in spec:
        raise CaseError(f"{r.filename}: {key}.spacing: missing (required with {what}: the distance between "
                        "consecutive heights)")
    spacing = r.number(spec["spacing"], f"{key}.spacing", low=0, low_open=True, high=SCALE_LIMIT)
    start = r.number(spec.get("start", 0), f"{key}.start", low=-SCALE_LIMIT, high=SCALE_LIMIT)
    return start + spacing * np.arange(count)


def _profile_expression(r: _Reader, spec: dict, key: str, limit: int) -> tuple[np.ndarray, np.ndarray]:
    for name in ("x", "points"):
        if name not in spec:
            raise CaseError(f"{r.filename}: {key}.{name}: missing (required with expression: the interval "
                            "[x0, x1] and the number of points sampled on it)")
    interval = spec["x"]
    if not isinstance(interval, list) or len(interval) != 2:
        raise r.fail(f"{key}.x", interval, "expected the interval [x0, x1] the profile spans")
    x0, x1 = (r.number(v, f"{key}.x[{i}]", low=-SCALE_LIMIT, high=SCALE_LIMIT) for i, v in enumerate(interval))
    if not x1 > x0:
        raise r.fail(f"{key}.x", interval, "expected x0 < x1")
    count = r.integer(spec["points"], f"{key}.points", low=2, high=limit)
    expression = r.expression(spec["expression"], f"{key}.expression")
    if "y" in expression.variables:
        raise r.fail(f"{key}.expression", expression.text, "expected the height as an expression in x only")
    s = np.linspace(x0, x1, count)
    h = expression(s, np.zeros_like(s))
    bad = np.flatnonzero(~np.isfinite(h) | (np.abs(h) > SCALE_LIMIT))
    if bad.size:
        raise r.fail(f"{key}.expression", expression.text,
                     f"is {h[bad[0]]:g} at x = {float(s[bad[0]])!r}; expected finite heights within ±{SCALE_LIMIT:g}")
    return s, h


#: The most bytes of data files (a profile, an outline and its holes) a case may read, all
#: of them together: room for MAX_POLYGON_VERTICES lines of two numbers written to full
#: precision; at most this many bytes plus one are read.
MAX_DATA_FILE_BYTES = 64 << 20


def _profile_file(r: _Reader, spec: dict, key: str, source: Path, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """The points of a CSV profile: two columns x, h, or one column of heights with ``spacing``."""
    fkey = f"{key}.file"
    text = spec["file"]
    lines = _data_file_lines(r, fkey, text, source, "a CSV file (x, h per line, or h per line with spacing)")
    table, line_of_row = _parse_columns(r, fkey, text, lines, limit)
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


def _data_file_lines(r: _Reader, fkey: str, text: Any, source: Path, expected: str) -> list[str]:
    """The lines of the data file a case names at ``fkey`` (a profile, an outline), read
    within :data:`MAX_DATA_FILE_BYTES` and recorded for the case's hash."""
    if not isinstance(text, str) or not text:
        raise r.fail(fkey, text, f"expected the path of {expected}")
    path = Path(text)
    if not path.is_absolute():
        path = source.parent / path
    shown = shortened(str(path))
    problem = path_problem(path)
    if problem is not None:
        raise r.fail(fkey, text, f"the path {'' if path == Path(text) else f'{shown} '}{problem}")
    data = _read_data_bytes(r, fkey, text, path)
    r.inputs.append(hashlib.sha256(data).digest())
    r.input_paths.append(path)
    try:
        content = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise r.fail(fkey, text, f"byte 0x{data[error.start]:02x} on line {line} is not UTF-8; expected "
                     "a text file") from None
    return content.splitlines()


def _digest(text: bytes, inputs: list[bytes]) -> str:
    """SHA-256 of the case text followed by the SHA-256 of each data file it reads
    (``inputs``, in the order read), so that a changed profile, outline or mesh file changes
    the case's hash; the text's alone when it reads none."""
    digest = hashlib.sha256(text)
    for file_digest in inputs:
        digest.update(file_digest)
    return digest.hexdigest()


def _file_digest(r: _Reader, key: str, spec: Any, path: Path) -> bytes:
    """SHA-256 of a file, read in blocks (a mesh file may be large)."""
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                digest.update(block)
    except OSError as error:
        raise r.fail(key, spec, f"cannot read {shortened(str(path))} ({_reason(error)})") from None
    return digest.digest()


def _read_data_bytes(r: _Reader, fkey: str, text: str, path: Path) -> bytes:
    """A regular file within what is left of the case's :data:`MAX_DATA_FILE_BYTES` for all
    its data files (a polygon and its holes each from a file share it), reading no more than
    one byte past that."""
    shown = shortened(str(path))
    budget = MAX_DATA_FILE_BYTES - r.data_bytes
    mode = _file_mode(r, fkey, text, path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    chunks, size = [], 0
    fd = None
    try:
        if stat.S_ISREG(mode):
            fd = os.open(path, flags)
            mode = os.fstat(fd).st_mode  # the file opened, which may differ from the one looked at
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
            raise r.fail(fkey, text, f"{shown} is {kind}; expected a CSV file")
        while size <= budget:
            chunk = os.read(fd, min(budget + 1 - size, 1 << 24))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise r.fail(fkey, text, f"cannot read {shown} ({_reason(error)})") from None
    finally:
        if fd is not None:
            os.close(fd)
    if size > budget:
        bound = f"{MAX_DATA_FILE_BYTES} bytes (64 MiB) all of a case's data files may hold"
        room = bound if budget == MAX_DATA_FILE_BYTES else f"the {budget} bytes left of the {bound}"
        raise r.fail(fkey, text, f"{shown} is larger than {room}; expected at most {MAX_POLYGON_VERTICES} lines "
                     "of points in all")
    r.data_bytes += size
    return b"".join(chunks)


class _DataLines:
    """The data lines of a CSV file: ``#`` comments and blank lines skipped, the delimiter
    (comma, semicolon or tab, else spaces) taken from the first data line, and that line
    dropped as a header when its first ``numeric`` fields are not all numbers."""

    def __init__(self, r: _Reader, fkey: str, text: str, lines: list[str], limit: int, numeric: int | None,
                 expected: str) -> None:
        self.lines = lines
        indices = [i for i, line in enumerate(lines) if (start := line.lstrip()) and start[0] != "#"]
        if not indices:
            raise r.fail(fkey, text, f"the file holds no numbers; expected {expected}")
        first = self.content(lines[indices[0]])
        self.delimiter = next((d for d in (",", ";", "\t") if d in first), None)
        if not all(is_number(f) for f in self.fields(lines[indices[0]])[:numeric]):
            indices = indices[1:]  # a header
        if len(indices) < 2:
            raise r.fail(fkey, text, f"{len(indices)} data lines; expected at least 2 points")
        if len(indices) > limit:
            raise r.fail(fkey, text, f"{len(indices)} data lines; expected at most {limit} points")
        self.indices = indices

    @staticmethod
    def content(line: str) -> str:
        return line.split("#", 1)[0].strip()

    def fields(self, line: str) -> list[str]:
        return [f.strip() for f in self.content(line).split(self.delimiter)]

    def line_of(self, row: int) -> int:
        """The 1-based line number of data row ``row``."""
        return self.indices[row] + 1


def is_number(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _checked_numbers(r: _Reader, fkey: str, text: str, table: np.ndarray, data: _DataLines) -> np.ndarray:
    bad = np.flatnonzero(~np.all(np.isfinite(table) & (np.abs(table) <= SCALE_LIMIT), axis=1))
    if bad.size:
        raise r.fail(fkey, text, f"line {data.line_of(int(bad[0]))}: {table[bad[0]].tolist()}: expected finite "
                     f"numbers within ±{SCALE_LIMIT:g}")
    return table


def _parse_columns(r: _Reader, fkey: str, text: str, lines: list[str], limit: int):
    """The numbers of a one- or two-column CSV (comma, semicolon, tab or spaces between
    them; ``#`` comments, blank lines and one header line allowed) as an (n, c) array,
    and a function from a row to its line number in the file."""
    data = _DataLines(r, fkey, text, lines, limit, None, "lines x, h (or h with spacing)")
    data_lines = data.indices
    columns = len(data.fields(lines[data_lines[0]]))
    if columns not in (1, 2):
        raise r.fail(fkey, text, f"line {data_lines[0] + 1} has {columns} columns; expected two (x, h) or one "
                     "(h, with spacing)")
    try:
        table = np.loadtxt([lines[i] for i in data_lines], delimiter=data.delimiter, comments="#", ndmin=2,
                           dtype=np.float64)
        if table.shape != (len(data_lines), columns):
            raise ValueError("shape")
    except ValueError:
        for i in data_lines:
            row = data.fields(lines[i])
            if len(row) != columns:
                raise r.fail(fkey, text, f"line {i + 1} has {len(row)} columns; expected {columns} like the "
                             "first line of numbers") from None
            bad = next((f for f in row if not is_number(f)), None)
            if bad is not None:
                raise r.fail(fkey, text, f"line {i + 1}: {shortened(bad, 40)!r} is not a number") from None
        raise r.fail(fkey, text, "cannot read the numbers; expected lines x, h (or h with spacing)") from None
    return _checked_numbers(r, fkey, text, table, data), data.line_of


OUTLINE_EXPECTED = "lines x, y, part (the part of the edge to the next point; empty: the part above)"


def _outline_file(r: _Reader, text: Any, key: str, source: Path, limit: int) -> Loop:
    """A closed straight-edged loop from a CSV file: per line a vertex x, y and the part of
    the edge from it to the next vertex (the last to the first), which may be left empty
    after the first line to continue the part above. Either orientation is accepted; the
    loop is returned counter-clockwise (a clockwise file read backwards), and is simple."""
    fkey = f"{key}.file"
    lines = _data_file_lines(r, fkey, text, source, f"a CSV file of {OUTLINE_EXPECTED}")
    data = _DataLines(r, fkey, text, lines, limit, 2, OUTLINE_EXPECTED)
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
    vertices = _checked_numbers(r, fkey, text, table, data)
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
    _check_extent(r, fkey, vertices)
    return Loop(vertices=vertices, edge_names=tuple(names.tolist()))


def _loop(r: _Reader, vertices: Any, edges: Any, key: str) -> Loop:
    if not isinstance(vertices, list) or len(vertices) < 2:
        raise r.fail(f"{key}.vertices", vertices, "expected a list of at least 2 points [x, y]")
    if len(vertices) > MAX_POLYGON_VERTICES:
        raise r.fail(f"{key}.vertices", f"<{len(vertices)} vertices>",
                     f"expected at most {MAX_POLYGON_VERTICES} vertices (use a gmsh mesh_file for finer outlines)")
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
    _check_extent(r, f"{key}.vertices", points)
    try:
        return Loop(vertices=points, edge_names=tuple(names), edge_arcs=tuple(arcs))
    except MeshError as error:
        raise r.fail(f"{key}.vertices", points.tolist(), str(error)) from None


#: How far (relative to the radius) a listed vertex may lie from the end of an arc given by its
#: angles; it is then moved onto the arc.
ARC_END_TOLERANCE = 1e-6


def _arc_by_angles(r: _Reader, arc: dict, key: str, center: tuple[float, float], points: np.ndarray,
                   index: int, loop_key: str) -> Arc:
    """An arc given by ``{center, radius, angles: [from, to]}`` (degrees, counter-clockwise when
    to > from): places its end points in ``points`` (vertices ``index`` and ``index + 1``)."""
    for name in ("radius", "angles"):
        if name not in arc:
            raise CaseError(f"{r.filename}: {key}.{name}: missing (an arc by angles needs radius and angles)")
    radius = r.number(arc["radius"], f"{key}.radius", low=1 / SCALE_LIMIT, high=SCALE_LIMIT)
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


def _listed_loop(r: _Reader, spec: dict, key: str, source: Path, limit: int) -> Loop:
    """A polygonal loop as the case gives it: ``vertices`` and ``edges``, or an outline ``file``."""
    if "file" in spec:
        for listed in ("vertices", "edges"):
            if listed in spec:
                raise r.fail(f"{key}.{listed}", "...", "not with file: the file lists the vertices and their "
                             "edges' parts")
        return _outline_file(r, spec["file"], key, source, limit)
    for listed in ("vertices", "edges"):
        if listed not in spec:
            raise CaseError(f"{r.filename}: {key}.{listed}: missing (a polygon is vertices and edges, or a file)")
    return _loop(r, spec["vertices"], spec["edges"], key)


def _hole(r: _Reader, data: Any, key: str, extent: float, source: Path, limit: int) -> Loop:
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
        least = max(extent / (2 * MAX_DIVISIONS), 1e-6 * math.hypot(*center),
                    1 / SCALE_LIMIT)
        if radius < least:
            raise r.fail(f"{key}.circle.radius", radius,
                         f"must be at least {least:.3g}: the body's extent / {2 * MAX_DIVISIONS}, and 1e-6 of the "
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
        loop = _listed_loop(r, data, key, source, limit)
        least = extent / MAX_DIVISIONS
        span = float(coordinate_span(loop.vertices).min())
        if span < least:
            raise r.fail(f"{key}.vertices", loop.vertices.tolist(),
                         f"the hole is {span:.3g} across; expected at least the body's extent / {MAX_DIVISIONS} "
                         f"= {least:.3g}, the finest mesh size")
    return loop


def _check_holes_inside(r: _Reader, key: str, outer: Loop, holes: list[Loop]) -> None:
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


def _check_extent(r: _Reader, key: str, points: np.ndarray) -> None:
    """The body must be resolvable in float64: both sides of its bounding box at least
    1/SCALE_LIMIT and 1e-9 of its distance from the origin (or the mesh degenerates)."""
    span = coordinate_span(points)
    far = float(np.abs(points).max())
    least = max(1.0 / SCALE_LIMIT, 1e-9 * far)
    if span.min() < least and not (len(points) < 3 and span.max() >= least):
        raise r.fail(key, points.tolist(), f"the body's extent {span.min():.3g} is too small: it must be at "
                     f"least {least:.3g} (1e-50, and 1e-9 of the distance from the origin)")


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
        span = coordinate_span(v).max()
        arcs = geometry.outer.edge_arcs
        radii = [np.hypot(*(v[i] - arcs[i].center)) for i in geometry.outer.arc_edges.tolist()]
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
        if kind == "platen":
            parts.append(BoundaryPart(name, "platen", platen=_platen(r, value, f"{key}.platen")))
            continue
        if kind == "pressure":
            values: tuple[Expression | None, ...] = (r.expression(value, f"{key}.pressure"),)
        else:
            values = r.vector_field(value, f"{key}.{kind}", allow_free=kind == "displacement")
            if kind == "displacement" and all(v is None for v in values):
                raise r.fail(f"{key}.displacement", value, "at least one component must be prescribed")
        parts.append(BoundaryPart(name, kind, values))
    if not any(p.is_support for p in parts):
        raise CaseError(
            f"{r.filename}: boundary: no clamped, displacement, symmetry or platen part; the body could move "
            "rigidly, so the problem is ill-posed (give at least one part: clamped)"
        )
    if not any(p.kind == "contact" for p in parts):
        raise CaseError(f"{r.filename}: boundary: no contact part; mark the part that may touch the obstacle: contact")
    return tuple(parts)


def _platen(r: _Reader, data: Any, key: str) -> Platen:
    """``{force: P}`` or ``{displacement: d}``: one number, the drive of a rigid frictionless platen."""
    if not isinstance(data, dict) or len(data) != 1:
        raise r.fail(key, data, "expected {force: P} (the force the platen presses with, per unit thickness) "
                                "or {displacement: d} (how far it advances into the body)")
    data = r.mapping(data, key, PLATEN_CONTROLS)
    (control, value), = data.items()
    limit = SCALE_LIMIT
    amount = r.number(value, f"{key}.{control}", low=-limit, high=limit,
                      expected=f"expected a number in [-{limit:g}, {limit:g}]")
    return Platen(control=control, value=amount)


def _load_path(r: _Reader, data: Any) -> LoadPath:
    """``{steps: n}`` (factors 1/n, 2/n, …, 1) or ``{factors: [f1, f2, …]}`` (each > 0)."""
    data = r.mapping(data, "load_path", ("steps", "factors"))
    if len(data) != 1:
        raise r.fail("load_path", data, "give one of steps (equal increments up to 1) or factors (a list)")
    if "steps" in data:
        steps = data["steps"]
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= MAX_LOAD_STEPS:
            raise r.fail("load_path.steps", steps, f"expected a whole number from 1 to {MAX_LOAD_STEPS}")
        return LoadPath(factors=tuple((i + 1) / steps for i in range(steps)))
    factors = data["factors"]
    if not isinstance(factors, list) or not 1 <= len(factors) <= MAX_LOAD_STEPS:
        raise r.fail("load_path.factors", factors, f"expected a list of 1 to {MAX_LOAD_STEPS} load factors")
    values = tuple(r.number(f, f"load_path.factors[{i}]", low=0, low_open=True, high=SCALE_LIMIT,
                            expected=f"expected a load factor > 0 and at most {SCALE_LIMIT:g}")
                   for i, f in enumerate(factors))
    return LoadPath(factors=values)


def _obstacle(r: _Reader, data: Any) -> Obstacle:
    data = r.mapping(data, "obstacle", ("point", "normal", "points", "segment"))
    given = [key for key in ("points", "segment") if key in data]
    if given:
        key = given[0]
        if len(given) > 1 or "point" in data or "normal" in data:
            raise r.fail("obstacle", data, "give one of: point and normal, points (an infinite line), "
                                           "or segment (a finite one)")
        points = data[key]
        if not isinstance(points, list) or len(points) != 2:
            raise r.fail(f"obstacle.{key}", points, "expected two points [[x0, y0], [x1, y1]] on the obstacle's surface")
        p0 = np.array(r.point(points[0], f"obstacle.{key}[0]"))
        p1 = np.array(r.point(points[1], f"obstacle.{key}[1]"))
        d = p1 - p0
        length = np.hypot(*d)
        scale = max(np.abs(p0).max(), np.abs(p1).max(), 1e-300)
        if not length > 1e-9 * scale:
            raise r.fail(f"obstacle.{key}", points, "the two points must differ (a segment of positive length)")
        # The obstacle lies to the right of the line walked from the first point to the second.
        normal = (d[1] / length, -d[0] / length)
        ends = (tuple(float(v) for v in p0), tuple(float(v) for v in p1)) if key == "segment" else None
        return Obstacle(point=tuple(float(v) for v in p0), normal=normal, ends=ends)
    for key in ("point", "normal"):
        if key not in data:
            raise CaseError(f"{r.filename}: obstacle.{key}: missing (give point and normal, points, or segment)")
    point = r.point(data["point"], "obstacle.point")
    normal = np.array(r.point(data["normal"], "obstacle.normal"))
    length = np.hypot(*normal)
    if abs(length - 1.0) > 1e-6:
        raise r.fail("obstacle.normal", normal.tolist(), "expected a unit vector pointing into the obstacle")
    return Obstacle(point=point, normal=tuple(normal / length))


def _units(r: _Reader, data: Any) -> Units:
    data = r.mapping(data if data is not None else {}, "units", ("length", "force"))
    names = {}
    for key, default in (("length", "m"), ("force", "N")):
        value = data.get(key, default)
        if not isinstance(value, str) or not value or len(value) > 16 or not value.isprintable() or " " in value:
            raise r.fail(f"units.{key}", value, "expected a unit symbol (at most 16 printable characters, no "
                         f"spaces), e.g. {default}")
        names[key] = value
    return Units(**names)


def _solver(r: _Reader, data: Any) -> SolverSettings:
    data = r.mapping(data if data is not None else {}, "solver",
                     ("method", "tolerance", "max_iterations", "c", "backend"))
    method = r.choice(data.get("method", "positive"), "solver.method", METHOD_NAMES)
    tolerance = r.number(data.get("tolerance", 1e-10), "solver.tolerance", low=1e-15, high=1e-2,
                         expected="must be in [1e-15, 1e-2]")
    # auto: one Newton step per contact node, at least 50 (kernel.default_max_iterations).
    max_iterations = data.get("max_iterations", "auto")
    if max_iterations != "auto":
        if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or not 1 <= max_iterations <= 10_000:
            raise r.fail("solver.max_iterations", max_iterations, "expected an integer in [1, 10000] or auto")
    max_iterations = None if max_iterations == "auto" else max_iterations
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
    problem = path_problem(directory, name_reserve=OUTPUT_NAME_RESERVE, path_reserve=OUTPUT_PATH_RESERVE)
    if problem is not None:
        given = "" if "directory" in data else " (the default, from the case file's name)"
        raise r.fail("output.directory", directory, f"the path{given} {problem}")
    files = data.get("files", list(DEFAULT_FORMATS))
    if not isinstance(files, list) or not files:
        raise r.fail("output.files", files, f"expected a non-empty list from {', '.join(FORMAT_NAMES)}")
    chosen = tuple(dict.fromkeys(r.choice(f, f"output.files[{i}]", FORMAT_NAMES) for i, f in enumerate(files)))
    for name, need in missing_needs(chosen):
        raise r.fail("output.files", files, f"{name} is written beside {need} and reads it: list {need} too")
    return OutputSettings(directory=Path(directory), files=chosen)


# --------------------------------------------------------------------------- helpers


def _join(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def _show(value: Any) -> str:
    try:
        text = repr(value) if isinstance(value, str) else str(value)
    except (ValueError, RecursionError):  # an integer past Python's 4300-digit str() limit
        text = f"<{type(value).__name__} too large to print>"
    return text if len(text) <= 80 else text[:77] + "..."


def shortened(text: str, limit: int = 120) -> str:
    """``text`` cut in the middle to at most ``limit`` characters (a path keeps its end, the file name)."""
    if len(text) <= limit:
        return text
    tail = (limit - 3) * 2 // 3
    return text[: limit - 3 - tail] + "..." + text[-tail:]


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
