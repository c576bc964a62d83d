"""Pictures of a result directory: the deformed body and the ΓC profiles (matplotlib, off-screen).

Everything is read back from ``solution.h5`` (:func:`contactfem.io.read_hdf5`): the mesh,
the fields, the contact arrays, the obstacle (``/contact`` attributes), the title and the
units (root attributes); the case file is not read again. Nothing here prints;
:func:`make_pictures` returns what it wrote.

What ``deformed.png`` draws (its caption says it too):

- the body at x + f·u, coloured by the von Mises stress (colour bar in the case's stress
  unit), on axes with coordinates in the case's length unit and a scale bar;
- f·u magnifies the displacement (auto: the largest displacement a tenth of the body's
  size, or less so that no triangle turns over, :func:`turn_over_limit`), but never the
  body across the obstacle: where the magnified point would come closer to the obstacle's
  line than :data:`KEEP_FRACTION` of its true distance (gap g0 − u·n), its component along
  the obstacle's normal is cut back to that distance (:func:`drawn_positions`). A point
  drawn on the line is therefore in contact, and a point apart stays visibly apart. An
  obstacle that starts inside the body (an imposed indentation) is drawn moved by f − 1
  times that overlap (:func:`drawn_obstacle`), its rest position dotted;
- the undeformed outline in grey, the obstacle (its line, or its segment when
  ``/contact`` has ``obstacle_ends``) with its side shaded, ΓC thick red where it touches
  (active nodes as dots) and blue where it lifts off;
- a second panel at the scale of the contact zone (or of its lift-off end when the zone
  covers much of ΓC), with its own magnification, and its window outlined in the first;
- mesh edges only where a triangle is at least :data:`EDGE_PIXELS` pixels across, thin
  and light, so graded meshes do not turn the contact region black.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactfem.errors import CaseError
from contactfem.io.atomic import ensure_directory
from contactfem.io.registry import (
    COMPARE_JSON,
    COMPARE_PNG,
    CONVERGENCE_JSON,
    CONVERGENCE_PNGS,
    DEFORMED_PNG,
    PICTURES,
    PROFILE_PNG,
    SOLUTION_H5,
)
from contactfem.picture_text import chars_across, heading, save_png, shown

__all__ = ["DEFORMED_PNG", "PROFILE_PNG", "auto_scale", "drawn_positions",
           "load_result", "make_pictures", "parse_size", "parse_zoom", "pictures_of", "render_deformed",
           "units_of"]

#: The auto magnification makes the largest displacement this fraction of the body's size.
AUTO_FRACTION = 0.10
#: A drawn point keeps at least this fraction of its true distance from the obstacle's line.
KEEP_FRACTION = 0.5
#: A triangle's edges are drawn when it is at least this many pixels across.
EDGE_PIXELS = 8.0
#: Above this many triangles no edges are drawn at all.
_EDGES_UP_TO = 200_000
#: The zoom frames the whole contact zone when it spans at most this fraction of ΓC.
ZOOM_WHOLE_ZONE = 0.3
#: Otherwise it frames the zone's first lift-off end, this fraction of ΓC wide.
ZOOM_END_WIDTH = 0.25
_DPI = 100
#: A unit symbol is shown with at most this many characters (a case's units have at most 16).
UNIT_CHARS = 24
#: The zoom panel's place in the figure (left, bottom, width, height as fractions).
_ZOOM_BOX = (0.69, 0.36, 0.29, 0.36)
_BODY_COLOURS = "viridis"
_CONTACT_RED = "#d62728"
_APART_BLUE = "#1f77b4"


def parse_size(text: str) -> tuple[int, int]:
    """``"1200x900"`` -> (1200, 900); each side in [100, 8000]."""
    parts = text.lower().replace("×", "x").split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise CaseError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 1200x900") from None
    if not (100 <= width <= 8000 and 100 <= height <= 8000):
        raise CaseError(f"--size {text!r}: each side must be between 100 and 8000 pixels")
    return width, height


def parse_zoom(text: str | None) -> tuple[float, float] | None:
    """``"0.2:0.25"`` -> (0.2, 0.25), a window along the obstacle; None -> None."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        low = high = float("nan")
    if not (np.isfinite(low) and np.isfinite(high) and low < high):
        raise CaseError(f"--zoom {text!r}: expected FROM:TO, two finite positions along the obstacle with "
                        "FROM < TO, e.g. 0.2:0.25")
    return low, high


def parse_scale(text: str) -> float | None:
    """``"auto"`` -> None; a positive finite number otherwise."""
    if text.strip().lower() == "auto":
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value) or value <= 0:
        raise CaseError(f"--scale {text!r}: expected auto or a positive number")
    return value


