"""The rigid obstacle as the contact boundary sees it: a gap, a normal and which points it faces.

An obstacle is anything with the :class:`Obstacle` protocol. The contact boundary asks it,
for the contact nodes in the reference configuration (small deformations):

- ``gap(points)`` (k,): the distance to the obstacle along its normal, positive when apart;
- ``normals(points)`` (k, 2): the unit normal at each point's closest point on the
  obstacle, pointing from the body into the obstacle;
- ``faces(points)`` (k,) bool: whether the obstacle lies in front of each point (a node
  facing no part of it carries no constraint);
- ``abscissa(points)`` (k,): the position of each point's closest point along the
  obstacle's surface, the coordinate contact zones and profiles are reported in;
- ``describe()``: what report.json and the archives record of it.

The flat obstacles are :class:`HalfPlane` (the infinite line bounding the half-plane
{p : (p − point)·normal ≥ 0}, given by a point and a normal or by two points on the line)
and :class:`Segment` (the finite part of such a line between two ends: a table, a punch's
face). The curved ones (:mod:`contactfem.discretize.indenters`) are a disk and an open
polyline; each node gets the gap and normal of its closest point on them.
:func:`obstacle_of` builds the one a case describes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from contactfem.case import Obstacle as ObstacleSettings


class Obstacle(Protocol):
    """A rigid obstacle (see the module docstring)."""

    kind: str

    def gap(self, points: np.ndarray) -> np.ndarray: ...

    def normals(self, points: np.ndarray) -> np.ndarray: ...

    def faces(self, points: np.ndarray) -> np.ndarray: ...

    def abscissa(self, points: np.ndarray) -> np.ndarray: ...

    def describe(self) -> dict: ...


@dataclass(frozen=True, eq=False)
class HalfPlane:
    """The rigid half-plane {p : (p − point)·normal ≥ 0}: its surface is an infinite line.

    ``point`` (2,) on the line, ``normal`` (2,) the unit normal pointing from the body into
    the obstacle; ``tangent`` (2,) = (−n_y, n_x) is the direction abscissae are measured
    along.
    """

    point: np.ndarray
    normal: np.ndarray
    kind = "half-plane"

    #: A flat obstacle has one normal everywhere; consumers that need it read ``normal``.
    flat = True
    ends = None

    @property
    def tangent(self) -> np.ndarray:
        return np.array([-self.normal[1], self.normal[0]])

    def gap(self, points: np.ndarray) -> np.ndarray:
        """Initial gap g0 (k,) of ``points`` (k, 2) along the normal: positive when apart."""
        return (self.point - np.asarray(points, dtype=float)) @ self.normal

    def normals(self, points: np.ndarray) -> np.ndarray:
        return np.tile(self.normal, (len(points), 1))

    def abscissa(self, points: np.ndarray) -> np.ndarray:
        """Position (k,) of ``points`` (k, 2) along the obstacle's tangent."""
        return np.asarray(points, dtype=float) @ self.tangent

    def faces(self, points: np.ndarray) -> np.ndarray:
        return np.ones(len(points), dtype=bool)

    @property
    def extent(self) -> tuple[float, float] | None:
        """The abscissa range of a finite obstacle, None for an infinite one."""
        return None

    def describe(self) -> dict:
        return {"kind": self.kind, "point": [float(v) for v in self.point],
                "normal": [float(v) for v in self.normal]}


@dataclass(frozen=True, eq=False)
class Segment(HalfPlane):
    """The finite part of a half-plane's surface between ``ends`` (2, 2): only points whose
    projection along the normal falls on it face it."""

    ends: np.ndarray | None = None
    kind = "segment"

    @property
    def extent(self) -> tuple[float, float]:
        low, high = sorted(self.abscissa(self.ends))
        return float(low), float(high)

    def faces(self, points: np.ndarray) -> np.ndarray:
        """Whether each of ``points`` (k, 2) lies in front of the segment: its projection
        along the normal falls on it (ends included, to round-off)."""
        low, high = self.extent
        s = self.abscissa(points)
        slack = 1e-9 * max(high - low, abs(low), abs(high))
        return (s >= low - slack) & (s <= high + slack)

    def describe(self) -> dict:
        return {**super().describe(), "ends": np.asarray(self.ends, dtype=float).tolist()}


def obstacle_of(settings: "ObstacleSettings") -> Obstacle:
    """The obstacle a case's validated ``obstacle`` section describes."""
    if not settings.flat:
        from contactfem.discretize.indenters import Circle, Polyline

        if settings.shape == "circle":
            return Circle(center=np.asarray(settings.center, dtype=float), radius=float(settings.radius))
        return Polyline(vertices=np.asarray(settings.vertices, dtype=float))
    point = np.asarray(settings.point, dtype=float)
    normal = np.asarray(settings.normal, dtype=float)
    if settings.ends is None:
        return HalfPlane(point=point, normal=normal)
    return Segment(point=point, normal=normal, ends=np.asarray(settings.ends, dtype=float))
