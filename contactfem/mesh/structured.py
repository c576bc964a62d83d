"""Structured triangle meshes of axis-aligned rectangles."""

from __future__ import annotations

import numpy as np

from contactfem.errors import MeshError
from contactfem.mesh.core import Mesh

__all__ = ["structured_rectangle", "SIDES", "DIAGONALS"]

#: The rectangle's sides in counter-clockwise order, starting at the lower-left corner.
SIDES: tuple[str, ...] = ("bottom", "right", "top", "left")
#: The ways a cell can be split into triangles.
DIAGONALS: tuple[str, ...] = ("right", "left", "alternate", "crossed")


def _check_count(name: str, value: object) -> int:
    """Return ``value`` as a positive int or raise MeshError."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise MeshError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def _check_corner(name: str, value: object) -> np.ndarray:
    """Return ``value`` as a finite float array (2,) or raise MeshError."""
    try:
        corner = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MeshError(f"{name} must be a pair of numbers, got {value!r}") from None
    if corner.shape != (2,) or not np.all(np.isfinite(corner)):
        raise MeshError(f"{name} must be a pair of finite numbers, got {value!r}")
    return corner


def _part_table(side_names: dict[str, str] | None) -> tuple[tuple[str, ...], np.ndarray]:
    """Part names and the part index of each side in ``SIDES`` order.

    Returns
    -------
    part_names : tuple of str
        Distinct names in order of first use along ``SIDES``.
    side_part : (4,) int64
        Index into ``part_names`` for bottom, right, top, left.
    """
    names = dict(zip(SIDES, SIDES))
    if side_names is not None:
        unknown = sorted(set(side_names) - set(SIDES))
        if unknown:
            raise MeshError(f"unknown rectangle side {unknown[0]!r}; sides are {', '.join(SIDES)}")
        for side, name in side_names.items():
            if not isinstance(name, str) or not name:
                raise MeshError(f"part name of side {side!r} must be a non-empty string, got {name!r}")
        names.update(side_names)
    part_names: list[str] = []
    for side in SIDES:
        if names[side] not in part_names:
            part_names.append(names[side])
    side_part = np.array([part_names.index(names[side]) for side in SIDES], dtype=np.int64)
    return tuple(part_names), side_part


def structured_rectangle(
    lower: tuple[float, float],
    upper: tuple[float, float],
    nx: int,
    ny: int,
    diagonal: str = "right",
    side_names: dict[str, str] | None = None,
) -> Mesh:
    """Triangulate the rectangle ``[lower, upper]`` on a uniform ``nx`` by ``ny`` grid.

    Parameters
    ----------
    lower, upper : (2,) float
        Lower-left and upper-right corners; ``upper`` must exceed ``lower`` in both x and y.
    nx, ny : int
        Number of cells in x and in y (at least 1 each).
    diagonal : {"right", "left", "alternate", "crossed"}
        How each cell is split: "right" by its lower-left to upper-right diagonal,
        "left" by its lower-right to upper-left diagonal, "alternate" with the two
        diagonals in a chessboard pattern (the mesh is then mirror-symmetric about
        the vertical centre line when ``nx`` is even), "crossed" into four triangles
        around an extra node at the cell centre.
    side_names : dict of str to str, optional
        Part name of each side ("bottom", "right", "top", "left"); a side that is
        not given is named after itself. Several sides may share a name.

    Returns
    -------
    Mesh
        Grid node ``(i, j)`` (x index i, y index j) is node ``j * (nx + 1) + i``; for
        "crossed" the centre of cell ``(i, j)`` is node ``(nx + 1) * (ny + 1) + j * nx + i``.
        ``(nx + 1) * (ny + 1)`` grid nodes and ``2 * nx * ny`` triangles
        (``4 * nx * ny`` for "crossed"). Boundary edges run counter-clockwise:
        bottom left to right, right upwards, top right to left, left downwards.

    Raises
    ------
    MeshError
        For non-positive counts, an empty rectangle, an unknown diagonal or side.
    """
    nx = _check_count("nx", nx)
    ny = _check_count("ny", ny)
    lo = _check_corner("lower corner", lower)
    hi = _check_corner("upper corner", upper)
    if not np.all(hi > lo):
        raise MeshError(f"upper corner {hi.tolist()} must exceed lower corner {lo.tolist()} in x and y")
    if diagonal not in DIAGONALS:
        raise MeshError(f"unknown diagonal {diagonal!r}; choose one of {', '.join(DIAGONALS)}")
    part_names, side_part = _part_table(side_names)

    x = np.linspace(lo[0], hi[0], nx + 1)
    y = np.linspace(lo[1], hi[1], ny + 1)
    points = np.empty(((nx + 1) * (ny + 1), 2))
    points[:, 0] = np.tile(x, ny + 1)
    points[:, 1] = np.repeat(y, nx + 1)

    # Corners of every cell, cells numbered j * nx + i.
    i, j = np.meshgrid(np.arange(nx, dtype=np.int64), np.arange(ny, dtype=np.int64))
    i = i.reshape(-1)
    j = j.reshape(-1)
    a = j * (nx + 1) + i  # lower left
    b = a + 1  # lower right
    c = b + (nx + 1)  # upper right
    d = a + (nx + 1)  # upper left

    if diagonal == "crossed":
        n_grid = len(points)
        m = n_grid + j * nx + i
        centres = 0.5 * (points[a] + points[c])
        points = np.concatenate([points, centres])
        triangles = np.stack(
            [np.stack(t, axis=1) for t in ((a, b, m), (b, c, m), (c, d, m), (d, a, m))], axis=1
        ).reshape(-1, 3)
    else:
        right_split = np.stack([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)], axis=1)
        left_split = np.stack([np.stack([a, b, d], axis=1), np.stack([b, c, d], axis=1)], axis=1)
        if diagonal == "right":
            triangles = right_split
        elif diagonal == "left":
            triangles = left_split
        else:
            # Mirroring x maps cell i to nx-1-i and swaps the diagonal direction; the
            # chessboard parity of i + j flips exactly when nx is even.
            use_right = ((i + j) % 2 == 0)[:, None, None]
            triangles = np.where(use_right, right_split, left_split)
        triangles = triangles.reshape(-1, 3)

    ix = np.arange(nx, dtype=np.int64)
    jy = np.arange(ny, dtype=np.int64)
    top_row = ny * (nx + 1)
    bottom = np.stack([ix, ix + 1], axis=1)
    right = np.stack([jy * (nx + 1) + nx, (jy + 1) * (nx + 1) + nx], axis=1)
    top = np.stack([top_row + ix + 1, top_row + ix], axis=1)[::-1]
    left = np.stack([(jy + 1) * (nx + 1), jy * (nx + 1)], axis=1)[::-1]
    edges = np.concatenate([bottom, right, top, left])
    edge_parts = np.repeat(side_part, [nx, ny, nx, ny])

    return Mesh(
        points=points,
        triangles=np.ascontiguousarray(triangles, dtype=np.int64),
        boundary_edges=edges,
        edge_parts=edge_parts,
        part_names=part_names,
    )