def load_result(result_dir: Path | str) -> dict:
    """``read_hdf5(result_dir/solution.h5)``; a missing file is bad input (CaseError)."""
    from contactfem.io import read_hdf5

    path = Path(result_dir) / SOLUTION_H5
    if not path.is_file():
        raise CaseError(f"{result_dir}: no solution.h5 here; run `contactfem solve` first "
                        "(with h5 in output.files)")
    return read_hdf5(path)


def obstacle_of(data: dict) -> tuple | None:
    """(point, unit normal into the obstacle, segment ends (2, 2) or None) as stored with the
    contact fields, where a moving obstacle went, or None (files older than schema 2).

    A curved obstacle (``/contact/obstacle_vertices``) adds its surface (k, 2) where it
    went and its shift from rest (2,): (point, mean normal, None, surface, shift)."""
    contact = data.get("contact", {})
    attrs = contact.get("attrs", {})
    if "obstacle_point" not in attrs or "obstacle_normal" not in attrs:
        return None
    ends = attrs.get("obstacle_ends")
    shift = np.asarray(attrs.get("obstacle_shift", (0.0, 0.0)), dtype=float).reshape(2)
    point, normal = np.asarray(attrs["obstacle_point"], dtype=float) + shift, np.asarray(attrs["obstacle_normal"], dtype=float)
    if "obstacle_vertices" in contact:
        surface = np.asarray(contact["obstacle_vertices"], dtype=float).reshape(-1, 2) + shift
        return point, normal, None, surface, shift
    return point, normal, None if ends is None else np.asarray(ends, dtype=float).reshape(2, 2) + shift


def units_of(data: dict) -> dict[str, str]:
    """The case's units as stored in solution.h5 (empty strings in files written before they were)."""
    attrs = data.get("attrs", {})
    return {name: shown(attrs.get(f"{name}_unit", ""), UNIT_CHARS) for name in ("length", "force", "stress")}


def with_unit(label: str, unit: str) -> str:
    """``"x (m)"``, or the bare label when the unit is not known."""
    return f"{label} ({unit})" if unit else label


def _title(data: dict) -> str:
    """The case's title as stored (one line, at most :data:`contactfem.picture_text.USER_CHARS`
    characters: :func:`contactfem.picture_text.shown`)."""
    return shown(data.get("attrs", {}).get("title") or "contactfem result")


def auto_scale(points: np.ndarray, displacement: np.ndarray, fraction: float = AUTO_FRACTION) -> float:
    """The factor making max |u| equal ``fraction`` of the bounding-box diagonal (1 if u = 0)."""
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    largest = float(np.linalg.norm(displacement, axis=1).max()) if len(displacement) else 0.0
    if largest <= 0 or not np.isfinite(largest):
        return 1.0
    return fraction * size / largest


def turn_over_limit(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray) -> float:
    """The largest factor f with f·‖∇u‖ ≤ 1 on every triangle (Frobenius norm of the P1
    gradient): x + f·u then turns no triangle over (inf when u is constant)."""
    corners = points[triangles]
    frame = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=-1)
    values = displacement[triangles]
    change = np.stack([values[:, 1] - values[:, 0], values[:, 2] - values[:, 0]], axis=-1)
    with np.errstate(all="ignore"):
        gradient = change @ np.linalg.inv(frame)
    size = np.sqrt((gradient**2).sum(axis=(1, 2)))
    size = size[np.isfinite(size)]
    largest = float(size.max()) if len(size) else 0.0
    return 1.0 / largest if largest > 0 else float("inf")


def imposed_approach(data: dict) -> float:
    """How far the obstacle starts inside the body (≥ 0): minus the most negative initial gap of
    the contact nodes, an indentation imposed by the data (a punch set into the body)."""
    contact = data.get("contact", {})
    if np.any(contact.get("attrs", {}).get("obstacle_shift", 0.0)):
        return 0.0  # a moving obstacle: its gaps are those it went to, not where it started
    gaps = np.asarray(contact.get("gap", []), dtype=float)
    return float(max(0.0, -gaps.min())) if len(gaps) else 0.0


def drawn_obstacle(obstacle: tuple | None, normal_factor: float, approach: float) -> tuple | None:
    """The obstacle as drawn: moved towards the body by (normal_factor − 1)·approach, so that an
    imposed indentation is magnified like the displacement it causes (unchanged without one)."""
    if obstacle is not None and len(obstacle) == 5:  # curved: its motion magnified like the body's
        point, normal, _, surface, shift = obstacle
        if normal_factor <= 1:
            return obstacle
        # A moving obstacle's advance magnified like the displacement it causes; else an
        # imposed indentation's, towards the body along the mean normal.
        more = (normal_factor - 1.0) * (shift if shift.any() else -max(approach, 0.0) * normal)
        return point + more, normal, None, surface + more, shift
    if obstacle is None or approach <= 0 or normal_factor <= 1:
        return obstacle
    point, normal, ends = obstacle
    shift = -(normal_factor - 1.0) * approach * normal
    return point + shift, normal, None if ends is None else ends + shift


