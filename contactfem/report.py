"""The report of a solve, built from the case and the frozen result: the figures a user checks a
solve by (sign conditions, contact zone, contact force, equilibrium), the exact errors when the
case has an exact solution, and any extras (the estimator's figures). Nothing here solves or writes.
"""

from __future__ import annotations

import platform
from dataclasses import dataclass
from typing import TYPE_CHECKING, Collection, Mapping

import numpy as np

from contactfem import __version__
from contactfem.case import Case, PartKind
from contactfem.discretize import DiscreteProblem
from contactfem.discretize.contact import contact_patches
from contactfem.mesh.core import coordinate_span
from contactfem.methods import get_method
from contactfem.result import Solution
from contactfem.timings import clock

if TYPE_CHECKING:
    from contactfem.solve import PathResult, SolveResult

SCHEMA_VERSION = 1

#: Plane strain λ/μ above which report["warnings"] flags volumetric locking: 1e3 ⇔
#: ν > 0.4995. P1 displacements then lose accuracy in proportion to λ/μ (the discrete
#: divergence-free space is too small), the stiffness's condition number grows like λ/μ
#: and benchmarks/extremes.py measures the normalised displacement falling off from this
#: point on. Plane stress cannot lock (its effective λ is at most 2μ).
LOCKING_WARNING_RATIO = 1e3


@dataclass(frozen=True, eq=False)
class BodyFigures:
    """What the report needs of the whole mesh when no process holds it (a distributed mesh,
    each rank holding its piece): counts and sizes, the nodes' centroid and largest coordinate
    span, and the body force's resultant about that centroid, each reduced over the pieces
    (sums and extremes); ``errors`` the exact errors when the case has an exact solution.

    The problem handed to :func:`build_report` with it then has the boundary for its mesh, and
    for its load the whole load at the boundary nodes (what the reactions need).
    """

    nodes: int
    triangles: int
    h_min: float
    h_max: float
    centre: np.ndarray
    length: float
    body_force: dict
    errors: dict | None = None
    #: What the report could not compute without the whole mesh, for report["warnings"].
    warnings: tuple[str, ...] = ()


def case_record(case: Case) -> dict:
    """What every result file says of the case it solved: the file, its title, the SHA-256
    of its text and the data files it reads, and those files (a profile, an outline, a
    mesh), by path."""
    return {"file": str(case.source), "title": case.title, "sha256": case.digest,
            "data_files": [str(path) for path in case.data_files]}


