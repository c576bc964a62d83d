"""The residual estimator of :mod:`contactfem.estimator` on a mesh kept in pieces: each rank sums the
terms of its own triangles, and the terms no rank can compute alone are completed by messages of
O(cut + boundary) size.

- volume terms and the jumps across edges inside a piece: on the piece's own rank;
- jumps across the cut between two pieces: each side's rank sends σ of its triangle on the cut
  (keyed by the edge's two global node ids) to all ranks, and each side adds its half of
  h_E ‖[σν]‖²_E, as the serial estimator gives each of the two triangles one half;
- natural and contact edges (the boundary, O(√n)): each rank sends σ of the triangle of each
  of its boundary edges (by the edge's row in the serial mesh) to rank 0, which holds the
  whole boundary, its loads, multipliers and displacement, and evaluates them there.

The sums agree with the serial estimator's up to the order of the additions (see
tests/test_distributed_pieces.py); what is lost is the per-triangle indicator, which no file
of a distributed run holds.
"""

from __future__ import annotations


import numpy as np

from contactfem.assembly import edge_geometry
from contactfem.estimator import TERM_NAMES, contact_terms, jump_shares, natural_terms, stress_tensors, volume_terms
from contactfem.timings import clock


def piece_energy_estimate(problem, fields, mpi, solution=None, energy: float = 0.0) -> dict | None:
    """report.json's ``accuracy.energy`` (as :func:`contactfem.accuracy.energy_estimate` gives it)
    of a solve kept in pieces: every rank calls it with its ``fields``
    (:class:`~contactfem.distributed_output.PieceFields`); rank 0 passes the boundary
    ``solution`` and a(u, u) and receives the section (None elsewhere)."""
    from contactfem.accuracy import ENERGY_METHOD

    method = mpi.bcast(None if solution is None else solution.method, root=0)
    if method != "positive":
        return None if solution is None else {
            "estimate": None, "method": ENERGY_METHOD, "guaranteed": False,
            "reason": f"the residual estimator is defined for method (4) positive, not {method}"}
    started = clock()
    piece = problem.piece
    mesh = piece.as_mesh()
    scale = 1.0 / (2.0 * problem.law.mu)
    sigma = stress_tensors(fields.stress)
    sums = dict.fromkeys(TERM_NAMES, 0.0)
    force = problem.loads.body_force
    if force is not None:
        sums["volume"] = float(volume_terms(mesh.points, mesh.triangles, force, scale, mesh.triangle_diameters(),
                                            mesh.triangle_areas()).sum())
    topology = mesh.topology
    sides = topology.edge_triangles
    interior = (sides >= 0).all(axis=1)
    t1, t2 = sides[interior].T
    length, normal = edge_geometry(mesh.points, topology.edges[interior])
    sums["jump"] = 2.0 * float(jump_shares(sigma[t1], sigma[t2], length, normal, scale).sum())
    one_sided = np.flatnonzero(~interior)
    own = sides[one_sided].max(axis=1)
    ids = piece.node_ids[topology.edges[one_sided]]
    keys = ids.min(axis=1) * np.int64(fields.n_points) + ids.max(axis=1)
    boundary = piece.node_ids[piece.boundary_edges]
    boundary_keys = boundary.min(axis=1) * np.int64(fields.n_points) + boundary.max(axis=1)
    on_boundary = np.isin(keys, boundary_keys)
    sums["jump"] += _cut_jumps(mpi, keys[~on_boundary], one_sided[~on_boundary], own[~on_boundary], sigma,
                               fields.stress, mesh, topology, scale)
    # σ of each boundary edge's triangle, by the edge's serial row, to rank 0.
    order = np.argsort(keys[on_boundary])
    found = np.searchsorted(keys[on_boundary][order], boundary_keys)
    rows_sigma = (piece.boundary_ids, sigma[own[on_boundary][order][found]])
    gathered = mpi.gather(rows_sigma, root=0)
    totals = {name: mpi.reduce(sums[name], root=0) for name in ("volume", "jump")}
    if solution is None:
        return None
    totals.update(_boundary_terms(problem, solution, gathered, scale))
    eta = float(np.sqrt(max(sum(totals.values()), 0.0)))
    norm = float(np.sqrt(max(energy, 0.0)))
    return {"estimate": eta, "relative": eta / norm if norm > 0 else None, "method": ENERGY_METHOD,
            "guaranteed": False, "terms": {name: float(np.sqrt(max(totals[name], 0.0))) for name in TERM_NAMES},
            "seconds": clock() - started}


def _cut_jumps(mpi, keys: np.ndarray, edges: np.ndarray, own: np.ndarray, sigma: np.ndarray, stress: np.ndarray,
               mesh, topology, scale: float) -> float:
    """This rank's halves of the jump terms across the cut: σ of the far triangle from the rank
    holding it (every rank sends its cut edges' keys and σ to all)."""
    rank = mpi.Get_rank()
    sent = mpi.allgather((keys, stress[own][:, :3]))  # xx yy xy
    all_keys = np.concatenate([item[0] for item in sent])
    all_sigma = np.concatenate([item[1] for item in sent])
    all_ranks = np.concatenate([np.full(len(item[0]), r) for r, item in enumerate(sent)])
    order = np.lexsort((all_ranks, all_keys))
    all_keys, all_sigma, all_ranks = all_keys[order], all_sigma[order], all_ranks[order]
    first = np.searchsorted(all_keys, keys)
    # Each cut edge is held by two ranks: the entry beside this rank's is the other side.
    other = np.where(all_ranks[first] == rank, first + 1, first)
    if len(keys) and not (np.all(other < len(all_keys)) and np.array_equal(all_keys[other], keys)):
        raise AssertionError("an edge on the cut between pieces is not held by two ranks")
    far = stress_tensors(all_sigma[other])
    length, normal = edge_geometry(mesh.points, topology.edges[edges])
    return float(jump_shares(sigma[own], far, length, normal, scale).sum())


def _boundary_terms(problem, solution, gathered: list, scale: float) -> dict[str, float]:
    """On rank 0: the natural and contact terms over the whole boundary, σ of each edge's
    triangle from the pieces (by serial row)."""
    boundary = problem.mesh
    rows = np.concatenate([item[0] for item in gathered])
    sigma = np.concatenate([item[1] for item in gathered])
    sigma = sigma[np.argsort(rows)]  # row r of the boundary mesh is serial row r: each held once
    edges = boundary.boundary_edges
    n = np.int64(boundary.n_points)
    edge_keys = edges.min(axis=1) * n + edges.max(axis=1)
    sorter = np.argsort(edge_keys)

    def row_of(pairs: np.ndarray) -> np.ndarray:
        keys = pairs.min(axis=1) * n + pairs.max(axis=1)
        return sorter[np.searchsorted(edge_keys, keys, sorter=sorter)]

    totals = dict.fromkeys(("neumann", "contact_normal", "contact_tangential", "complementarity"), 0.0)
    natural = problem.loads.natural
    if len(natural.edges):
        totals["neumann"] = float(natural_terms(natural, sigma[row_of(natural.edges)], scale).sum())
    contact = problem.contact
    if len(contact.edges):
        lam = np.zeros(boundary.n_points)
        lam[solution.contact.nodes] = solution.contact.multiplier
        parts = contact_terms(contact, boundary.points, sigma[row_of(contact.edges)], lam, solution.displacement, scale)
        for name, values in zip(("contact_normal", "contact_tangential", "complementarity"), parts):
            totals[name] = float(values.sum())
    return totals