def drawn_positions(points: np.ndarray, displacement: np.ndarray, factor: float,
                    obstacle: tuple | None = None, keep: float = KEEP_FRACTION,
                    normal_factor: float | None = None, approach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Where the body is drawn: x + factor·u, never across the obstacle.

    With an obstacle (point p, unit normal n into it, optional segment ends), the
    displacement's component along n is magnified by ``normal_factor`` (default
    ``factor``) and the rest by ``factor``; the obstacle is drawn moved by
    :func:`drawn_obstacle` (by (normal_factor − 1)·``approach`` towards the body, when the
    data set it ``approach`` into the body). A point's true distance from the obstacle is
    G = (p − x)·n − u·n, its drawn one D from the drawn obstacle. Where D < keep·max(G, 0),
    the drawn point is moved back along n to distance keep·max(G, 0): the magnification
    never carries a point onto or across the drawn obstacle's line, and only points in
    contact (G = 0) are drawn on it. For a segment, only points drawn in front of it
    (between its ends) are limited.

    Returns
    -------
    drawn : (n, 2) float64
    limited : (n,) bool
        The points whose normal component was cut back.
    """
    drawn = points + factor * displacement
    limited = np.zeros(len(points), dtype=bool)
    if obstacle is None:
        return drawn, limited
    point, normal = obstacle[0], obstacle[1]
    normal_factor = factor if normal_factor is None else normal_factor
    if len(obstacle) == 5:
        return _drawn_by_curved(points, displacement, factor, obstacle, keep, normal_factor, approach)
    shown = drawn_obstacle((point, normal, obstacle[2] if len(obstacle) > 2 else None), normal_factor, approach)
    ends = shown[2]
    start = (point - points) @ normal
    moved = displacement @ normal
    drawn += (normal_factor - factor) * moved[:, None] * normal
    true_gap = start - moved
    drawn_gap = (shown[0] - points) @ normal - normal_factor * moved
    floor = keep * np.maximum(true_gap, 0.0)
    limited = drawn_gap < floor
    if ends is not None:
        tangent = np.array([-normal[1], normal[0]])
        low, high = sorted(ends @ tangent)
        along = drawn @ tangent
        limited &= (along >= low) & (along <= high)
    drawn[limited] += (drawn_gap[limited] - floor[limited])[:, None] * normal
    return drawn, limited


def _drawn_by_curved(points: np.ndarray, displacement: np.ndarray, factor: float, obstacle: tuple, keep: float,
                     normal_factor: float, approach: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`drawn_positions` for a curved obstacle: the true distance G of x + u and the
    drawn one D of the drawn point are measured to each one's closest point on the obstacle
    (where it went, and as drawn); where D < keep·max(G, 0), the drawn point is moved back
    along the drawn obstacle's normal there."""
    from contactfem.discretize.indenters import Polyline

    normal = obstacle[1]
    moved = displacement @ normal
    drawn = points + factor * displacement + (normal_factor - factor) * moved[:, None] * normal
    true = Polyline(vertices=obstacle[3]).closest(points + displacement)
    shown = Polyline(vertices=drawn_obstacle(obstacle, normal_factor, approach)[3]).closest(drawn)
    floor = keep * np.maximum(true.gap, 0.0)
    limited = shown.faces & (shown.gap < floor)
    drawn[limited] += (shown.gap[limited] - floor[limited])[:, None] * shown.normals[limited]
    return drawn, limited


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _nice_length(span: float) -> float:
    """A round length (1, 2 or 5 × 10^k) of about a fifth of ``span``."""
    target = span / 5
    if not target > 0:
        return 1.0
    power = 10.0 ** np.floor(np.log10(target))
    return float(min((m * power for m in (1, 2, 5, 10)), key=lambda v: abs(np.log(v / target))))


def _emptiest_corner(drawn: np.ndarray, xlim, ylim) -> str:
    """The axes corner (matplotlib ``loc`` name) with the fewest drawn points near it."""
    width, height = xlim[1] - xlim[0], ylim[1] - ylim[0]
    counts = {}
    for name, (fx, fy) in {"lower right": (1, 0), "lower left": (0, 0), "upper right": (1, 1),
                           "upper left": (0, 1)}.items():
        cx, cy = xlim[0] + fx * width, ylim[0] + fy * height
        near = (np.abs(drawn[:, 0] - cx) < 0.3 * width) & (np.abs(drawn[:, 1] - cy) < 0.15 * height)
        counts[name] = int(near.sum())
    return min(counts, key=counts.get)