def build_report(case: Case, result: "SolveResult", extras: Mapping | None = None,
                 body: BodyFigures | None = None) -> dict:
    """The report.json content: deterministic but for the timings and the machine.

    ``extras`` are further top-level entries (e.g. ``estimator``). The seconds spent here,
    the exact error norms included, are the ``report`` timing; the ``accuracy`` section
    (:func:`accuracy_section`), unless ``extras`` gives one, has its own. ``body``: the whole
    mesh's figures when ``result`` holds only its boundary (see :class:`BodyFigures`).
    """
    extras = dict(extras or {})
    if "accuracy" not in extras:
        extras["accuracy"] = accuracy_section(case, result, adapted="estimator" in extras)
    started = clock()
    problem, solution, kernel = result.problem, result.solution, result.kernel
    mesh = problem.mesh
    contact = solution.contact
    method = get_method(solution.method)
    if body is None:
        diameters = mesh.triangle_diameters()
        sizes = {"nodes": mesh.n_points, "triangles": mesh.n_triangles, "h_min": float(diameters.min()),
                 "h_max": float(diameters.max())}
    else:
        sizes = {"nodes": body.nodes, "triangles": body.triangles, "h_min": body.h_min, "h_max": body.h_max}
    # The push and the reactions (one product K u) serve both balances below.
    forces = contact_and_reactions(problem, solution.displacement, contact.nodal_force)
    certificate_force = kernel.certificate.scales.get("force", 0.0) if kernel.certificate is not None else 0.0
    force_unit = float(certificate_force) if np.isfinite(certificate_force) else 0.0
    material = case.material
    report = {
        "schema_version": SCHEMA_VERSION,
        "contactfem_version": __version__,
        "case": case_record(case),
        "method": {"name": method.name, "equation": method.equation,
                   "multiplier": method.multiplier_symbol, "summary": method.summary},
        "material": {"E": material.young, "nu": material.poisson, "lambda": material.lame_lambda,
                     "mu": material.lame_mu, "plane": material.plane},
        "units": case.units.to_dict(),
        "mesh": {
            **sizes,
            "contact_nodes": int(len(contact.nodes)),
            "contact_edges": int(len(contact.edges)),
        },
        "unknowns": {"displacement": problem.n_unknowns, "multiplier": int(len(contact.nodes))},
        "solver": {
            "backend": result.backend,
            "backend_reason": result.backend_reason or f"solver.backend = {case.solver.backend}",
            "linear": dict(result.linear) or None,
            "status": kernel.status.value,
            "message": kernel.message,
            "iterations": kernel.iterations,
            "c": kernel.c,
            "tolerance": case.solver.tolerance,
            "cycle_detected_at": kernel.cycle_detected_at,
            "factorizations": kernel.factorizations,
            "column_solves": kernel.column_solves,
            "sequencing": dict(result.sequencing),
            "certificate": kernel.certificate.to_dict() if kernel.certificate is not None else None,
        },
        "newton": [
            {"iteration": i + 1, **{k: getattr(r, k) for k in
                                    ("active", "added", "removed", "proposed", "proposer",
                                     "equilibrium_residual", "complementarity_residual", "seconds")}}
            for i, r in enumerate(kernel.history)
        ],
        "sign_conditions": sign_conditions(
            solution.method, contact.gap, contact.normal_displacement, contact.multiplier, contact.nodal_force
        ),
        "contact_zone": contact_zone(problem, contact.active),
        "obstacle": obstacle_figures(problem, contact.nodal_force),
        "contact_force": {
            "normal": float(contact.nodal_force.sum()),
            "vector": (-(problem.contact.normals * contact.nodal_force[:, None]).sum(axis=0)).tolist(),
        },
        "equilibrium": equilibrium(problem, solution.displacement, contact.nodal_force, forces, force_unit, body),
        "boundary_forces": boundary_forces(problem, solution.displacement, contact.nodal_force,
                                           {part.name: part.label for part in case.parts}, forces, force_unit,
                                           body),
        "platens": platen_figures(problem, solution.displacement, forces[1]),
        "errors": exact_errors(problem, solution) if body is None else body.errors,
        "warnings": (material_warnings(case.material) + contact_warnings(problem, contact)
                     + list(body.warnings if body is not None else ())),
        "machine": {"python": platform.python_version(), "platform": platform.platform()},
        **extras,
    }
    accuracy_seconds = (extras["accuracy"] or {}).get("cost", {}).get("seconds")
    report["timings"] = {**result.timings, **({} if accuracy_seconds is None else {"accuracy": accuracy_seconds}),
                         "report": clock() - started}
    return report


def accuracy_section(case: Case, result: "SolveResult", adapted: bool = False) -> dict:
    """report.json's ``accuracy`` (:func:`contactfem.accuracy.accuracy_figures`): the energy
    error estimate and the contact quantities' estimates from coarser solutions, those that
    sequencing solved (free) unless the case's ``solver.accuracy.levels`` asks for more. The
    last step of a load path is compared with coarser meshes at its factor; an ``adapted`` mesh
    (``contactfem adapt``) has no coarser level of its own, so it gets the energy estimate only."""
    from contactfem.accuracy import accuracy_figures

    factor = case.load_path.factors[-1] if case.load_path is not None else None
    levels = "none" if adapted else case.solver.accuracy.levels
    return accuracy_figures(case, result, load_factor=factor, levels=levels)


