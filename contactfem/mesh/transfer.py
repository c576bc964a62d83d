"""Transfer of P1 fields between meshes of one domain."""

from __future__ import annotations

import numpy as np

from contactfem.mesh.core import Mesh

#: Candidate triangles per point (nearest centroids), then for the points none of them
#: contains: graded meshes put a large triangle next to many small ones.
_CANDIDATES = (16, 256)


def locate(mesh: Mesh, where: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangle of ``mesh`` containing each point of ``where`` (q, 2) and the point's
    barycentric coordinates in it (q, 3); a point outside the mesh (a curved boundary
    drawn differently) gets the triangle whose smallest coordinate is largest.

    Candidates are the triangles with the nearest centroids (a KD-tree), so the cost is
    O(q log n) with no search structure beyond the tree."""
    from scipy.spatial import cKDTree

    where = np.asarray(where, dtype=float).reshape(-1, 2)
    corners = mesh.points[mesh.triangles]
    tree = cKDTree(corners.mean(axis=1))
    found = np.zeros(len(where), dtype=np.int64)
    bary = np.zeros((len(where), 3))
    pending = np.arange(len(where))
    for count in _CANDIDATES:
        count = min(count, mesh.n_triangles)
        _, candidates = tree.query(where[pending], k=count)
        candidates = candidates.reshape(len(pending), count)
        coordinates = _barycentric(corners[candidates], where[pending, None, :])  # (p, k, 3)
        best = np.argmax(coordinates.min(axis=2), axis=1)
        rows = np.arange(len(pending))
        found[pending] = candidates[rows, best]
        bary[pending] = coordinates[rows, best]
        scale = np.abs(coordinates[rows, best]).max(axis=1)
        inside = bary[pending].min(axis=1) >= -1e-12 * np.maximum(scale, 1.0)
        pending = pending[~inside]
        if len(pending) == 0 or count == mesh.n_triangles:
            break
    return found, bary


def _barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of ``points`` (..., 2) in triangles ``corners`` (..., 3, 2)."""
    e1, e2 = corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :]
    d = points - corners[..., 0, :]
    det = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    b1 = (d[..., 0] * e2[..., 1] - d[..., 1] * e2[..., 0]) / det
    b2 = (e1[..., 0] * d[..., 1] - e1[..., 1] * d[..., 0]) / det
    return np.stack([1.0 - b1 - b2, b1, b2], axis=-1)


def interpolate_p1(mesh: Mesh, values: np.ndarray, where: np.ndarray) -> np.ndarray:
    """The P1 field ``values`` (n_points, k) of ``mesh`` at the points ``where`` (q, 2)."""
    found, bary = locate(mesh, where)
    return np.einsum("qi,qi...->q...", bary, values[mesh.triangles[found]])
