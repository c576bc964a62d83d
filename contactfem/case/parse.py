"""Read a case file and validate it, once, into a frozen :class:`~contactfem.case.model.Case`."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from contactfem.case import limits
from contactfem.case.files import case_digest, read_text_file
from contactfem.case.geometry import read_geometry, read_mesh_settings
from contactfem.case.messages import shortened
from contactfem.case.model import Case, ExactBlock
from contactfem.case.obstacle import read_obstacle
from contactfem.case.reader import Reader
from contactfem.case.sections import (
    read_body_force,
    read_boundary,
    read_exact_displacement,
    read_load_path,
    read_material,
    read_output,
    read_solver,
    read_units,
)
from contactfem.case.yaml_loader import load_yaml
from contactfem.errors import CaseError


def load_case(path: str | Path) -> Case:
    """Read and validate a case file.

    At most :data:`~contactfem.case.limits.MAX_CASE_BYTES` + 1 bytes are read; directories, FIFOs and devices are
    refused from their status, before anything is read (a FIFO is opened non-blocking).

    Raises
    ------
    CaseError
        If the file cannot be read or any key is missing, unknown, mistyped or out of range.
    """
    path = Path(path)
    return parse_case(read_text_file(path), source=path)


def parse_case(text: str, source: str | Path = "<case>") -> Case:
    """Validate the YAML ``text`` of a case; ``source`` names it in messages and anchors relative paths."""
    source = Path(source)
    r = Reader(shortened(source.name))
    if not isinstance(text, str):
        raise CaseError(f"{r.filename}: expected the case as text, got {type(text).__name__}")
    if len(text) > limits.MAX_CASE_BYTES:
        raise CaseError(f"{r.filename}: the case file is larger than {limits.MAX_CASE_BYTES} bytes (1 MiB)")
    try:
        encoded = text.encode("utf-8")
    except UnicodeEncodeError as error:
        line = text.count("\n", 0, error.start) + 1
        raise CaseError(f"{r.filename}: line {line}: {text[error.start]!r} is a lone surrogate, "
                        "not a character; expected Unicode text") from None
    if len(encoded) > limits.MAX_CASE_BYTES:
        raise CaseError(f"{r.filename}: the case file is larger than {limits.MAX_CASE_BYTES} bytes (1 MiB)")
    data = load_yaml(text, r.filename)
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

    geometry, part_names = read_geometry(r, top["geometry"], source)
    mesh = read_mesh_settings(r, top.get("mesh", {}), geometry)
    material = read_material(r, top["material"])
    exact_displacement = read_exact_displacement(r, top["exact"]) if "exact" in top else None
    body_force = read_body_force(r, top.get("body_force"), exact_displacement is not None)
    parts = read_boundary(r, top["boundary"], part_names, exact_displacement)
    obstacle = read_obstacle(r, top["obstacle"], source)
    if exact_displacement is not None and (not obstacle.flat or obstacle.motion is not None):
        raise r.fail("exact", "...", "a manufactured solution (exact:) is derived for a flat obstacle that stays "
                                     "where it is; drop the exact: block or give a flat obstacle without motion")
    exact = None if exact_displacement is None else ExactBlock(exact_displacement, material, obstacle.normal)
    solver = read_solver(r, top.get("solver", {}))
    output = read_output(r, top.get("output", {}), source)
    units = read_units(r, top.get("units", {}))
    load_path = read_load_path(r, top["load_path"]) if "load_path" in top else None
    if load_path is not None and exact is not None:
        raise r.fail("load_path", top["load_path"], "a manufactured solution (exact:) is the answer to one load; "
                                                    "drop load_path or the exact: block")
    if load_path is not None and "path" not in output.files:
        files = [name for name in output.files if name != "json"]
        output = replace(output, files=(*files, "path", *(("json",) if "json" in output.files else ())))
    return Case(
        source=source,
        text=text,
        digest=case_digest(encoded, r.inputs),
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