def exact_errors(problem: DiscreteProblem, solution: Solution) -> dict | None:
    """The six norms of exact − discrete when the problem has an exact solution (None otherwise).

    The multiplier is compared with the exact pressure −σ_nn(u_exact) on ΓC. A norm
    that is not finite (a singular exact field hit by a quadrature point) is null.
    """
    if problem.exact is None:
        return None
    from contactfem.norms import exact_errors as norms_of

    errors = norms_of(solution, problem, problem.exact)
    return {name: (float(value) if np.isfinite(value) else None) for name, value in errors.items()}


def material_warnings(material) -> list[str]:
    """Warnings about the material for report["warnings"] (empty when there are none)."""
    ratio = material.lame_lambda / material.lame_mu
    if material.plane == "strain" and ratio > LOCKING_WARNING_RATIO:
        return [
            f"nearly incompressible material in plane strain: nu = {material.poisson:.6g}, lambda/mu = "
            f"{ratio:.3g} > {LOCKING_WARNING_RATIO:g} (nu > 0.4995); P1 triangles lock, so the displacement "
            "is underestimated by an amount that grows with lambda/mu; use plane stress if it applies, "
            "or treat the result with care"
        ]
    return []


def contact_warnings(problem: DiscreteProblem, contact) -> list[str]:
    """A warning when no contact node touches the obstacle: the body did not reach it, so
    the contact condition shaped nothing (a load too light, or a gap the case did not mean)."""
    if len(contact.nodes) == 0 or contact.active.any():
        return []
    remaining = contact.gap - contact.normal_displacement
    nearest = int(np.argmin(remaining))
    where = ", ".join(f"{value:.6g}" for value in problem.mesh.points[contact.nodes[nearest]])
    return [f"no contact node touches the obstacle: the nearest, at ({where}), stays {remaining[nearest]:.3g} "
            "from it, so the contact condition shaped nothing"]


def sign_conditions(
    method: str, gap: np.ndarray, normal_displacement: np.ndarray, multiplier: np.ndarray, nodal_force: np.ndarray
) -> dict:
    """The discrete contact conditions at the contact nodes, absolute and relative.

    ``relative_*`` divide by the natural scale of the quantity: the largest |u_n − g| for
    the gap, the largest nodal force for the forces, their product for complementarity.
    """
    slack = normal_displacement - gap
    gap_scale = max(np.abs(slack).max(initial=0.0), np.abs(normal_displacement).max(initial=0.0))
    force_scale = np.abs(nodal_force).max(initial=0.0)
    complementarity = np.abs(nodal_force * slack).max(initial=0.0)
    figures = {
        "max_normal_displacement_minus_gap": float(slack.max(initial=0.0)) if len(slack) else 0.0,
        "relative_max_penetration": _ratio(max(slack.max(initial=0.0), 0.0), gap_scale),
        "min_multiplier": float(multiplier.min()) if len(multiplier) else 0.0,
        "min_nodal_force": float(nodal_force.min()) if len(nodal_force) else 0.0,
        "relative_min_nodal_force": _ratio(min(nodal_force.min(initial=0.0), 0.0), force_scale),
        "max_abs_nodal_force_times_gap": float(complementarity),
        "relative_complementarity": _ratio(complementarity, force_scale * gap_scale),
    }
    if method == "positive":
        figures["max_abs_multiplier_times_gap"] = float(np.abs(multiplier * slack).max(initial=0.0))
    else:
        negative = multiplier < 0
        figures["negative_multiplier_nodes"] = int(negative.sum())
    return figures


