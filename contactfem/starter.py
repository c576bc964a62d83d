"""The commented starter case that ``contactfem init`` writes."""

from __future__ import annotations

from pathlib import Path

from contactfem.case.names import DEFAULT_FORMATS
from contactfem.errors import CaseError, OutputError

__all__ = ["starter_case", "write_starter_case"]

_TEMPLATE = """\
# A contactfem case: a 2D linear elastic body on a rigid flat obstacle (frictionless).
# Check it with `contactfem check {name}`, solve it with `contactfem solve {name} --plot`.
# Any consistent units (for example N, m, Pa); the README lists every key.
title: block pressed on a rigid floor

geometry:                    # rectangle, polygon (with holes and arcs) or mesh_file
  rectangle:
    lower: [0.0, 0.0]
    upper: [2.0, 1.0]
    # names: {{bottom: bottom, right: right, top: top, left: left}}   # the defaults

mesh:
  divisions: [32, 16]        # triangles per side, along x and y
  diagonal: alternate        # right | left | alternate | crossed
  refine: 0                  # uniform refinements, each halves h (also --refine K)

material:                    # E and nu, or lambda and mu
  E: 2.0e5
  nu: 0.3
  plane: strain              # strain | stress

# body_force: [0.0, -10.0]   # per unit volume; numbers or expressions in x and y

boundary:                    # part name -> condition
  top: {{displacement: [0.0, -0.01]}}   # pushed down by 0.01, no sliding on top
  left: free
  right: free
  bottom: contact            # may touch the obstacle
  # other conditions: clamped, symmetry, {{traction: [gx, gy]}}, {{pressure: p}},
  # {{platen: {{force: P}}}} (a rigid frictionless platen pressing with P per unit thickness)

obstacle:                    # the rigid half-plane below y = 0
  point: [0.0, 0.0]
  normal: [0.0, -1.0]        # unit, pointing from the body into the obstacle

solver:
  method: positive           # positive (method 4, lambda >= 0) | standard (method 5)
  tolerance: 1.0e-10
  max_iterations: auto         # Newton steps allowed: one per contact node, at least 50

output:
  directory: results/{stem}  # relative to the working directory
  files: [{files}]   # the default; exactly these are written (xdmf: add it, with h5)

# load_path: {{steps: 10}}     # solve at 10 load factors up to 1 (a PVD series, curves)
"""


def starter_case(path: Path) -> str:
    """The starter case's text for a file at ``path`` (its name fills the comments and the output
    directory; a byte of it that is not UTF-8 is written as ``\\xNN``, the file being UTF-8)."""
    from contactfem.io.registry import shown_text

    return _TEMPLATE.format(name=shown_text(path.name), stem=shown_text(path.stem) or "case",
                            files=", ".join(DEFAULT_FORMATS))


def write_starter_case(path: Path | str) -> Path:
    """Create ``path`` with the starter case; refuse (CaseError) if it exists."""
    path = Path(path)
    if path.suffix.lower() not in (".yaml", ".yml"):
        raise CaseError(f"{path}: a case file name ends in .yaml or .yml")
    try:
        with open(path, "x", encoding="utf-8") as handle:  # "x": never replaces a file
            handle.write(starter_case(path))
    except FileExistsError:
        raise CaseError(f"{path}: already exists; contactfem init never overwrites a file "
                        "(choose another PATH or remove it)") from None
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path
