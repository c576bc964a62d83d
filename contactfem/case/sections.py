"""The sections after the geometry: material, exact solution, body force, boundary (with
platens), load path, obstacle, units, solver and output."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.case import limits
from contactfem.case.files import path_problem
from contactfem.case.messages import CANNOT_DERIVE
from contactfem.case.model import (
    ACCURACY_LEVELS,
    ACCURACY_QUANTITIES,
    AccuracySettings,
    Accelerators,
    BoundaryPart,
    LoadPath,
    Material,
    OutputSettings,
    PartKind,
    Platen,
    PlatenControl,
    SolverSettings,
    Units,
)
from contactfem.case.names import BACKEND_CHOICES, DEFAULT_FORMATS, FORMAT_NAMES, FORMAT_NEEDS, METHOD_NAMES
from contactfem.case.reader import Reader
from contactfem.errors import CaseError
from contactfem.expressions import Expression, step_without_derivative


#: The conditions a part is given by their word alone (``left: clamped``).
PART_KINDS = (PartKind.CLAMPED, PartKind.FREE, PartKind.CONTACT, PartKind.SYMMETRY)
#: The conditions given as a mapping with a value (``top: {traction: [0, -1]}``).
PART_LOADS = (PartKind.TRACTION, PartKind.PRESSURE, PartKind.DISPLACEMENT, PartKind.PLATEN)
#: How a platen is driven: the force it presses with, or how far it advances into the body.
PLATEN_CONTROLS = tuple(PlatenControl)
EXACT = "exact"  # the value that takes a load or a displacement from the exact: block


def read_material(r: Reader, data: Any) -> Material:
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
        if not 1 / limits.SCALE_LIMIT <= young <= limits.SCALE_LIMIT:
            raise r.fail("material.E", young, f"must be in [{1 / limits.SCALE_LIMIT:g}, {limits.SCALE_LIMIT:g}] (use other units)")
        nu = r.number(data["nu"], "material.nu", low=0, high=0.5, high_open=True, expected="must be in [0, 0.5)")
        lam = young * nu / ((1 + nu) * (1 - 2 * nu))
        mu = young / (2 * (1 + nu))
    else:
        for key in ("lambda", "mu"):
            if key not in data:
                raise CaseError(f"{r.filename}: material.{key}: missing (required with {'mu' if key == 'lambda' else 'lambda'})")
        mu = r.number(data["mu"], "material.mu", low=0, low_open=True, expected="must be > 0")
        if not 1 / limits.SCALE_LIMIT <= mu <= limits.SCALE_LIMIT:
            raise r.fail("material.mu", mu, f"must be in [{1 / limits.SCALE_LIMIT:g}, {limits.SCALE_LIMIT:g}] (use other units)")
        lam = r.number(data["lambda"], "material.lambda", low=0, expected="must be >= 0")
        young = mu * (3 * lam + 2 * mu) / (lam + mu)
        nu = lam / (2 * (lam + mu))
    if lam > limits.MAX_LAME_RATIO * mu:
        key = "material.nu" if has_young else "material.lambda"
        raise r.fail(key, nu if has_young else lam,
                     f"lambda/mu = {lam / mu:.3g} exceeds {limits.MAX_LAME_RATIO:g} (nu > 0.499999995): P1 triangles "
                     "lock and the stiffness is singular to round-off; the material is too close to incompressible")
    return Material(lame_lambda=lam, lame_mu=mu, plane=plane, young=young, poisson=nu)


def read_exact_displacement(r: Reader, data: Any) -> tuple[Expression, Expression]:
    """The two checked expressions of ``exact.displacement``. Its fields (stress, body force)
    are derived where they are used (:func:`contactfem.exact.exact_solution`); a floor or
    ceil of x or y, which has no derivative, is refused here already."""
    data = r.mapping(data, "exact", ("displacement",), required=("displacement",))
    displacement = r.vector_field(data["displacement"], "exact.displacement")
    for component in displacement:
        reason = step_without_derivative(component)
        if reason is not None:
            raise r.fail("exact.displacement", [e.text for e in displacement], f"{CANNOT_DERIVE}: {reason}")
    return displacement  # type: ignore[return-value]


def read_body_force(r: Reader, value: Any, has_exact: bool) -> tuple[Expression, Expression] | None:
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


def read_boundary(r: Reader, data: Any, part_names: tuple[str, ...] | None,
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
            parts.append(BoundaryPart(name, PartKind(r.choice(spec, key, PART_KINDS))))
            continue
        if not isinstance(spec, dict) or len(spec) != 1:
            raise r.fail(
                key, spec,
                f"expected one of {', '.join(PART_KINDS)}, or a mapping with one of {', '.join(PART_LOADS)}",
            )
        (word, value), = spec.items()
        if word not in PART_LOADS:
            raise CaseError(f"{r.filename}: {key}.{word}: unknown key; expected one of {', '.join(PART_LOADS)}")
        kind = PartKind(word)
        if value == EXACT:
            if kind is PartKind.PRESSURE:
                raise r.fail(f"{key}.pressure", value, "'exact' is for traction and displacement; use {traction: exact}")
            if exact is None:
                raise r.fail(f"{key}.{kind}", value, "'exact' needs an exact: block with the displacement")
            parts.append(BoundaryPart(name, kind, exact if kind is PartKind.DISPLACEMENT else (), exact=True))
            continue
        if kind is PartKind.PLATEN:
            parts.append(BoundaryPart(name, kind, platen=_platen(r, value, f"{key}.platen")))
            continue
        if kind is PartKind.PRESSURE:
            values: tuple[Expression | None, ...] = (r.expression(value, f"{key}.pressure"),)
        else:
            values = r.vector_field(value, f"{key}.{kind}", allow_free=kind is PartKind.DISPLACEMENT)
            if kind is PartKind.DISPLACEMENT and all(v is None for v in values):
                raise r.fail(f"{key}.displacement", value, "at least one component must be prescribed")
        parts.append(BoundaryPart(name, kind, values))
    if not any(p.is_support for p in parts):
        raise CaseError(
            f"{r.filename}: boundary: no clamped, displacement, symmetry or platen part; the body could move "
            "rigidly, so the problem is ill-posed (give at least one part: clamped)"
        )
    if not any(p.kind is PartKind.CONTACT for p in parts):
        raise CaseError(f"{r.filename}: boundary: no contact part; mark the part that may touch the obstacle: contact")
    return tuple(parts)


def _platen(r: Reader, data: Any, key: str) -> Platen:
    """``{force: P}`` or ``{displacement: d}``: one number, the drive of a rigid frictionless platen."""
    if not isinstance(data, dict) or len(data) != 1:
        raise r.fail(key, data, "expected {force: P} (the force the platen presses with, per unit thickness) "
                                "or {displacement: d} (how far it advances into the body)")
    data = r.mapping(data, key, PLATEN_CONTROLS)
    (word, value), = data.items()
    control = PlatenControl(word)
    limit = limits.SCALE_LIMIT
    amount = r.number(value, f"{key}.{control}", low=-limit, high=limit,
                      expected=f"expected a number in [-{limit:g}, {limit:g}]")
    return Platen(control=control, value=amount)


def read_load_path(r: Reader, data: Any) -> LoadPath:
    """``{steps: n}`` (factors 1/n, 2/n, …, 1) or ``{factors: [f1, f2, …]}`` (each > 0)."""
    data = r.mapping(data, "load_path", ("steps", "factors"))
    if len(data) != 1:
        raise r.fail("load_path", data, "give one of steps (equal increments up to 1) or factors (a list)")
    if "steps" in data:
        steps = data["steps"]
        if isinstance(steps, bool) or not isinstance(steps, int) or not 1 <= steps <= limits.MAX_LOAD_STEPS:
            raise r.fail("load_path.steps", steps, f"expected a whole number from 1 to {limits.MAX_LOAD_STEPS}")
        return LoadPath(factors=tuple((i + 1) / steps for i in range(steps)))
    factors = data["factors"]
    if not isinstance(factors, list) or not 1 <= len(factors) <= limits.MAX_LOAD_STEPS:
        raise r.fail("load_path.factors", factors, f"expected a list of 1 to {limits.MAX_LOAD_STEPS} load factors")
    values = tuple(r.number(f, f"load_path.factors[{i}]", low=0, low_open=True, high=limits.SCALE_LIMIT,
                            expected=f"expected a load factor > 0 and at most {limits.SCALE_LIMIT:g}")
                   for i, f in enumerate(factors))
    return LoadPath(factors=values)


def read_units(r: Reader, data: Any) -> Units:
    data = r.mapping(data if data is not None else {}, "units", ("length", "force"))
    names = {}
    for key, default in (("length", "m"), ("force", "N")):
        value = data.get(key, default)
        if not isinstance(value, str) or not value or len(value) > 16 or not value.isprintable() or " " in value:
            raise r.fail(f"units.{key}", value, "expected a unit symbol (at most 16 printable characters, no "
                         f"spaces), e.g. {default}")
        names[key] = value
    return Units(**names)


#: The solver's accelerations a case may switch off (``solver.accelerators``), each on by default.
ACCELERATORS = tuple(accelerator.name for accelerator in fields(Accelerators))


def read_solver(r: Reader, data: Any) -> SolverSettings:
    data = r.mapping(data if data is not None else {}, "solver",
                     ("method", "tolerance", "max_iterations", "c", "backend", "accelerators", "accuracy"))
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
    scale = limits.SCALE_LIMIT
    c = None if c == "auto" else r.number(c, "solver.c", low=1 / scale, high=scale,
                                          expected=f"must be in [{1 / scale:g}, {scale:g}] or auto")
    backend = r.choice(data.get("backend", "auto"), "solver.backend", BACKEND_CHOICES)
    accelerators = _accelerators(r, data.get("accelerators"))
    return SolverSettings(method=method, tolerance=tolerance, max_iterations=max_iterations, c=c, backend=backend,
                          accelerators=accelerators, accuracy=_accuracy(r, data.get("accuracy")))


#: The relative accuracy targets a case may ask for: from 1e-6 (round-off in the quantities
#: read) to one half.
ACCURACY_TARGET_RANGE = (1e-6, 0.5)


def relative_target(value: Any) -> float | None:
    """A relative accuracy as a fraction: ``0.5%`` (a string) or ``0.005`` (a number); None
    when it is neither or lies outside :data:`ACCURACY_TARGET_RANGE`."""
    if isinstance(value, str):
        text = value.strip()
        scale = 0.01 if text.endswith("%") else 1.0
        try:
            value = float(text[:-1] if scale != 1.0 else text) * scale
        except ValueError:
            return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    low, high = ACCURACY_TARGET_RANGE
    return float(value) if low <= value <= high else None


def _accuracy(r: Reader, data: Any) -> AccuracySettings:
    """``solver.accuracy``: target, quantity, budget (unknowns, steps) and levels."""
    data = r.mapping(data if data is not None else {}, "solver.accuracy", ("target", "quantity", "budget", "levels"))
    target = None
    if "target" in data:
        target = relative_target(data["target"])
        if target is None:
            low, high = ACCURACY_TARGET_RANGE
            raise r.fail("solver.accuracy.target", data["target"],
                         f"expected a relative error in [{low:g}, {high:g}], e.g. 0.5% or 0.005")
    quantity = r.choice(data.get("quantity", "energy"), "solver.accuracy.quantity", ACCURACY_QUANTITIES)
    budget = r.mapping(data.get("budget") or {}, "solver.accuracy.budget", ("unknowns", "steps"))
    unknowns = budget.get("unknowns")
    if unknowns is not None:
        unknowns = r.integer(unknowns, "solver.accuracy.budget.unknowns", low=10, high=10**9)
    steps = r.integer(budget.get("steps", 30), "solver.accuracy.budget.steps", low=1, high=200)
    levels = r.choice(data.get("levels", "reuse"), "solver.accuracy.levels", ACCURACY_LEVELS)
    return AccuracySettings(target=target, quantity=quantity, max_unknowns=unknowns, max_steps=steps, levels=levels)


def _accelerators(r: Reader, data: Any) -> Accelerators:
    """``solver.accelerators``: which of :data:`ACCELERATORS` to use, true or false each (all by default)."""
    data = r.mapping(data if data is not None else {}, "solver.accelerators", ACCELERATORS)
    return Accelerators(**{name: r.boolean(value, f"solver.accelerators.{name}") for name, value in data.items()})


def read_output(r: Reader, data: Any, source: Path) -> OutputSettings:
    data = r.mapping(data if data is not None else {}, "output", ("directory", "files"))
    directory = data.get("directory", f"results/{source.stem}")
    if not isinstance(directory, str) or not directory.strip():
        raise r.fail("output.directory", directory, "expected a directory path")
    problem = path_problem(directory, name_reserve=limits.OUTPUT_NAME_RESERVE, path_reserve=limits.OUTPUT_PATH_RESERVE)
    if problem is not None:
        given = "" if "directory" in data else " (the default, from the case file's name)"
        raise r.fail("output.directory", directory, f"the path{given} {problem}")
    files = data.get("files", list(DEFAULT_FORMATS))
    if not isinstance(files, list) or not files:
        raise r.fail("output.files", files, f"expected a non-empty list from {', '.join(FORMAT_NAMES)}")
    chosen = tuple(dict.fromkeys(r.choice(f, f"output.files[{i}]", FORMAT_NAMES) for i, f in enumerate(files)))
    for name in chosen:
        for need in FORMAT_NEEDS.get(name, ()):
            if need not in chosen:
                raise r.fail("output.files", files, f"{name} is written beside {need} and reads it: list {need} too")
    return OutputSettings(directory=Path(directory), files=chosen)