def obstacle_figures(problem: DiscreteProblem, nodal_force_of: np.ndarray | None = None) -> dict:
    """The obstacle as solved: its surface, a finite one's ends, and which nodes of ΓC face it."""
    contact = problem.contact
    obstacle = contact.obstacle
    description = obstacle.describe()
    figures = {
        "kind": description["kind"],
        "point": [float(v) for v in np.asarray(obstacle.point, dtype=float)],
        "normal": [float(v) for v in contact.reference_normal],
        "ends": description.get("ends"),
        "extent": None if obstacle.extent is None else list(obstacle.extent),
        "facing_nodes": int(len(contact.nodes)),
        "beyond_nodes": int(len(contact.beyond)),
    }
    if not contact.flat:
        # Each node's gap and normal are those of its closest point at rest: small deformations.
        figures.update({key: description[key] for key in ("center", "radius", "vertices") if key in description})
        figures["small_deformations"] = True
    drive = problem.drive
    if drive is not None:
        nodal_force = nodal_force_of
        figures["motion"] = {
            "direction": drive.direction.tolist(), "advance": float(drive.advance),
            "control": "displacement" if drive.force is None else "force",
            **({} if drive.force is None else {"force": float(drive.force)}),
            **({} if nodal_force is None else {"reaction": drive.reaction(nodal_force, contact.normals)}),
        }
    return figures


def contact_zone(problem: DiscreteProblem, active: np.ndarray) -> dict:
    """Active nodes and the intervals of ΓC they form (connected along ΓC edges:
    :func:`contactfem.discretize.contact.contact_patches`)."""
    contact = problem.contact
    first, last, counts = contact_patches(contact.abscissa, active, contact.node_edges())
    ends = problem.mesh.points[contact.nodes]
    intervals = [{"from": ends[a].tolist(), "to": ends[b].tolist(),
                  "abscissa": [float(contact.abscissa[a]), float(contact.abscissa[b])], "nodes": int(count)}
                 for a, b, count in zip(first, last, counts)]
    return {"active_nodes": int(np.count_nonzero(active)), "contact_nodes": len(contact.nodes),
            "intervals": intervals}


def equilibrium(problem: DiscreteProblem, displacement: np.ndarray, nodal_force: np.ndarray,
                forces: tuple[np.ndarray, np.ndarray] | None = None, force_unit: float = 0.0,
                body: BodyFigures | None = None) -> dict:
    """Force and moment balance: applied loads + contact force + support reactions = 0.

    The reactions are what the supports must add for K u to balance: R = K u − F − f_c
    on the prescribed unknowns and at the nodes of symmetry lines, f_c = −n Λ being the
    obstacle's push on each contact node. The residuals are relative to the resultants'
    magnitudes, and to ``force_unit`` at least (the certificate's force scale): a body
    that nothing loads or touches has round-off for forces, which are no scale of their own.
    ``body``: the whole mesh's figures when ``problem`` holds only its boundary.
    """
    points = problem.mesh.points
    contact_force, reactions = forces or contact_and_reactions(problem, displacement, nodal_force)
    centre = points.mean(axis=0) if body is None else body.centre

    def resultant(force: np.ndarray) -> list[float]:
        total = _resultant(points, centre, force)
        return [*total["force"], total["moment"]]

    if body is None:
        applied = resultant(problem.load)
    else:  # the surface loads at the boundary, and the body force's resultant over the pieces
        surface = resultant(problem.loads.natural.load_vector(problem.mesh.n_points))
        applied = [*np.add(surface[:2], body.body_force["force"]).tolist(), surface[2] + body.body_force["moment"]]
    contact, support = (resultant(v) for v in (contact_force, reactions))
    total = np.add(np.add(applied, contact), support)
    length = coordinate_span(points).max() if body is None else body.length
    scale = np.abs(applied) + np.abs(contact) + np.abs(support)
    force_scale = max(scale[0], scale[1], scale[2] / length, force_unit, np.finfo(float).tiny)
    return {
        "applied": applied,
        "contact": contact,
        "reactions": support,
        "moment_about": centre.tolist(),
        "relative_force_residual": float(np.hypot(total[0], total[1]) / force_scale),
        "relative_moment_residual": float(abs(total[2]) / (force_scale * length)),
    }