def _contact_state(data: dict, n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ΓC edges (k, 2), closed (k,) edges in the contact zone, active (n_points,) mask)."""
    contact = data["contact"]
    nodes = np.asarray(contact["nodes"], dtype=np.int64)
    active = np.zeros(n_points, dtype=bool)
    active[nodes[np.asarray(contact["active"], dtype=bool)]] = True
    in_contact_set = np.zeros(n_points, dtype=bool)
    in_contact_set[nodes] = True
    edges = np.asarray(contact["edges"], dtype=np.int64).reshape(-1, 2)
    # An edge is in the contact zone when each end is active or carries no multiplier
    # (a support node), and at least one end is active.
    closed = (active | ~in_contact_set)[edges].all(axis=1) & active[edges].any(axis=1)
    return edges, closed, active


def zoom_window(data: dict) -> dict | None:
    """The window of the zoom panel along the obstacle, or None (no contact, or contact all along ΓC).

    Returns ``{"from": s0, "to": s1, "what": text}`` in abscissae along the obstacle (the
    coordinate of report.json's contact_zone intervals).
    """
    contact = data["contact"]
    obstacle = obstacle_of(data)
    if "abscissa" not in contact or obstacle is None:
        return None
    s = np.asarray(contact["abscissa"], dtype=float)
    active = np.asarray(contact["active"], dtype=bool)
    if not active.any() or len(s) < 3:
        return None
    order = np.argsort(s, kind="stable")
    s, active = s[order], active[order]
    # ΓC's extent counts the nodes a finite obstacle does not reach as well.
    tangent = np.array([-obstacle[1][1], obstacle[1][0]])
    gamma = np.unique(np.asarray(contact["edges"], dtype=np.int64))
    along = np.asarray(data["mesh"]["points"], dtype=float)[gamma] @ tangent
    extent = float(max(np.ptp(along) if len(along) else 0.0, s[-1] - s[0]))
    low, high = float(s[active].min()), float(s[active].max())
    spacing = float(np.median(np.diff(s))) if len(s) > 1 else extent / 10
    if high - low <= ZOOM_WHOLE_ZONE * extent:
        half = max(0.5 * (high - low) * 1.8, 6 * spacing)
        centre = 0.5 * (low + high)
        return {"from": centre - half, "to": centre + half, "what": "the contact zone"}
    # The zone covers much of ΓC: frame the first place where the body lifts off.
    change = np.flatnonzero(active[1:] != active[:-1])
    if not change.size:
        return None
    i = int(change[0])
    centre = 0.5 * (s[i] + s[i + 1])
    half = max(0.5 * ZOOM_END_WIDTH * extent, 6 * spacing)
    return {"from": centre - half, "to": centre + half, "what": "where the contact zone ends"}


def _window_box(obstacle, window: dict, aspect: float,
                centre: np.ndarray | None = None) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis-aligned limits of the zoom: ``window`` along the obstacle, mostly on the body's side."""
    point, normal = obstacle[0], obstacle[1]
    tangent = np.array([-normal[1], normal[0]])
    s0, s1 = window["from"], window["to"]
    base = point - (point @ tangent) * tangent
    if len(obstacle) == 5 and centre is not None:  # along a curved obstacle: about the nodes in the window
        base = centre - (0.5 * (s0 + s1)) * tangent
    width = s1 - s0
    depth = width * aspect
    corners = np.array([base + s * tangent + d * normal for s in (s0, s1) for d in (0.15 * depth, -0.85 * depth)])
    return (float(corners[:, 0].min()), float(corners[:, 0].max())), (float(corners[:, 1].min()),
                                                                       float(corners[:, 1].max()))


def _draw_panel(ax, plt, data: dict, drawn: np.ndarray, shown_obstacle, norm, cmap, xlim, ylim, units: dict,
                pixels_per_unit: float) -> None:
    """Body, outline, obstacle (as drawn, and where it rests when it was moved), ΓC and active
    nodes of ``drawn`` into ``ax`` with limits xlim × ylim."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.patches import Polygon
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    mesh, fields = data["mesh"], data["fields"]
    points = np.asarray(mesh["points"], dtype=float)
    triangles = np.asarray(mesh["triangles"], dtype=np.int64)
    corners = drawn[triangles]
    # Only triangles that reach into the window are drawn (the zoom shows a small part).
    low, high = corners.min(axis=1), corners.max(axis=1)
    visible = ((high[:, 0] >= xlim[0]) & (low[:, 0] <= xlim[1]) & (high[:, 1] >= ylim[0]) & (low[:, 1] <= ylim[1]))
    faces = cmap(norm(np.asarray(fields["von_mises"], dtype=float)[visible]))
    # Edges: the face colour (which hides the seams between triangles) where the mesh is
    # dense on screen, a lighter tint of it where a triangle is large enough to read.
    edge_colours = faces.copy()
    if len(triangles) <= _EDGES_UP_TO:
        across = np.max(high[visible] - low[visible], axis=1) * pixels_per_unit
        tint = 0.4 * np.clip(across / EDGE_PIXELS - 1.0, 0.0, 1.0)[:, None]
        edge_colours[:, :3] = (1 - tint) * faces[:, :3] + tint
    ax.add_collection(PolyCollection(corners[visible], facecolors=faces, edgecolors=edge_colours,
                                     linewidths=0.35, zorder=2))
    outline = np.asarray(mesh["boundary_edges"], dtype=np.int64).reshape(-1, 2)
    ax.add_collection(LineCollection(points[outline], colors="#8c8c8c", linewidths=0.8, linestyles="--",
                                     zorder=1.5, label="undeformed outline"))

    rest = obstacle_of(data)
    if shown_obstacle is not None and len(shown_obstacle) == 5:
        _draw_curved(ax, shown_obstacle, rest, max(xlim[1] - xlim[0], ylim[1] - ylim[0]))
    elif shown_obstacle is not None:
        reach = 10 * max(xlim[1] - xlim[0], ylim[1] - ylim[0])
        centre = np.array([0.5 * (xlim[0] + xlim[1]), 0.5 * (ylim[0] + ylim[1])])

        def surface(obstacle) -> tuple[np.ndarray, np.ndarray]:
            point, normal, ends = obstacle
            if ends is not None:
                return ends[0], ends[1]
            tangent = np.array([-normal[1], normal[0]])
            foot = point + ((centre - point) @ tangent) * tangent
            return foot - reach * tangent, foot + reach * tangent

        normal = shown_obstacle[1]
        a, b = surface(shown_obstacle)
        depth = reach if shown_obstacle[2] is None else 0.06 * max(xlim[1] - xlim[0], ylim[1] - ylim[0])
        band = Polygon(np.array([a, b, b + depth * normal, a + depth * normal]), closed=True, facecolor="#e4e4e4",
                       edgecolor="#a0a0a0", hatch="//", linewidth=0, zorder=0.5)
        ax.add_patch(band)
        ax.plot([a[0], b[0]], [a[1], b[1]], color="black", linewidth=1.4, zorder=1, label="rigid obstacle")
        if rest is not None and not np.allclose(rest[0], shown_obstacle[0]):
            a, b = surface(rest)
            ax.plot([a[0], b[0]], [a[1], b[1]], color="black", linewidth=0.8, linestyle=":", zorder=1,
                    label="obstacle at rest")

    edges, closed, active = _contact_state(data, len(points))
    if (~closed).any():
        ax.add_collection(LineCollection(drawn[edges[~closed]], colors=_APART_BLUE, linewidths=1.6, zorder=3,
                                         label="contact boundary ΓC, apart"))
    if closed.any():
        ax.add_collection(LineCollection(drawn[edges[closed]], colors=_CONTACT_RED, linewidths=3.0, zorder=3.1,
                                         label="ΓC in contact"))
    if active.any():
        ax.plot(drawn[active, 0], drawn[active, 1], "o", color=_CONTACT_RED, markersize=3.2, zorder=4,
                linestyle="none", label="active nodes")

    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(with_unit("x", units["length"]))
    ax.set_ylabel(with_unit("y", units["length"]))
    ax.tick_params(labelsize=8)
    length = _nice_length(xlim[1] - xlim[0])
    ax.add_artist(AnchoredSizeBar(ax.transData, length, f"{length:g} {units['length']}".strip(),
                                  _emptiest_corner(drawn, xlim, ylim), pad=0.4, borderpad=0.6, sep=4,
                                  frameon=True, size_vertical=0, fontproperties={"size": 8}))


def _draw_curved(ax, shown: tuple, rest: tuple | None, span: float) -> None:
    """A curved obstacle: its surface, shaded on its side (a circle filled), dotted at rest when it moved."""
    from matplotlib.patches import Polygon

    surface = shown[3]
    closed = len(surface) > 2 and np.allclose(surface[0], surface[-1])
    if closed:
        region = surface
    else:
        step = np.diff(surface, axis=0)
        side = np.stack([step[:, 1], -step[:, 0]], axis=1)
        side = side / np.maximum(np.hypot(*side.T), 1e-300)[:, None]
        depth = 0.06 * span * (side.sum(axis=0) / max(float(np.hypot(*side.sum(axis=0))), 1e-300))
        region = np.concatenate([surface, surface[::-1] + depth])
    ax.add_patch(Polygon(region, closed=True, facecolor="#e4e4e4", edgecolor="#a0a0a0", hatch="//", linewidth=0,
                         zorder=0.5))
    ax.plot(surface[:, 0], surface[:, 1], color="black", linewidth=1.4, zorder=1, label="rigid obstacle")
    if rest is not None and rest[4].any():
        at_rest = rest[3] - rest[4]
        ax.plot(at_rest[:, 0], at_rest[:, 1], color="black", linewidth=0.8, linestyle=":", zorder=1,
                label="obstacle at rest")


def _limits(drawn: np.ndarray, points: np.ndarray, data: dict) -> tuple[tuple, tuple]:
    """The first panel's limits: the drawn and undeformed body with a margin, and some of the obstacle."""
    box = np.concatenate([drawn, points])
    low, high = box.min(axis=0), box.max(axis=0)
    size = float(np.max(high - low)) or 1.0
    obstacle = obstacle_of(data)
    if obstacle is not None:
        nodes = np.asarray(data["contact"]["nodes"], dtype=np.int64)
        if len(nodes):
            beyond = drawn[nodes] + 0.06 * size * obstacle[1]
            low, high = np.minimum(low, beyond.min(axis=0)), np.maximum(high, beyond.max(axis=0))
    margin = 0.04 * size
    return (float(low[0] - margin), float(high[0] + margin)), (float(low[1] - margin), float(high[1] + margin))


def _fit(xlim, ylim, ratio: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Limits grown about their centre so that height / width = ``ratio`` (the panel's, in pixels)."""
    width, height = xlim[1] - xlim[0], ylim[1] - ylim[0]
    if height < ratio * width:
        grow = 0.5 * (ratio * width - height)
        ylim = (ylim[0] - grow, ylim[1] + grow)
    else:
        grow = 0.5 * (height / ratio - width)
        xlim = (xlim[0] - grow, xlim[1] + grow)
    return xlim, ylim


def _pixel_box(ax, figure) -> list[float]:
    """The panel's axes area in image pixels: [first column, first row, last column, last row] (rows from the top)."""
    box = ax.get_window_extent()
    height = figure.bbox.height
    return [float(box.x0), float(height - box.y1), float(box.x1), float(height - box.y0)]


def _pixel_transform(ax, figure) -> list[list[float]]:
    """The affine map data (x, y) -> image pixel (column, row from the top) of ``ax``, as 2 × 3."""
    matrix = ax.transData.get_matrix()
    height = figure.bbox.height
    return [[float(matrix[0, 0]), float(matrix[0, 1]), float(matrix[0, 2])],
            [float(-matrix[1, 0]), float(-matrix[1, 1]), float(height - matrix[1, 2])]]


def render_deformed(data: dict, path: Path, size: tuple[int, int] = (1200, 900),
                    scale: float | None = None) -> dict:
    """Draw the deformed body (see the module docstring) into the PNG ``path`` of exactly ``size`` pixels.

    Returns
    -------
    dict
        ``scale`` (f of the first panel), ``zoom_scale`` (the zoom's, or None),
        ``limited_points`` (points whose normal displacement was cut back) and ``panels``:
        per panel (``body``, ``zoom``) ``pixel_transform``, the 2 × 3 affine map from (x, y)
        to the image's (column, row from the top), ``pixel_box`` its axes area in pixels
        [column, row, column, row], and ``obstacle``, the obstacle as drawn there (point,
        normal, ends or None).
    """
    plt = _pyplot()
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    mesh, fields = data["mesh"], data["fields"]
    points = np.asarray(mesh["points"], dtype=float)
    displacement = np.asarray(fields["displacement"], dtype=float)
    von_mises = np.asarray(fields["von_mises"], dtype=float)
    units = units_of(data)
    obstacle = obstacle_of(data)
    triangles = np.asarray(mesh["triangles"], dtype=np.int64)
    turn_over = turn_over_limit(points, triangles, displacement)
    factor = min(auto_scale(points, displacement), turn_over) if scale is None else float(scale)
    approach = imposed_approach(data)
    drawn, limited = drawn_positions(points, displacement, factor, obstacle, approach=approach)
    shown_obstacle = drawn_obstacle(obstacle, factor, approach)
    cmap = colormaps[_BODY_COLOURS]
    finite = von_mises[np.isfinite(von_mises)]
    norm = Normalize(vmin=float(finite.min()) if len(finite) else 0.0,
                     vmax=float(finite.max()) if len(finite) else 1.0)

    window = zoom_window(data)
    width_px, height_px = size
    figure = plt.figure(figsize=(width_px / _DPI, height_px / _DPI), dpi=_DPI)
    try:
        scale_text = min(width_px / 1200, height_px / 900)
        font = max(6.0, 10.5 * scale_text)
        main_width = 0.55 if window is not None else 0.87
        body_ax = figure.add_axes((0.075, 0.175, main_width, 0.62))
        xlim, ylim = _fit(*_limits(drawn, points, data), (0.62 * height_px) / (main_width * width_px))
        pixels_per_unit = main_width * width_px / (xlim[1] - xlim[0])
        _draw_panel(body_ax, plt, data, drawn, shown_obstacle, norm, cmap, xlim, ylim, units, pixels_per_unit)
        auto_turned = scale is None and turn_over < auto_scale(points, displacement)
        lines = _caption_lines(data, factor, scale, auto_turned, approach, limited, units)
        title = heading(_title(data), chars_across(0.98 * width_px, font * 1.25 * 1.1), lines=1)  # bold is wider
        figure.text(0.01, 0.985, title, fontsize=font * 1.25, fontweight="bold", va="top")
        figure.text(0.01, 0.945, "\n".join(lines), fontsize=font * 0.85, va="top", linespacing=1.4)
        body_ax.set_title("the whole body", fontsize=font)

        panels = {"body": body_ax}
        zoom_factor = None
        if window is not None:
            panels["zoom"], zoom_factor = _draw_zoom(figure, plt, body_ax, data, window, factor, scale, approach,
                                                     norm, cmap, units, font, size)
        _draw_legend_and_bar(figure, body_ax, norm, cmap, units, font, main_width, zoomed=window is not None)
        _save_png(figure, path)
        transforms = {name: {"pixel_transform": _pixel_transform(ax, figure), "pixel_box": _pixel_box(ax, figure)}
                      for name, ax in panels.items()}
        transforms["body"]["obstacle"] = shown_obstacle
        if "zoom" in transforms:
            transforms["zoom"]["obstacle"] = drawn_obstacle(obstacle, zoom_factor, approach)
    finally:
        plt.close(figure)
    return {"scale": factor, "zoom_scale": zoom_factor, "limited_points": int(limited.sum()), "panels": transforms}


def _caption_lines(data: dict, factor: float, scale: float | None, auto_turned: bool, approach: float,
                   limited: np.ndarray, units: dict) -> list[str]:
    """The caption under the title: the method, the magnification and how it was chosen
    (``auto_turned``: the auto factor was lowered so that no triangle turns over), the
    moved obstacle and the points cut back."""
    method = shown(data["attrs"].get("method", "?"), 40)
    multiplier = {"positive": "λh ≥ 0, method (4)", "standard": "θh, method (5)"}.get(method, method)
    if scale is None:
        how = (" (auto: no triangle turned over, f·|∇u| ≤ 1)" if auto_turned
               else " (auto: the largest displacement is 10% of the body's size)")
    else:
        how = ""
    lines = [f"method {method} ({multiplier}); body drawn at x + f·u with f = {factor:.3g}{how}"]
    if approach > 0 and factor > 1:
        lines.append(f"the obstacle starts {approach:.3g} {units['length']} inside the body (an imposed "
                     f"indentation): it is drawn moved by (f − 1) × that towards the body, dotted where it rests")
    if limited.any():
        lines.append(f"towards the obstacle, f·u is cut back where it would bring a point closer than "
                     f"{KEEP_FRACTION:g}× its true distance: {int(limited.sum())} points; "
                     "points drawn on the obstacle are in contact")
    else:
        lines.append("every point is drawn at x + f·u: none comes closer to the obstacle than "
                     f"{KEEP_FRACTION:g}× its true distance; points on the obstacle are in contact")
    return lines


def _draw_zoom(figure, plt, body_ax, data: dict, window: dict, factor: float, scale: float | None,
               approach: float, norm, cmap, units: dict, font: float, size: tuple[int, int]) -> tuple[object, float]:
    """The zoom panel on ``window``, its frame outlined in the first panel; returns its axes and
    its (normal) magnification."""
    from matplotlib.patches import Rectangle

    width_px, height_px = size
    points = np.asarray(data["mesh"]["points"], dtype=float)
    triangles = np.asarray(data["mesh"]["triangles"], dtype=np.int64)
    displacement = np.asarray(data["fields"]["displacement"], dtype=float)
    obstacle = obstacle_of(data)
    zoom_ax = figure.add_axes(_ZOOM_BOX)
    aspect = (_ZOOM_BOX[3] * height_px) / (_ZOOM_BOX[2] * width_px)
    zxlim, zylim = _fit(*_window_box(obstacle, window, aspect, _window_centre(data, window)), aspect)
    inside = ((points[:, 0] >= zxlim[0]) & (points[:, 0] <= zxlim[1]) & (points[:, 1] >= zylim[0])
              & (points[:, 1] <= zylim[1]))
    # The zoom magnifies the normal displacement so that the gaps it frames can be
    # seen (the largest normal displacement in it a tenth of its height), and the
    # tangential one no more than the first panel does.
    normal_moves = np.abs(displacement[inside] @ obstacle[1]) if inside.any() else np.zeros(1)
    largest = float(normal_moves.max())
    zoom_factor = AUTO_FRACTION * (zylim[1] - zylim[0]) / largest if largest > 0 else factor
    if scale is None:  # nor turning a triangle of the window over
        near = inside[triangles].any(axis=1)
        zoom_factor = min(zoom_factor, turn_over_limit(points, triangles[near], displacement))
    tangential_factor = min(factor, zoom_factor)
    zoom_drawn, _ = drawn_positions(points, displacement, tangential_factor, obstacle,
                                    normal_factor=zoom_factor, approach=approach)
    _draw_panel(zoom_ax, plt, data, zoom_drawn, drawn_obstacle(obstacle, zoom_factor, approach), norm, cmap,
                zxlim, zylim, units, _ZOOM_BOX[2] * width_px / (zxlim[1] - zxlim[0]))
    title = (f"f = {zoom_factor:.3g}" if np.isclose(tangential_factor, zoom_factor) else
             f"normal f = {zoom_factor:.3g}, tangential f = {tangential_factor:.3g}")
    zoom_ax.set_title(f"zoom on {window['what']}\n{title}", fontsize=font)
    body_ax.add_patch(Rectangle((zxlim[0], zylim[0]), zxlim[1] - zxlim[0], zylim[1] - zylim[0],
                                fill=False, edgecolor="black", linestyle=":", linewidth=1.0, zorder=5))
    return zoom_ax, zoom_factor


def _window_centre(data: dict, window: dict) -> np.ndarray | None:
    """The mean position of the contact nodes whose abscissa lies in ``window`` (None: none)."""
    contact = data["contact"]
    s = np.asarray(contact["abscissa"], dtype=float)
    inside = (s >= window["from"]) & (s <= window["to"])
    if not inside.any():
        return None
    points = np.asarray(data["mesh"]["points"], dtype=float)[np.asarray(contact["nodes"], dtype=np.int64)[inside]]
    return points.mean(axis=0)


def _draw_legend_and_bar(figure, body_ax, norm, cmap, units: dict, font: float, main_width: float,
                         zoomed: bool) -> None:
    """The first panel's legend in the lower right corner and the von Mises colour bar under it."""
    from matplotlib.cm import ScalarMappable

    handles, labels = body_ax.get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower right", bbox_to_anchor=(0.99, 0.01), fontsize=font * 0.8,
                  frameon=True, ncol=1 if zoomed else 2)
    bar_ax = figure.add_axes((0.075, 0.06, min(main_width, 0.55), 0.022))
    bar = figure.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=bar_ax, orientation="horizontal",
                          format="%.3g")
    bar.set_label(with_unit("von Mises stress", units["stress"]), fontsize=font * 0.9)
    bar.ax.tick_params(labelsize=font * 0.75)


def _save_png(figure, path: Path) -> None:
    """Write ``figure`` as the PNG ``path`` (atomically, its texts literal); a failed write is an
    :class:`~contactfem.errors.OutputError`."""
    ensure_directory(Path(path).parent)
    save_png(figure, path, dpi=_DPI)


def make_pictures(result_dir: Path | str, out_dir: Path | str | None = None,
                  size: tuple[int, int] = (1200, 900), scale: float | None = None,
                  window: tuple[float, float] | None = None) -> dict:
    """Write ``deformed.png`` and ``contact_profile.png`` of ``result_dir`` into ``out_dir``;
    ``window`` (from, to along the obstacle) is the profile's zoom window (default: its
    densest stretch of patches, when there are many).

    Returns ``{"files": [...], "scale": factor, "zoom_scale": factor or None, "size": [w, h]}``
    (JSON-ready).
    """
    from contactfem.plots import plot_result_profile

    data = load_result(result_dir)
    out = ensure_directory(Path(out_dir) if out_dir is not None else Path(result_dir))
    drawn = render_deformed(data, out / DEFORMED_PNG, size=size, scale=scale)
    plot_result_profile(out / PROFILE_PNG, data, size=size, title=_title(data), window=window)
    return {"files": [str(out / DEFORMED_PNG), str(out / PROFILE_PNG)], "scale": drawn["scale"],
            "zoom_scale": drawn["zoom_scale"], "size": list(size)}


def pictures_of(result_dir: Path | str) -> tuple[str, ...]:
    """The PNGs ``contactfem plot`` draws for ``result_dir``: deformed.png and contact_profile.png
    of a solve (solution.h5), compare.png of a compare (compare.json), the convergence PNGs of a
    converge (convergence.json); a directory holding none of them is bad input (CaseError)."""
    directory = Path(result_dir)
    names: tuple[str, ...] = ()
    if (directory / SOLUTION_H5).is_file():
        names += PICTURES
    if (directory / COMPARE_JSON).is_file():
        names += (COMPARE_PNG,)
    if (directory / CONVERGENCE_JSON).is_file():
        names += CONVERGENCE_PNGS
    if not names:
        raise CaseError(f"{result_dir}: no solution.h5, compare.json or convergence.json here; run "
                        "`contactfem solve` (with h5 in output.files), `compare` or `converge` first")
    return names
