"""Pictures of a result directory: the deformed body (pyvista, off-screen) and the ΓC profiles.

Everything is read back from ``solution.h5`` (:func:`contactfem.io.read_hdf5`): the mesh,
the fields, the contact arrays, the obstacle (``/contact`` attributes) and the title (a root
attribute); the case file is not read again. Nothing here prints; :func:`make_pictures`
returns what it wrote.

VTK renders without an X server through its EGL window (``VTK_DEFAULT_OPENGL_WINDOW``
is set before pyvista is imported, unless the caller chose another window already).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from contactfem.errors import CaseError, OutputError
from contactfem.io.atomic import atomic_path, ensure_directory
from contactfem.io.registry import DEFORMED_PNG, PROFILE_PNG, SOLUTION_H5

__all__ = ["DEFORMED_PNG", "PROFILE_PNG", "auto_scale", "load_result", "make_pictures", "parse_size",
           "render_deformed"]

#: The auto magnification makes the largest displacement this fraction of the body's size.
AUTO_FRACTION = 0.10
#: Above this many triangles the mesh edges would only grey the picture out.
_EDGES_UP_TO = 20_000


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


def _obstacle(data: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """(point, unit normal into the obstacle) as stored with the contact fields, or None (older files)."""
    attrs = data.get("contact", {}).get("attrs", {})
    if "obstacle_point" not in attrs or "obstacle_normal" not in attrs:
        return None
    return np.asarray(attrs["obstacle_point"], dtype=float), np.asarray(attrs["obstacle_normal"], dtype=float)


def _title(data: dict) -> str:
    return str(data["attrs"].get("title") or "contactfem result")


def auto_scale(points: np.ndarray, displacement: np.ndarray, fraction: float = AUTO_FRACTION) -> float:
    """The factor making max |u| equal ``fraction`` of the bounding-box diagonal (1 if u = 0)."""
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    largest = float(np.linalg.norm(displacement, axis=1).max()) if len(displacement) else 0.0
    if largest <= 0 or not np.isfinite(largest):
        return 1.0
    return fraction * size / largest


def _pyvista():
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    return pyvista


def _lines(pv, points2: np.ndarray, edges: np.ndarray):
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    cells = np.column_stack([np.full(len(edges), 2), edges]).ravel()
    return pv.PolyData(np.column_stack([points2, np.zeros(len(points2))]), lines=cells)


def render_deformed(data: dict, path: Path, size: tuple[int, int] = (1200, 900),
                    scale: float | None = None) -> float:
    """Render the deformed body coloured by von Mises stress into ``path``; return the factor.

    Drawn: the triangles at x + factor·u (edges shown up to 20 000 triangles), a scalar
    bar, the undeformed outline in grey, the obstacle's line with a grey band on its
    side, the edges of ΓC — thick red where both ends are in contact, thin blue where
    the body lifts off — and the active nodes as red dots; the factor is written in the
    picture.
    """
    pv = _pyvista()
    mesh, fields, contact = data["mesh"], data["fields"], data["contact"]
    points = np.asarray(mesh["points"], dtype=float)
    displacement = np.asarray(fields["displacement"], dtype=float)
    factor = auto_scale(points, displacement) if scale is None else float(scale)
    deformed = points + factor * displacement
    triangles = np.asarray(mesh["triangles"], dtype=np.int64)
    body = pv.PolyData(np.column_stack([deformed, np.zeros(len(deformed))]),
                       faces=np.column_stack([np.full(len(triangles), 3), triangles]).ravel())
    body.cell_data["von Mises stress"] = np.asarray(fields["von_mises"], dtype=float)

    title = _title(data)
    method = data["attrs"].get("method", "?")

    plotter = pv.Plotter(off_screen=True, window_size=list(size))
    try:
        plotter.set_background("white")
        plotter.add_mesh(
            body, scalars="von Mises stress", cmap="viridis", show_edges=len(triangles) <= _EDGES_UP_TO,
            edge_color="#505050", line_width=0.5,
            scalar_bar_args={"title": "von Mises stress", "vertical": True, "color": "black",
                             "position_x": 0.86, "position_y": 0.15, "width": 0.06, "height": 0.7,
                             "fmt": "%.3g", "title_font_size": 16, "label_font_size": 14},
        )
        plotter.add_mesh(_lines(pv, points, mesh["boundary_edges"]), color="#9a9a9a", line_width=1.5)

        nodes = np.asarray(contact["nodes"], dtype=np.int64)
        active = np.zeros(len(points), dtype=bool)
        active[nodes[np.asarray(contact["active"], dtype=bool)]] = True
        in_contact_set = np.zeros(len(points), dtype=bool)
        in_contact_set[nodes] = True
        edges = np.asarray(contact["edges"], dtype=np.int64).reshape(-1, 2)
        # An edge is in the contact zone when each end is active or carries no multiplier
        # (a support node), and at least one end is active.
        closed = (active | ~in_contact_set)[edges].all(axis=1) & active[edges].any(axis=1)
        legend = []
        if (~closed).any():
            plotter.add_mesh(_lines(pv, deformed, edges[~closed]), color="#1f77b4", line_width=4)
            legend.append(["contact boundary, apart", "#1f77b4"])
        if closed.any():
            plotter.add_mesh(_lines(pv, deformed, edges[closed]), color="#d62728", line_width=8)
        if active.any():
            dots = pv.PolyData(np.column_stack([deformed[active], np.zeros(int(active.sum()))]))
            plotter.add_mesh(dots, color="#d62728", point_size=9, render_points_as_spheres=True)
            legend.append(["contact zone (active)", "#d62728"])

        obstacle = _obstacle(data)
        caption = f"{title}\nmethod: {method}\ndisplacement magnified x {factor:.3g}"
        if obstacle is not None:
            point, normal = obstacle
            tangent = np.array([-normal[1], normal[0]])
            extent = float(np.linalg.norm(np.ptp(deformed, axis=0))) or 1.0
            along = (deformed - point) @ tangent
            lo, hi = along.min() - 0.12 * extent, along.max() + 0.12 * extent
            a, b = point + lo * tangent, point + hi * tangent
            depth = 0.04 * extent * normal
            band = pv.PolyData(np.column_stack([np.array([a, b, b + depth, a + depth]), np.zeros(4)]),
                               faces=np.array([4, 0, 1, 2, 3]))
            plotter.add_mesh(band, color="#c8c8c8")
            plotter.add_mesh(_lines(pv, np.array([a, b]), np.array([[0, 1]])), color="black", line_width=3)
            legend.append(["rigid obstacle", "black"])
            # The gaps are not magnified with the displacement: where ΓC started away from
            # the obstacle, the magnified body can appear to cross its (true) line.
            crossing = float(((deformed[nodes] - point) @ normal).max()) if len(nodes) else 0.0
            if crossing > 1e-6 * extent:
                caption += "\nobstacle at its true position: gaps are not magnified,\nso the body may appear to cross it"

        plotter.add_text(caption, position="upper_left", font_size=12, color="black")
        if legend:
            plotter.add_legend(legend, bcolor="white", border=True, loc="lower left", size=(0.3, 0.12))
        plotter.view_xy()
        plotter.enable_parallel_projection()
        plotter.reset_camera()
        plotter.camera.zoom(0.8)
        ensure_directory(Path(path).parent)
        try:
            with atomic_path(path) as temporary:
                plotter.screenshot(str(temporary))
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    finally:
        plotter.close()
    return factor


def make_pictures(result_dir: Path | str, out_dir: Path | str | None = None,
                  size: tuple[int, int] = (1200, 900), scale: float | None = None) -> dict:
    """Write ``deformed.png`` and ``contact_profile.png`` of ``result_dir`` into ``out_dir``.

    Returns ``{"files": [...], "scale": factor, "size": [w, h]}`` (JSON-ready).
    """
    from contactfem.plots import plot_result_profile

    data = load_result(result_dir)
    out = ensure_directory(Path(out_dir) if out_dir is not None else Path(result_dir))
    factor = render_deformed(data, out / DEFORMED_PNG, size=size, scale=scale)
    title = _title(data)
    plot_result_profile(out / PROFILE_PNG, data, size=size, title=title)
    return {"files": [str(out / DEFORMED_PNG), str(out / PROFILE_PNG)], "scale": factor,
            "size": list(size)}