def contact_and_reactions(problem: DiscreteProblem, displacement: np.ndarray,
                          nodal_force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The obstacle's push f_c = −n Λ at the contact nodes and the supports' reactions
    R = K u − F − f_c on the held unknowns (prescribed, and both at symmetry-line and platen
    nodes), each (2n,)."""
    u = displacement.ravel()
    contact = problem.contact
    push = np.zeros_like(u)
    push[2 * contact.nodes] = -contact.normals[:, 0] * nodal_force
    push[2 * contact.nodes + 1] = -contact.normals[:, 1] * nodal_force
    symmetry = np.concatenate([problem.symmetry_nodes, *(p.nodes for p in problem.platens)])
    held = np.unique(np.concatenate([problem.dirichlet_dofs, 2 * symmetry, 2 * symmetry + 1]))
    reactions = np.zeros_like(u)
    reactions[held] = (problem.stiffness @ u)[held] - problem.load[held] - push[held]
    return push, reactions


def load_path_figures(path: "PathResult", steps: list[dict] | None = None) -> dict:
    """report.json's ``load_path``: per step its factor, the solve's account and the curves a
    user plots against the factor (total contact force, contact width along the obstacle,
    active nodes, each platen's advance and force); ``curves`` holds the same as columns.

    ``steps`` are the steps' :func:`path_step_figures`, when they were taken as the path
    was solved (``path`` then holds only its last step)."""
    if steps is None:
        steps = [path_step_figures(factor, step) for factor, step in zip(path.factors, path.steps)]
    return {"steps": steps, "curves": path_curves(steps), "factorizations": path.factorizations,
            "seconds": path.seconds}


def path_step_figures(factor: float, step: "SolveResult") -> dict:
    """One step of a load path in report.json's ``load_path.steps``."""
    solution, kernel = step.solution, step.kernel
    zone = contact_zone(step.problem, solution.contact.active)
    _, reactions = contact_and_reactions(step.problem, solution.displacement, solution.contact.nodal_force)
    platens = platen_figures(step.problem, solution.displacement, reactions)
    return {
        "factor": float(factor),
        "status": kernel.status.value,
        "iterations": kernel.iterations,
        "factorizations": kernel.factorizations,
        "column_solves": kernel.column_solves,
        "seconds": float(step.timings["solve"]),
        "active_nodes": zone["active_nodes"],
        "contact_patches": len(zone["intervals"]),
        "contact_force": float(solution.contact.nodal_force.sum()),
        "contact_width": float(sum(i["abscissa"][1] - i["abscissa"][0] for i in zone["intervals"])),
        "platens": {name: {"advance": entry["advance"], "force": entry["force"]} for name, entry in platens.items()},
    }


def path_curves(steps: list[dict]) -> dict[str, list[float]]:
    """The columns of path.csv: the load factor, then each plotted quantity per step."""
    curves = {name: [step[name] for step in steps]
              for name in ("factor", "contact_force", "contact_width", "active_nodes", "contact_patches", "iterations",
                           "factorizations", "column_solves")}
    for name in steps[0]["platens"] if steps else ():
        for quantity in ("advance", "force"):
            curves[f"platen_{name}_{quantity}"] = [step["platens"][name][quantity] for step in steps]
    return curves


def platen_figures(problem: DiscreteProblem, displacement: np.ndarray, reactions: np.ndarray) -> dict:
    """Each platen's advance δ into the body, its displacement vector −δ n, and the force
    it presses with: the work of its nodes' reactions per unit advance, Σ m · R (equal to
    the prescribed force of a force-driven platen, to the solve's residual)."""
    u = displacement.reshape(-1, 2)
    r = reactions.reshape(-1, 2)
    figures = {}
    for platen in problem.platens:
        advance = float(-(u[platen.master] @ platen.normal))
        figures[platen.name] = {
            "control": platen.control,
            "prescribed": platen.value,
            "advance": advance,
            "displacement": (-advance * platen.normal).tolist(),
            "force": float(np.sum(platen.motion * r[platen.nodes])),
            "normal": platen.normal.tolist(),
        }
    return figures


def _resultant(points: np.ndarray, centre: np.ndarray, force: np.ndarray, nodes: np.ndarray | None = None) -> dict:
    """Force and moment about ``centre`` of nodal forces (2n,), over ``nodes`` (all by default)."""
    f = force.reshape(-1, 2)
    where = points
    if nodes is not None:
        f, where = f[nodes], points[nodes]
    arm = where - centre
    return {"force": [float(f[:, 0].sum()), float(f[:, 1].sum())],
            "moment": float(np.sum(arm[:, 0] * f[:, 1] - arm[:, 1] * f[:, 0]))}


def boundary_forces(problem: DiscreteProblem, displacement: np.ndarray, nodal_force: np.ndarray,
                    labels: Mapping[str, str], forces: tuple[np.ndarray, np.ndarray] | None = None,
                    force_unit: float = 0.0, body: BodyFigures | None = None) -> dict:
    """Force and moment of every boundary part on the body, and of the body force.

    Applied surface forces on the natural parts, reactions on the supports (clamped,
    prescribed, symmetry lines, platens: K u − F − f_c on their held unknowns, each part
    along the directions it holds, :func:`booked_reactions`) and the obstacle's push on the
    contact parts (−n Λ). Moments are about ``equilibrium``'s point (the nodes' centroid).
    The entries sum to zero up to the solve's residual: ``total`` is that sum, relative
    to the parts' forces and to ``force_unit`` at least (see :func:`equilibrium`). ``body``:
    the whole mesh's figures when ``problem`` holds only its boundary.
    """
    mesh = problem.mesh
    points = mesh.points
    push, reaction = forces or contact_and_reactions(problem, displacement, nodal_force)
    natural = problem.loads.natural
    centre = points.mean(axis=0) if body is None else body.centre

    def resultant(force: np.ndarray, nodes: np.ndarray | None = None) -> dict:
        return _resultant(points, centre, force, nodes)

    # The obstacle's push belongs to the contact parts: a node shared by two counts for the
    # first in the mesh's order. Each reaction is split among the parts that hold its node,
    # each along the direction it holds (booked_reactions).
    kinds = {name: labels.get(name, PartKind.FREE).split(" ")[0] for name in mesh.part_names}

    def owners(selected: Collection[str]) -> np.ndarray:
        owner = np.full(mesh.n_points, -1)
        for index in reversed(range(len(mesh.part_names))):
            if kinds[mesh.part_names[index]] in selected:
                owner[np.unique(mesh.boundary_edges[mesh.edge_parts == index])] = index
        return owner

    booked = booked_reactions(problem, reaction, centre)
    contact_owner = owners({PartKind.CONTACT})
    entries: dict[str, dict] = {}
    for index, name in enumerate(mesh.part_names):
        pieces = [resultant(_natural_part_load(natural, natural.parts == index, mesh.n_points)),
                  booked.get(name, {"force": [0.0, 0.0], "moment": 0.0}),
                  resultant(push, np.flatnonzero(contact_owner == index))]
        entries[name] = {"condition": labels.get(name, PartKind.FREE),
                         "force": [sum(p["force"][k] for p in pieces) for k in range(2)],
                         "moment": sum(p["moment"] for p in pieces)}
    if body is None:
        entries["body force"] = {"condition": "volume", **resultant(problem.load - natural.load_vector(mesh.n_points))}
    else:
        entries["body force"] = {"condition": "volume", "force": list(body.body_force["force"]),
                                 "moment": body.body_force["moment"]}
    force = np.sum([entry["force"] for entry in entries.values()], axis=0)
    moment = float(sum(entry["moment"] for entry in entries.values()))
    scale = max(sum(float(np.hypot(*entry["force"])) for entry in entries.values()), force_unit,
                np.finfo(float).tiny)
    length = float(coordinate_span(points).max()) if body is None else body.length
    return {"moment_about": centre.tolist(), "parts": entries,
            "total": {"force": force.tolist(), "moment": moment,
                      "relative_force_residual": float(np.hypot(*force) / scale),
                      "relative_moment_residual": float(abs(moment) / (scale * length))}}


#: Two directions holding one node are one direction (a part prescribing a component a symmetry
#: line along that axis also holds) below this |sin| of the angle between them.
PARALLEL_DIRECTIONS = 1e-9


def booked_reactions(problem: DiscreteProblem, reaction: np.ndarray,
                     centre: np.ndarray | None = None) -> dict[str, dict]:
    """Each support part's share of the reactions (2n,): its force and moment about the nodes'
    centroid (as :func:`boundary_forces`; ``centre`` when the mesh is only the boundary), by part name.

    A node held along two directions (a clamped or prescribed node, a platen's corner on a
    symmetry line, a node on two symmetry lines) has its reaction R split as R = a d1 + b d2
    along them, a d1 booked to the part holding d1 and b d2 to the one holding d2: a
    frictionless platen then carries no tangential force, and a symmetry line all of the
    force across it. The directions are taken in the mesh's part order, the first of each
    node's parts first (two parts prescribing one component: the first holds it). A node held
    along one direction books all of R to that part (R is along it, to the solve's residual).
    """
    mesh = problem.mesh
    holds = problem.holds
    points = mesh.points
    centre = points.mean(axis=0) if centre is None else centre
    r = reaction.reshape(-1, 2)
    if holds is None or len(holds.nodes) == 0:
        return {}
    order_of = {name: index for index, name in enumerate(mesh.part_names)}
    part_order = np.array([order_of.get(name, len(order_of)) for name in holds.names])[holds.parts]
    # Rows by node, then by the mesh's part order, then as given.
    rows = np.lexsort((np.arange(len(holds.nodes)), part_order, holds.nodes))
    nodes, directions, parts = holds.nodes[rows], holds.directions[rows], holds.parts[rows]
    start = np.flatnonzero(np.concatenate([[True], nodes[1:] != nodes[:-1]]))
    group = np.cumsum(np.concatenate([[False], nodes[1:] != nodes[:-1]]))
    first = directions[start][group]
    sine = first[:, 0] * directions[:, 1] - first[:, 1] * directions[:, 0]
    # The second direction of each node: its first row across the first direction.
    across = np.where(np.abs(sine) > PARALLEL_DIRECTIONS, np.arange(len(rows)), len(rows))
    second = np.minimum.reduceat(across, start)
    paired = second < len(rows)
    share = np.zeros((len(rows), 2))
    node_r = r[nodes[start]]
    share[start[~paired]] = node_r[~paired]
    d1 = directions[start[paired]]
    d2 = directions[second[paired]]
    rp = node_r[paired]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    a = (rp[:, 0] * d2[:, 1] - rp[:, 1] * d2[:, 0]) / det
    b = (d1[:, 0] * rp[:, 1] - d1[:, 1] * rp[:, 0]) / det
    share[start[paired]] = a[:, None] * d1
    share[second[paired]] = b[:, None] * d2
    arm = points[nodes] - centre
    moment = arm[:, 0] * share[:, 1] - arm[:, 1] * share[:, 0]
    booked = {}
    for index, name in enumerate(holds.names):
        mine = parts == index
        booked[name] = {"force": [float(share[mine, 0].sum()), float(share[mine, 1].sum())],
                        "moment": float(moment[mine].sum())}
    return booked


def _natural_part_load(natural, selected: np.ndarray, n_points: int) -> np.ndarray:
    from contactfem.assembly import edge_load_vector

    return edge_load_vector(natural.edges[selected], natural.length[selected], natural.traction[:, selected],
                            n_points)


def _ratio(value: float, scale: float) -> float:
    return float(value / scale) if scale > 0 else 0.0
