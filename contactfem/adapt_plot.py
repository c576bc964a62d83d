"""adapt.png: the final mesh of ``contactfem adapt`` coloured by the error indicator η_T, and
the estimate η (with the true energy error, when the case has an exact solution) step by step.

Left: every triangle of the final (undeformed) mesh filled with the colour of its η_T on a
logarithmic scale (the indicators span decades: refinement concentrates where they were
large), ΓC drawn red, the other boundary grey; triangle edges drawn while the mesh has at
most :data:`EDGES_UP_TO` triangles. Right: η and the energy error against the displacement
unknowns of each step (log–log). The picture is written like the other pictures
(:func:`contactfem.picture_text.save_png`: atomically, its texts literal).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactfem.picture_text import chars_across, heading, shown

#: Triangle edges are drawn up to this many triangles (beyond, the fill alone).
EDGES_UP_TO = 20_000
_SIZE = (13.0, 6.5)
_DPI = 110


def _colours(indicators: np.ndarray):
    """A logarithmic colour scale over the positive indicators (zeros at its bottom)."""
    from matplotlib.colors import LogNorm, Normalize

    values = np.asarray(indicators, dtype=float)
    positive = values[np.isfinite(values) & (values > 0)]
    if not len(positive):
        return Normalize(vmin=0.0, vmax=1.0), np.zeros_like(values)
    low, high = float(positive.min()), float(positive.max())
    if high <= low:
        high = low * 10.0
    return LogNorm(vmin=low, vmax=high), np.where(np.isfinite(values) & (values > 0), values, low)


def plot_adapt(path: Path | str, points: np.ndarray, triangles: np.ndarray, indicators: np.ndarray,
               history: dict, boundary_edges: np.ndarray | None = None,
               contact_edges: np.ndarray | None = None) -> Path:
    """Write adapt.png (see the module docstring) to ``path``.

    ``points`` (n, 2), ``triangles`` (t, 3) and ``indicators`` (t,) are the final mesh and
    its η_T; ``history`` is adapt.json's content (title, units, steps, stop reason);
    ``boundary_edges`` and ``contact_edges`` (k, 2) point indices of the boundary and of ΓC.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter
    from mpl_toolkits.axes_grid1 import make_axes_locatable

    from contactfem.picture_text import save_png
    from contactfem.plots import error_units

    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    indicators = np.asarray(indicators, dtype=float)
    units = history.get("units") or {}
    length = shown(units.get("length", ""), 24)
    eta_unit = error_units(units)["displacement_energy"] if units else "the case's units"
    steps = list(history.get("steps") or [])
    norm, values = _colours(indicators)
    figure = plt.figure(figsize=_SIZE, dpi=_DPI)
    try:
        mesh_ax = figure.add_axes((0.06, 0.14, 0.52, 0.7))
        steps_ax = figure.add_axes((0.74, 0.14, 0.24, 0.7))
        cmap = matplotlib.colormaps["magma_r"]
        faces = cmap(norm(values))
        edges = len(triangles) <= EDGES_UP_TO
        mesh_ax.add_collection(PolyCollection(points[triangles], facecolors=faces,
                                              edgecolors=(0.2, 0.2, 0.2, 0.35) if edges else faces,
                                              linewidths=0.25 if edges else 0.0))
        if boundary_edges is not None and len(boundary_edges):
            mesh_ax.add_collection(LineCollection(points[np.asarray(boundary_edges, dtype=np.int64)],
                                                  colors="#7f7f7f", linewidths=0.8, label="boundary"))
        if contact_edges is not None and len(contact_edges):
            mesh_ax.add_collection(LineCollection(points[np.asarray(contact_edges, dtype=np.int64)],
                                                  colors="tab:red", linewidths=2.0, label="contact boundary ΓC"))
        low, high = points.min(axis=0), points.max(axis=0)
        margin = 0.03 * float(np.max(high - low) or 1.0)
        mesh_ax.set_xlim(low[0] - margin, high[0] + margin)
        mesh_ax.set_ylim(low[1] - margin, high[1] + margin)
        mesh_ax.set_aspect("equal", adjustable="box")
        mesh_ax.set_xlabel(f"x ({length})" if length else "x")
        mesh_ax.set_ylabel(f"y ({length})" if length else "y")
        mesh_ax.set_title(f"final mesh: {len(triangles)} triangles, {len(points)} nodes, coloured by η_T", fontsize=10)
        handles, labels = mesh_ax.get_legend_handles_labels()
        if handles:
            figure.legend(handles, labels, fontsize=8, loc="lower left", bbox_to_anchor=(0.01, 0.005), ncol=2,
                          frameon=False)
        bar_ax = make_axes_locatable(mesh_ax).append_axes("right", size="3%", pad=0.1)
        bar = figure.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), cax=bar_ax)
        bar.set_label(f"error indicator η_T ({eta_unit})", fontsize=9)
        bar.ax.tick_params(labelsize=8)

        unknowns = np.array([row.get("unknowns", np.nan) for row in steps], dtype=float)
        eta = np.array([row.get("eta", np.nan) for row in steps], dtype=float)
        keep = np.isfinite(unknowns) & np.isfinite(eta) & (unknowns > 0) & (eta > 0)
        if keep.any():
            steps_ax.loglog(unknowns[keep], eta[keep], "-o", ms=4, color="tab:purple", label="estimate η")
            energy = np.array([((row.get("errors") or {}).get("displacement_energy") or np.nan) for row in steps],
                              dtype=float)
            known = keep & np.isfinite(energy) & (energy > 0)
            if known.any():
                steps_ax.loglog(unknowns[known], energy[known], "-s", ms=4, color="tab:green",
                                label="energy error ‖u − u_h‖ (exact solution)")
            steps_ax.legend(fontsize=8)
            steps_ax.grid(True, which="both", alpha=0.25)
            steps_ax.xaxis.set_major_locator(FixedLocator(sorted(set(unknowns[keep].tolist()))))
            steps_ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:.0f}"))
            steps_ax.xaxis.set_minor_formatter(NullFormatter())
            steps_ax.tick_params(axis="x", labelrotation=45, labelsize=8)
        else:
            steps_ax.text(0.5, 0.5, "no step to draw", transform=steps_ax.transAxes, ha="center")
        steps_ax.set_xlabel("displacement unknowns")
        steps_ax.set_ylabel(f"η and error ({eta_unit})")
        steps_ax.set_title(f"{len(steps)} steps; stopped: {shown(history.get('stop_reason', '?'), 60)}", fontsize=10)
        title = (history.get("case") or {}).get("title", "")
        figure.text(0.01, 0.975, heading(title or "adaptive refinement", chars_across(_SIZE[0] * _DPI, 12, _DPI),
                                         lines=1),
                    fontsize=12, fontweight="bold", va="top")
        figure.text(0.01, 0.925, "adaptive refinement with method (4) and its residual estimator: Dörfler marking, "
                    "newest-vertex bisection; colours on a logarithmic scale", fontsize=9, va="top")
        return save_png(figure, path, dpi=_DPI)
    finally:
        plt.close(figure)
