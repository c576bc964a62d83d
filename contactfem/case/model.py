"""The validated case as frozen data: what :func:`contactfem.case.parse_case` returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, Callable, ClassVar

from contactfem.case.loops import Loop
from contactfem.expressions import Expression


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


#: The grading rule's constant G0: without a ``mesh.grading`` key the grading is
#: G0 · sqrt(contact_size / size) (:func:`grading_of`). Chosen on the quarter Hertz disk
#: (cases/hertz_quarter.yaml, no grading key), where a smaller G0 grades more gently and
#: lets the half-width error keep falling as contact_size is halved, while a larger one
#: leaves it stalled (benchmarks/mesh_knob.py; see docs/performance.md#measured-design-choices).
GRADING_CONSTANT = 0.7
#: The range the rule's grading is clipped to: at most the former fixed default (a
#: contact mesh as coarse as the bulk grades no faster than before), at least a growth
#: that still doubles h within 50 contact elements.
GRADING_RANGE = (0.02, 0.25)


def grading_of(contact_size: float, size: float) -> float:
    """The grading that follows the contact mesh: G0 · sqrt(contact_size / size), clipped to
    :data:`GRADING_RANGE`.

    The error of the transition from contact_size to size behaves like grading² (as the
    quarter Hertz disk's half-width error shows, benchmarks/mesh_knob.py), and the contact
    mesh's own like contact_size: with grading² ∝ contact_size
    both fall together when contact_size is halved, and the graded band's triangles,
    ∝ 1 / (grading · contact_size), grow 2.8 times per halving instead of 2."""
    low, high = GRADING_RANGE
    return float(min(max(GRADING_CONSTANT * (contact_size / size) ** 0.5, low), high))


@dataclass(frozen=True)
class MeshSettings:
    """How to mesh. ``contact_size`` and ``grading`` grade a polygon mesh towards ΓC:
    h(x) = min(size, contact_size + grading · distance(x, ΓC)).

    ``grading_key`` is the case's ``mesh.grading`` (None: not given); :attr:`grading` is the
    grading used, that key or the rule of :func:`grading_of`, which follows contact_size
    (so that a copy with another contact_size, :func:`dataclasses.replace`, follows too)."""

    divisions: tuple[int, int] | None
    size: float | None
    diagonal: str
    refine: int
    min_angle: float
    contact_size: float | None = None
    grading_key: float | None = None

    @property
    def grading(self) -> float:
        if self.grading_key is not None:
            return self.grading_key
        if self.contact_size is None or not self.size:
            return GRADING_RANGE[1]
        return grading_of(self.contact_size, self.size)


@dataclass(frozen=True)
class Material:
    lame_lambda: float
    lame_mu: float
    plane: str  # "strain" | "stress"
    young: float
    poisson: float


class PartKind(StrEnum):
    """What holds on a boundary part. A member is the word the case file uses for it (its
    value), so that labels, messages and reports print it as written."""

    CLAMPED = "clamped"
    FREE = "free"
    CONTACT = "contact"
    SYMMETRY = "symmetry"
    TRACTION = "traction"
    PRESSURE = "pressure"
    DISPLACEMENT = "displacement"
    PLATEN = "platen"


#: The kinds that prescribe the displacement.
DIRICHLET_KINDS = frozenset({PartKind.CLAMPED, PartKind.DISPLACEMENT})
#: The kinds that hold the body somewhere: a prescribed motion, a symmetry line, a platen.
SUPPORT_KINDS = DIRICHLET_KINDS | {PartKind.SYMMETRY, PartKind.PLATEN}


class PlatenControl(StrEnum):
    """How a platen is driven: the force it presses with, or how far it advances into the body."""

    FORCE = "force"
    DISPLACEMENT = "displacement"


@dataclass(frozen=True)
class BoundaryPart:
    """A named boundary part and what holds on it.

    ``kind`` is a :class:`PartKind`: clamped | free | contact | symmetry | traction |
    pressure | displacement | platen. ``values`` holds the two components of a traction or
    a displacement (None for a displacement component left free), or the single pressure.
    ``exact`` marks ``{traction: exact}`` (``values`` empty: σ(u_exact) n depends on the
    edge's normal) and ``{displacement: exact}`` (``values`` are the exact block's two
    expressions). ``platen`` is the drive of a platen part.
    """

    name: str
    kind: PartKind
    values: tuple[Expression | None, ...] = ()
    exact: bool = False
    platen: "Platen | None" = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", PartKind(self.kind))

    @property
    def label(self) -> str:
        """The kind as the case file says it, e.g. ``traction (exact)`` or ``platen (force 2000)``."""
        if self.platen is not None:
            return f"{self.kind} ({self.platen.control} {self.platen.value:g})"
        return f"{self.kind} (exact)" if self.exact else str(self.kind)

    @property
    def is_dirichlet(self) -> bool:
        return self.kind in DIRICHLET_KINDS

    @property
    def is_support(self) -> bool:
        """Whether the part holds the body somewhere (a prescribed motion, a symmetry line, a platen)."""
        return self.kind in SUPPORT_KINDS

    @property
    def is_force_driven(self) -> bool:
        """Whether the part is a platen driven by force: it presses with a force of its own
        rather than holding the body."""
        return self.platen is not None and self.platen.control is PlatenControl.FORCE


@dataclass(frozen=True)
class Platen:
    """A rigid, frictionless platen on a straight boundary part: the part's normal
    displacement is one unknown δ (its advance into the body, along the inward normal),
    its tangential motion free. ``control`` is :attr:`PlatenControl.FORCE` (δ unknown, the
    platen presses with ``value`` per unit thickness; negative pulls) or
    :attr:`PlatenControl.DISPLACEMENT` (δ = ``value``).
    """

    control: PlatenControl
    value: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "control", PlatenControl(self.control))


@dataclass(frozen=True)
class LoadPath:
    """Load factors applied in turn (``factors``, each > 0): every load, prescribed
    displacement and platen drive of the case, and a moving obstacle's advance or force, is
    multiplied by the factor; an obstacle without motion stays where it is."""

    factors: tuple[float, ...]


@dataclass(frozen=True)
class ObstacleMotion:
    """How a rigid obstacle is driven: its advance along the unit ``direction`` is one
    unknown, prescribed (``control`` displacement: ``value`` is the advance) or pushed
    (force: ``value`` is the force along the direction the obstacle presses with)."""

    direction: tuple[float, float]
    control: PlatenControl
    value: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "control", PlatenControl(self.control))


@dataclass(frozen=True)
class Obstacle:
    """The rigid obstacle.

    ``shape`` ``line`` is the half-plane {p : (p − point)·normal ≥ 0}; ``normal`` is a
    unit vector pointing into it. ``ends`` are the two end points of a finite obstacle (a
    segment: a table, a punch), None for an infinite one: only the part of the surface
    between them exists.

    ``shape`` ``circle`` is the disk of ``center`` and ``radius`` (the body outside it);
    ``polyline`` the open polyline through ``vertices`` (a polyline or a profile), the
    obstacle on the right of the walk from the first vertex to the last. A curved obstacle
    has no single normal: ``point`` is its center or first vertex and ``normal`` None.
    ``motion`` drives the obstacle (None: it stays where it is).
    """

    point: tuple[float, float]
    normal: tuple[float, float] | None
    ends: tuple[tuple[float, float], tuple[float, float]] | None = None
    shape: str = "line"
    center: tuple[float, float] | None = None
    radius: float | None = None
    vertices: tuple[tuple[float, float], ...] | None = None
    motion: ObstacleMotion | None = None

    @property
    def flat(self) -> bool:
        return self.shape == "line"


@dataclass(frozen=True)
class ExactBlock:
    """The ``exact:`` block: a manufactured displacement, as two checked expressions, and what
    the fields derived from it depend on: the material (the plane law's Lamé parameters) and
    the obstacle's unit ``normal`` (the contact pressure).

    The fields themselves (strain, stress, body force f = −div σ, contact pressure: an
    :class:`~contactfem.exact.ExactSolution`) are derived with sympy where they are used,
    by :func:`contactfem.exact.exact_solution`, once per block: ``derived`` keeps them and is
    left out of comparison and hashing.
    """

    displacement: tuple[Expression, Expression]
    material: Material
    normal: tuple[float, float]
    derived: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    #: Derives a block's fields; :mod:`contactfem.exact` installs it when it is imported, so
    #: that :attr:`solution` works without the case layer importing what lies above it.
    builder: ClassVar[Callable[["ExactBlock"], Any] | None] = None

    @property
    def solution(self) -> Any:
        """The derived fields (an :class:`~contactfem.exact.ExactSolution`), for callers written
        when the reader built them; call :func:`contactfem.exact.exact_solution` instead."""
        if ExactBlock.builder is None:
            raise RuntimeError("an exact block's fields are derived by contactfem.exact: import it, or call "
                               "contactfem.exact.exact_solution(case)")
        return ExactBlock.builder(self)


@dataclass(frozen=True)
class Accelerators:
    """The solver's accelerations, each on unless ``solver.accelerators`` turns it off: the
    solution is the same either way, only the work to reach it differs (a switch to measure
    one against the others, or to rule one out).

    ``sequencing``: start the active set from the same case solved on coarser meshes;
    ``zone_fronts``: extrapolate a contact zone's creeping edges along ΓC
    (``contactfem.kernel.ZoneFronts``); ``schur_updates``: solve later Newton steps through
    a Schur complement over the nodes whose state changed, rather than refactorising;
    ``start_checks``: correct each load path step's starting set where its Schur system
    alone (without the displacement) shows that Newton's first update would change it.
    """

    sequencing: bool = True
    zone_fronts: bool = True
    schur_updates: bool = True
    start_checks: bool = True


#: What ``solver.accuracy.quantity`` may name: the energy norm of the displacement error
#: (the residual estimator's), or a contact quantity (its Richardson estimate).
ACCURACY_QUANTITIES = ("energy", "contact_width", "peak_pressure", "contact_force")
#: What ``solver.accuracy.levels`` may name: the coarser solutions the contact quantities'
#: estimates of a plain solve compare with: only those sequencing solved anyway (free), or
#: also ones solved for the purpose (up to a third of the solve's unknowns more).
ACCURACY_LEVELS = ("reuse", "solve")


@dataclass(frozen=True)
class AccuracySettings:
    """``solver.accuracy``: a relative ``target`` for the estimated error of ``quantity``
    (None: solve the case's mesh once and only report the estimates), the budget the
    refinement towards it may spend (``max_unknowns``: None, what memory allows;
    ``max_steps`` refinements), and where a plain solve's quantity estimates come from."""

    target: float | None = None
    quantity: str = "energy"
    max_unknowns: int | None = None
    max_steps: int = 30
    levels: str = "reuse"


@dataclass(frozen=True)
class SolverSettings:
    method: str
    tolerance: float
    max_iterations: int | None  # None: auto (see contactfem.kernel.default_max_iterations)
    c: float | None
    backend: str
    accelerators: Accelerators = Accelerators()
    accuracy: AccuracySettings = AccuracySettings()


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

    ``exact`` is the ``exact:`` block, a manufactured displacement (None without one); the
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

    def parts_of_kind(self, *kinds: PartKind) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts if p.kind in kinds)

    @property
    def contact_parts(self) -> tuple[str, ...]:
        return self.parts_of_kind(PartKind.CONTACT)

    @property
    def dirichlet_parts(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts if p.is_dirichlet)

    def exact_solution(self) -> Any:
        """The exact: block's derived fields, or None without one: as
        :func:`contactfem.exact.exact_solution`, which callers should use instead."""
        return None if self.exact is None else self.exact.solution

    def with_solver(self, **changes: Any) -> "Case":
        """A copy with some solver settings replaced (validated like the file's)."""
        from dataclasses import replace

        return replace(self, solver=replace(self.solver, **changes))
