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

The package reads and validates, and imports nothing numerical: only the standard
library, NumPy, PyYAML, :mod:`contactfem.errors` and :mod:`contactfem.expressions`.
Its modules, in the order a case is read: :mod:`~contactfem.case.parse` (the entry
points), :mod:`~contactfem.case.files` (bounded reading, paths, digests),
:mod:`~contactfem.case.yaml_loader`, :mod:`~contactfem.case.reader` (typed checks and
their messages), :mod:`~contactfem.case.geometry` with :mod:`~contactfem.case.profile`,
:mod:`~contactfem.case.outline` and :mod:`~contactfem.case.tables`,
:mod:`~contactfem.case.sections` (the other sections); :mod:`~contactfem.case.model` is
the frozen result, :mod:`~contactfem.case.limits` the bounds, and
:mod:`~contactfem.case.loops` and :mod:`~contactfem.case.crossings` (with
:mod:`~contactfem.case.predicates`) the plain outline geometry the mesher shares.
"""

from contactfem.case.files import path_problem, read_text_file
from contactfem.case.geometry import DIAGONALS, SIDES
from contactfem.case.limits import (
    MAX_CASE_BYTES,
    MAX_DATA_FILE_BYTES,
    MAX_DIVISIONS,
    MAX_LAME_RATIO,
    MAX_LOAD_STEPS,
    MAX_POLYGON_VERTICES,
    MAX_YAML_DEPTH,
    MAX_YAML_VALUES,
    NAME_MAX,
    OUTPUT_NAME_RESERVE,
    OUTPUT_PATH_RESERVE,
    PATH_MAX,
    SCALE_LIMIT,
)
from contactfem.case.loops import Arc, Loop
from contactfem.case.messages import shortened
from contactfem.case.model import (
    ACCURACY_LEVELS,
    ACCURACY_QUANTITIES,
    DIRICHLET_KINDS,
    AccuracySettings,
    SUPPORT_KINDS,
    Accelerators,
    BoundaryPart,
    Case,
    ExactBlock,
    Geometry,
    LoadPath,
    Material,
    MeshFileGeometry,
    MeshSettings,
    Obstacle,
    ObstacleMotion,
    OutputSettings,
    PartKind,
    Platen,
    PlatenControl,
    PolygonGeometry,
    RectangleGeometry,
    SolverSettings,
    Units,
)
from contactfem.case.outline import ARC_END_TOLERANCE, OUTLINE_EXPECTED
from contactfem.case.parse import load_case, parse_case
from contactfem.case.profile import PROFILE_SOURCES
from contactfem.case.sections import ACCELERATORS, EXACT, PART_KINDS, PART_LOADS, PLATEN_CONTROLS, relative_target
from contactfem.case.tables import is_number

__all__ = [
    "ACCELERATORS", "ACCURACY_LEVELS", "ACCURACY_QUANTITIES", "AccuracySettings", "relative_target", "ARC_END_TOLERANCE", "DIAGONALS", "DIRICHLET_KINDS", "EXACT", "MAX_CASE_BYTES", "MAX_DATA_FILE_BYTES", "MAX_DIVISIONS",
    "MAX_LAME_RATIO", "MAX_LOAD_STEPS", "MAX_POLYGON_VERTICES", "MAX_YAML_DEPTH", "MAX_YAML_VALUES", "NAME_MAX",
    "OUTLINE_EXPECTED", "OUTPUT_NAME_RESERVE", "OUTPUT_PATH_RESERVE", "PART_KINDS", "PART_LOADS", "PATH_MAX",
    "PLATEN_CONTROLS", "PROFILE_SOURCES", "SCALE_LIMIT", "SIDES", "SUPPORT_KINDS",
    "Accelerators", "Arc", "BoundaryPart", "Case", "ExactBlock", "Geometry", "LoadPath", "Loop", "Material", "MeshFileGeometry",
    "MeshSettings", "Obstacle", "ObstacleMotion", "OutputSettings", "PartKind", "Platen", "PlatenControl", "PolygonGeometry", "RectangleGeometry",
    "SolverSettings", "Units",
    "is_number", "load_case", "parse_case", "path_problem", "read_text_file", "shortened",
]
