"""PNG figures of the contact profiles and of the studies (matplotlib, off-screen), each written atomically.

Every profile is drawn against the position along the obstacle (the coordinate along its
tangent t = (−n_y, n_x)): the abscissa of report.json's contact_zone intervals, of
``/contact/abscissa`` in solution.h5, of contact.csv and of compare.json's profiles. The
contact zone is shaded over exactly those intervals.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactfem.io.registry import CONVERGENCE_PNGS
from contactfem.norms import NORM_NAMES
from contactfem.picture_text import chars_across, heading, save_png, shown

_LABELS = {
    "displacement_l2": "‖u − u_ref‖ L²",
    "displacement_h1_semi": "|u − u_ref| H¹",
    "displacement_h1": "‖u − u_ref‖ H¹",
    "displacement_energy": "energy norm",
    "multiplier_l2": "‖λ − λ_ref‖ L²(ΓC)",
    "multiplier_h_minus_half": "‖λ − λ_ref‖ H^-1/2(ΓC)",
}


def error_units(units: dict | None) -> dict[str, str]:
    """The unit of each error norm (:data:`contactfem.norms.NORM_NAMES`) in the case's units (2D,
    per unit thickness: an energy is a force). The H¹ norm adds an L² part (length²) to an H¹
    seminorm (length), the H^-1/2 norm divides by such a norm: their unit is mixed, both parts named."""
    units = units or {}
    length, force, stress = (_unit(units.get(key)) for key in ("length", "force", "stress"))
    if not (length and force and stress):
        return {norm: "the case's units" for norm in NORM_NAMES}
    return {
        "displacement_l2": f"{length}²",
        "displacement_h1_semi": length,
        "displacement_h1": f"mixed: {length}², {length}",
        "displacement_energy": f"{force}^½",
        "multiplier_l2": f"{stress}·{length}^½",
        "multiplier_h_minus_half": f"mixed: {stress}·{length}, {stress}",
    }


_SYMBOLS = {"positive": "λh (positive, method 4)", "standard": "θh (standard, method 5)"}
_ALONG = "position along the obstacle"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: Path, dpi: int = 110, layout: dict | None = None) -> Path:
    """Write ``figure`` (its texts literal, :func:`contactfem.picture_text.save_png`), laid out
    with ``tight_layout(**layout)`` first unless ``layout`` is None."""
    return save_png(figure, path, dpi=dpi, layout={} if layout is None else layout)


#: A unit symbol is shown with at most this many characters (a case's units have at most 16).
UNIT_CHARS = 24


def _unit(unit) -> str:
    """A unit as drawn: the user's symbol (:func:`contactfem.picture_text.shown`), '' for none."""
    return shown(unit, UNIT_CHARS) if unit else ""


def _with_unit(label: str, unit: str | None) -> str:
    unit = _unit(unit)
    return f"{label} ({unit})" if unit else label


def zone_intervals(abscissa: np.ndarray, active: np.ndarray, edges: np.ndarray | None = None,
                   nodes: np.ndarray | None = None) -> list[tuple[float, float]]:
    """The contact zone's intervals [from, to] along the obstacle, as report.json's contact_zone
    (:func:`contactfem.discretize.contact.contact_patches`).

    Active nodes joined by ΓC edges whose both ends are active form one interval (its
    smallest and largest abscissa). Without ``edges``/``nodes`` (mesh indices of ΓC's
    edges and of the contact nodes), consecutive active nodes in abscissa order are joined.
    """
    from contactfem.discretize.contact import contact_patches, node_pairs

    s = np.asarray(abscissa, dtype=float)
    if edges is not None and nodes is not None:
        pairs = node_pairs(nodes, edges)
    else:
        order = np.argsort(s, kind="stable")
        pairs = np.column_stack([order[:-1], order[1:]])
    first, last, _counts = contact_patches(s, active, pairs)
    return sorted(zip(s[first].tolist(), s[last].tolist()))


def _shade(axis, intervals, label: str | None = None) -> None:
    """Shade the contact ``intervals`` over the axis' height (a one-node interval as a line),
    as two collections: an artist per interval is far too slow for a rough profile's
    thousand intervals."""
    from matplotlib.collections import LineCollection, PolyCollection

    spans = [(low, high) for low, high in intervals if high > low]
    points = [low for low, high in intervals if not high > low]
    across = axis.get_xaxis_transform()  # x along ΓC, y from the axis' bottom (0) to its top (1)
    if spans:
        axis.add_collection(PolyCollection([[(a, 0), (b, 0), (b, 1), (a, 1)] for a, b in spans], transform=across,
                                           facecolors="tab:red", alpha=0.12, linewidths=0, label=label),
                            autolim=False)
    if points:
        axis.add_collection(LineCollection([[(x, 0), (x, 1)] for x in points], transform=across, colors="tab:red",
                                           alpha=0.4, linewidths=1.5, label=None if spans else label),
                            autolim=False)


#: Contact intervals listed one by one up to this many; a zone of more patches (a rough
#: profile touches in thousands) is told by its count, extent and widest patch.
ZONE_INTERVALS_LISTED = 6


def zone_text(intervals, unit: str = "") -> str:
    """The contact zone in a line: its (low, high) intervals along ΓC, or for many of them
    their count, extent and widest one."""
    intervals = list(intervals)
    suffix = f" {unit}" if unit and intervals else ""
    if len(intervals) <= ZONE_INTERVALS_LISTED:
        return (", ".join(f"[{low:.4g}, {high:.4g}]" for low, high in intervals) or "none") + suffix
    low, high = min(a for a, _ in intervals), max(b for _, b in intervals)
    wide_low, wide_high = max(intervals, key=lambda pair: pair[1] - pair[0])
    return (f"{len(intervals)} patches over [{low:.4g}, {high:.4g}]{suffix}, "
            f"the widest [{wide_low:.4g}, {wide_high:.4g}]")


def _zone_text(intervals, unit: str) -> str:
    return "contact zone along the obstacle: " + zone_text(intervals, unit)


# --------------------------------------------------------------------------- one result


def _abscissa(data: dict) -> np.ndarray:
    """The contact nodes' position along the obstacle (``/contact/abscissa``; for files older
    than schema 2, the arc length from the first contact node)."""
    contact = data["contact"]
    if "abscissa" in contact:
        return np.asarray(contact["abscissa"], dtype=float)
    nodes = np.asarray(contact["nodes"], dtype=np.int64)
    xy = np.asarray(data["mesh"]["points"], dtype=float)[nodes]
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]) if len(xy) else xy[:, 0]


def _columns(width_pixels: float) -> int:
    """The pixel columns of a full-width panel of a figure ``width_pixels`` wide."""
    return int(min(max(0.8 * width_pixels, 50), 8000))


def _span(s: np.ndarray) -> tuple[float, float]:
    finite = s[np.isfinite(s)]
    if not len(finite):
        return 0.0, 1.0
    low, high = float(finite.min()), float(finite.max())
    return (low, high) if high > low else (low - 0.5, high + 0.5)


def _window_of(s: np.ndarray, intervals, window, dense: bool) -> tuple[tuple[float, float] | None, str]:
    """The zoom window and what it frames: the one asked for, else for a dense profile its
    densest stretch of patches (:func:`contactfem.profile_view.densest_window`), else none."""
    from contactfem.profile_view import densest_window

    if window is not None:
        return (float(window[0]), float(window[1])), "the window asked for"
    if dense:
        found = densest_window(s, intervals)
        if found is not None:
            return found, "the densest stretch of contact patches"
    return None, ""


def _headroom(axis, rows: int) -> None:
    """Room above the data for a legend of ``rows`` rows across the top of ``axis``."""
    low, high = axis.get_ylim()
    axis.set_ylim(low, high + (0.13 * rows + 0.04) * (high - low))


def _gap_on_right(axis, x: np.ndarray, gap: np.ndarray, length: str, label: str = "gap g0 − u_n"):
    """The gap on a second y axis of ``axis``, its zero level with the pressure's; returns that axis."""
    from contactfem.profile_view import GAP_GREEN

    right = axis.twinx()
    right.plot(x, gap, "-", color=GAP_GREEN, lw=1.3, label=label)
    right.set_ylabel(_with_unit("gap g0 − u_n", length), color=GAP_GREEN)
    right.tick_params(axis="y", colors=GAP_GREEN, labelsize=8)
    left, right_end = axis.get_xlim()
    seen = np.isfinite(gap) & (x >= min(left, right_end)) & (x <= max(left, right_end))
    finite = gap[seen] if seen.any() else gap[np.isfinite(gap)]
    low, high = axis.get_ylim()
    top = float(finite.max()) if len(finite) else 0.0
    if high > 0 and low < high and top > 0:
        share = max(-low, 0.0) / (high - low)  # where 0 sits on the pressure axis
        top *= 1.1
        right.set_ylim(-share / max(1.0 - share, 1e-9) * top, top)
    return right


def _draw_zoom(axis, s: np.ndarray, curves, gap: np.ndarray, active: np.ndarray, intervals, window,
               what: str, length: str, stress: str, columns: int) -> None:
    """Node by node over ``window``: the pressure ``curves`` ((values, marker, colour, label)), the
    active nodes, the patches there shaded, and the gap g0 − u_n on the right axis. A window
    asked for that holds more nodes than the panel can show apart
    (:func:`contactfem.profile_view.is_dense`) is drawn as envelopes per pixel column instead."""
    from contactfem.profile_view import column_envelope, draw_envelope, draw_strip, in_window, is_dense

    pick = in_window(s, window)
    here = [(a, b) for a, b in intervals if b >= window[0] and a <= window[1]]
    inside = sum(1 for a, b in here if a >= window[0] and b <= window[1])
    crowded = is_dense(inside, len(pick), columns)
    axis.axhline(0.0, color="k", lw=0.8)
    axis.grid(True, alpha=0.3)
    if crowded:
        for values, _, colour, label in curves:
            draw_envelope(axis, s[pick], values[pick], window[0], window[1], columns, colour, label)
        draw_strip(axis, here, (window[1] - window[0]) / columns)
        x, smallest, _ = column_envelope(s[pick], gap[pick], window[0], window[1], columns)
    else:
        _shade(axis, here, label="contact patches")
        for values, marker, colour, label in curves:
            axis.plot(s[pick], values[pick], "-" + marker, ms=3, color=colour, label=label)
        touching = pick[active[pick]]
        axis.plot(s[touching], curves[0][0][touching], "o", ms=5, color="tab:red", label="active nodes")
        x, smallest = s[pick], gap[pick]
    axis.set_xlim(*window)
    axis.set_ylabel(_with_unit("contact pressure", stress))
    _headroom(axis, 1)
    right = _gap_on_right(axis, x, smallest, length,
                          label="gap g0 − u_n" + (", smallest of each pixel column" if crowded else ""))
    handles, labels = axis.get_legend_handles_labels()
    more, names = right.get_legend_handles_labels()
    axis.legend(handles + more, labels + names, fontsize=8, loc="upper left", ncol=len(handles) + len(more))
    how = "as envelopes per pixel column (too many nodes to show apart)" if crowded else "node by node"
    axis.set_title(f"zoom on {what}, [{window[0]:.4g}, {window[1]:.4g}] {length}".rstrip()
                   + f": {inside} patches, {how}, the gap on the right axis", fontsize=9)


def _draw_dense(axis, s: np.ndarray, curves, intervals, span, columns: int, window) -> None:
    """A full-length panel of a dense profile: each of ``curves`` ((values, colour, label, alpha))
    as its per-pixel-column envelope, the patches as a strip along the foot, the zoom window outlined."""
    from contactfem.profile_view import draw_envelope, draw_strip, mark_window

    axis.axhline(0.0, color="k", lw=0.8)
    axis.grid(True, alpha=0.3)
    for values, colour, label, alpha in curves:
        draw_envelope(axis, s, values, span[0], span[1], columns, colour, label, alpha=alpha)
    draw_strip(axis, intervals, (span[1] - span[0]) / columns)
    if window is not None:
        mark_window(axis, window, label="zoom window")


def profile_figure(data: dict, size: tuple[int, int] = (1200, 900), title: str = "",
                   window: tuple[float, float] | None = None):
    """The figure of contact_profile.png (see :func:`plot_result_profile`) and what it shows:
    ``(figure, {"patches", "fraction", "dense", "window", "axes"})``. The caller closes it."""
    from contactfem.profile_view import contact_fraction, is_dense

    plt = _pyplot()
    attrs = data.get("attrs", {})
    length, stress = _unit(attrs.get("length_unit", "")), _unit(attrs.get("stress_unit", ""))
    contact = data["contact"]
    nodes = np.asarray(contact["nodes"], dtype=np.int64)
    active = np.asarray(contact["active"], dtype=bool)
    s = _abscissa(data)
    order = np.argsort(s, kind="stable")
    multiplier = np.asarray(contact["multiplier"], dtype=float)
    gap = np.asarray(contact["gap"], dtype=float) - np.asarray(contact["normal_displacement"], dtype=float)
    exact = np.asarray(contact["exact_pressure"], dtype=float) if "exact_pressure" in contact else None
    intervals = zone_intervals(s, active, contact.get("edges"), nodes)
    symbol = _SYMBOLS.get(attrs.get("method", ""), "multiplier")
    dpi = 100
    columns = _columns(size[0])
    dense = is_dense(len(intervals), len(s), columns)
    window, what = _window_of(s, intervals, window, dense)
    fraction = contact_fraction(s, active)
    shape = (3, 1) if window is not None else (2, 1)
    ratios = [3, 2, 3] if window is not None else [1, 1]
    figure, axes = plt.subplots(*shape, figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi,
                                gridspec_kw={"height_ratios": ratios})
    try:
        return _draw_profile(figure, axes, size, dpi, title, s, order, multiplier, gap, exact, active, intervals,
                             symbol, length, stress, columns, dense, window, what, fraction)
    except BaseException:
        plt.close(figure)
        raise


def _draw_profile(figure, axes, size, dpi, title, s, order, multiplier, gap, exact, active, intervals, symbol,
                  length, stress, columns, dense, window, what, fraction):
    from contactfem.profile_view import column_envelope, patch_note

    top, bottom = axes[0], axes[1]
    bottom.sharex(top)
    top.tick_params(labelbottom=False)
    if dense:
        span = _span(s)
        _draw_dense(top, s, [(multiplier, "tab:blue", f"{symbol}, largest and smallest of each pixel column", 0.55)],
                    intervals, span, columns, window)
        if exact is not None:
            x, _, largest = column_envelope(s, exact, span[0], span[1], columns)
            top.plot(x, largest, "--", color="black", lw=1.2, label="exact pressure −σnn(u_exact)")
        _draw_dense(bottom, s, [(gap, "tab:green", "gap g0 − u_n, smallest and largest of each pixel column",
                                 0.45)], intervals, span, columns, window)
        for axis in (top, bottom):
            _headroom(axis, 1)
        top.legend(fontsize=9, loc="upper left", ncol=4)
    else:
        for axis in (top, bottom):
            _shade(axis, intervals)
            axis.axhline(0.0, color="k", lw=0.8)
            axis.grid(True, alpha=0.3)
        top.plot(s[order], multiplier[order], "-o", ms=3, color="tab:blue", label=symbol)
        top.plot(s[active], multiplier[active], "o", ms=5, color="tab:red", label="active nodes (in contact)")
        if exact is not None:
            finite = np.isfinite(exact[order])
            top.plot(s[order][finite], exact[order][finite], "--", color="black", lw=1.2,
                     label="exact pressure −σnn(u_exact)")
        bottom.plot(s[order], gap[order], "-", color="tab:green", label="gap g0 − u_n")
        bottom.plot(s[active], gap[active], "o", ms=5, color="tab:red")
        if window is not None:
            from contactfem.profile_view import mark_window

            for axis in (top, bottom):
                mark_window(axis, window, label="zoom window")
        top.legend(fontsize=9)
    top.set_ylabel(_with_unit("contact pressure", stress))
    top.set_title(heading(title or "contact boundary ΓC", chars_across(size[0], 11, dpi), lines=1) + "\n"
                  + _zone_text(intervals, length) + "\n" + patch_note(len(intervals), fraction), fontsize=11)
    bottom.set_ylabel(_with_unit("gap g0 − u_n", length))
    bottom.set_xlabel(_with_unit(_ALONG, length) + "  (report.json's contact_zone abscissa)")
    bottom.legend(fontsize=9, loc="upper left" if dense else "best", ncol=3 if dense else 1)
    if window is not None:
        curves = [(multiplier, "o", "tab:blue", symbol)]
        _draw_zoom(axes[2], s, curves, gap, active, intervals, window, what, length, stress, columns)
        axes[2].set_xlabel(_with_unit(_ALONG, length))
    info = {"patches": len(intervals), "fraction": fraction, "dense": dense, "window": window,
            "axes": {"pressure": top, "gap": bottom, **({"zoom": axes[2]} if window is not None else {})}}
    return figure, info


def plot_result_profile(path: Path, data: dict, size: tuple[int, int] = (1200, 900), title: str = "",
                        window: tuple[float, float] | None = None) -> Path:
    """Contact pressure and gap g0 − u_n along ΓC of one result (``read_hdf5``'s dict).

    The abscissa is the position along the obstacle (``/contact/abscissa``); the contact
    zone is shaded over report.json's intervals, and the exact pressure overlaid when the
    file has one (``/contact/exact_pressure``). The title gives the number of contact
    patches and the contact fraction. A profile of few patches is drawn node by node, the
    active nodes marked; one of many (:func:`contactfem.profile_view.is_dense`) as
    envelopes per pixel column, the patches as a strip, with a third panel zooming node by
    node on its densest stretch of patches, pressure and gap together. ``window`` (from,
    to along the obstacle) asks for that zoom panel on a window of one's own. The PNG is
    exactly ``size`` pixels.
    """
    plt = _pyplot()
    figure, _ = profile_figure(data, size=size, title=title, window=window)
    try:
        return _save(figure, path, dpi=100)
    finally:
        plt.close(figure)


def plot_load_path(path: Path, curves: dict, units: dict | None = None, title: str = "") -> Path:
    """The curves of a load path against its load factor (report.json's ``load_path.curves``):
    total contact force, contact width along the obstacle, and each platen's advance."""
    plt = _pyplot()
    units = units or {}
    length, force = units.get("length"), units.get("force")
    factor = np.asarray(curves["factor"], dtype=float)
    platens = [name[len("platen_"):-len("_advance")] for name in curves
               if name.startswith("platen_") and name.endswith("_advance")]
    panels = [("contact_force", _with_unit("total contact force", f"{force}/{length}" if force and length else None)),
              ("contact_width", _with_unit("contact width", length))]
    panels += [(f"platen_{name}_advance", _with_unit(f"platen {shown(name, 40)}: advance", length))
               for name in platens]
    figure, axes = plt.subplots(len(panels), 1, figsize=(8, 2.6 * len(panels)), dpi=110, sharex=True)
    try:
        for axis, (name, label) in zip(np.atleast_1d(axes), panels):
            axis.plot(factor, np.asarray(curves[name], dtype=float), "-o", ms=4)
            axis.set_ylabel(label)
            axis.grid(True, alpha=0.3)
        np.atleast_1d(axes)[-1].set_xlabel("load factor")
        np.atleast_1d(axes)[0].set_title(heading(title or "load path", chars_across(8 * 110, 12, 110)))
        return _save(figure, path)
    finally:
        plt.close(figure)


# --------------------------------------------------------------------------- compare


def plot_compare(path: Path, figures: dict, title: str = "", window: tuple[float, float] | None = None) -> Path:
    """λh, θh and the gap along ΓC from compare.json's content.

    Three panels: both multipliers over ΓC; a zoom; the gap g0 − u_n. The contact zone is
    shaded over the positive method's intervals, and the title gives the number of
    contact patches and the contact fraction. For few patches, the profiles are drawn node
    by node and the zoom shows the lift-off zone (the nodes where the positive method has
    no contact), where θh's oscillation below zero shows at its own scale, with the gap on
    its right axis. For many (:func:`contactfem.profile_view.is_dense`), the profiles over
    ΓC are envelopes per pixel column, the patches a strip, and the zoom shows the densest
    stretch of patches node by node, λh, θh and the gap. ``window`` (from, to along the
    obstacle) asks for the zoom on a window of one's own.
    """
    plt = _pyplot()
    figure, _ = compare_figure(figures, title=title, window=window)
    try:
        return _save(figure, Path(path))
    finally:
        plt.close(figure)


def compare_figure(figures: dict, title: str = "", window: tuple[float, float] | None = None):
    """The figure of compare.png (see :func:`plot_compare`) and what it shows:
    ``(figure, {"patches", "fraction", "dense", "window", "axes"})``. The caller closes it."""
    from contactfem.profile_view import contact_fraction, is_dense

    plt = _pyplot()
    profiles = figures["profiles"]
    units = figures.get("units", {})
    length, stress = _unit(units.get("length", "")), _unit(units.get("stress", ""))
    s = np.asarray(profiles["abscissa"], dtype=float)
    lam = np.asarray(profiles["lambda"], dtype=float)
    theta = np.asarray(profiles["theta"], dtype=float) if "theta" in profiles else None
    gap = np.asarray(profiles["gap"], dtype=float)
    active = np.asarray(profiles["active"]["positive"], dtype=bool)
    zone = figures.get("methods", {}).get("positive", {}).get("contact_zone", {}).get("intervals", [])
    intervals = [tuple(i["abscissa"]) for i in zone]
    size = (900, 950)
    columns = _columns(size[0])
    dense = is_dense(len(intervals), len(s), columns)
    window, what = _window_of(s, intervals, window, dense)
    fraction = contact_fraction(s, active)
    figure, axes = plt.subplots(3, 1, figsize=(9, 9.5), gridspec_kw={"height_ratios": [3, 2.2, 2]})
    try:
        heading_line = heading(title or figures.get("case", {}).get("title", ""), chars_across(size[0], 11), lines=1)
        _draw_compare(axes, s, lam, theta, gap, active, intervals, length, stress, columns, dense, window, what,
                      fraction, heading_line)
    except BaseException:
        plt.close(figure)
        raise
    info = {"patches": len(intervals), "fraction": fraction, "dense": dense, "window": window,
            "axes": {"pressure": axes[0], "zoom": axes[1], "gap": axes[2]}}
    return figure, info


def _draw_compare(axes, s, lam, theta, gap, active, intervals, length, stress, columns, dense, window, what,
                  fraction, heading_line) -> None:
    from contactfem.profile_view import mark_window, patch_note

    top, middle, bottom = axes
    order = np.argsort(s, kind="stable")
    if dense:
        span = _span(s)
        curves = [(lam, "tab:blue", _SYMBOLS["positive"], 0.6)]
        if theta is not None:  # under λh: θh's dips below zero show beneath
            curves.insert(0, (theta, "tab:orange", _SYMBOLS["standard"], 0.45))
        _draw_dense(top, s, curves, intervals, span, columns, window)
        _draw_dense(bottom, s, [(gap, "tab:green", "gap g0 − u_n (positive)", 0.45)], intervals, span, columns,
                    window)
        _headroom(top, 2)
        _headroom(bottom, 1)
        top.legend(fontsize=8, loc="upper left", ncol=3, title="largest and smallest of each pixel column",
                   title_fontsize=8, alignment="left")
    else:
        for axis in (top, bottom):
            _shade(axis, intervals, label="contact zone")
            axis.axhline(0.0, color="k", lw=0.8)
            axis.grid(True, alpha=0.3)
        top.plot(s[order], lam[order], "-o", ms=3, label=_SYMBOLS["positive"])
        if theta is not None:
            top.plot(s[order], theta[order], "-s", ms=3, label=_SYMBOLS["standard"])
        bottom.plot(s[order], gap[order], "-", color="tab:green", label="gap g0 − u_n (positive)")
        if window is not None:
            for axis in (top, bottom):
                mark_window(axis, window, label="zoom window")
        top.legend(fontsize=9)
    top.set_ylabel(_with_unit("contact pressure", stress))
    top.set_title(heading_line + "\n" + _zone_text(intervals, length) + "\n" + patch_note(len(intervals), fraction),
                  fontsize=11)

    if window is not None:
        curves = [(lam, "o", "tab:blue", "λh")]
        if theta is not None:
            curves.append((theta, "s", "tab:orange", "θh"))
        _draw_zoom(middle, s, curves, gap, active, intervals, window, what, length, stress, columns)
    else:
        _draw_lift_off(middle, s, order, lam, theta, gap, active, length, stress)
    bottom.set_ylabel(_with_unit("gap g0 − u_n", length))
    bottom.set_xlabel(_with_unit(_ALONG, length))
    bottom.sharex(top)
    bottom.legend(fontsize=8, loc="upper left" if dense else "best", ncol=3 if dense else 1)


def _draw_lift_off(middle, s, order, lam, theta, gap, active, length, stress) -> None:
    """The lift-off zone (no contact for λh) and a node on each side at the scale of the values
    there, the gap on the right axis."""
    lift = ~active
    middle.axhline(0.0, color="k", lw=0.8)
    middle.grid(True, alpha=0.3)
    if lift.any():
        # The lift-off nodes and one node on each side, at the scale of their own values.
        near = lift.copy()
        near[1:] |= lift[:-1]
        near[:-1] |= lift[1:]
        pick = order[near[order]]
        middle.plot(s[pick], lam[pick], "-o", ms=3, label="λh")
        values = [lam[lift]]
        if theta is not None:
            middle.plot(s[pick], theta[pick], "-s", ms=3, color="tab:orange", label="θh")
            # θh's dips below zero, at the lift-off nodes and at the contact zone's edge.
            values += [theta[lift], np.minimum(theta[pick], 0.0)]
            low = pick[int(np.argmin(theta[pick]))]
            middle.text(0.01, 0.04, f"min θh = {theta[low]:.3g} {stress} at {s[low]:.4g} {length} "
                        f"(λh there: {lam[low]:.3g})", transform=middle.transAxes, fontsize=8, color="tab:orange")
        spread = np.concatenate(values)
        low_value, high_value = float(spread.min()), float(spread.max())
        pad = 0.15 * max(high_value - low_value, abs(low_value), abs(high_value), np.finfo(float).tiny)
        middle.set_ylim(min(low_value, 0.0) - pad, max(high_value, 0.0) + pad)
        framed = s[pick]
        if theta is not None:
            # Frame the nodes where θh is not zero (its oscillation sits next to the zone's
            # edge), with a few nodes of margin, rather than the whole lift-off zone.
            moving = np.flatnonzero(np.abs(theta[pick]) > 1e-3 * np.abs(theta[pick]).max())
            if moving.size:
                framed = framed[max(moving[0] - 4, 0):moving[-1] + 5]
        middle.set_xlim(float(framed.min()), float(framed.max()))
        right = _gap_on_right(middle, s[pick], gap[pick], length)
        handles, labels = middle.get_legend_handles_labels()
        more, names = right.get_legend_handles_labels()
        middle.legend(handles + more, labels + names, fontsize=8)
        middle.set_title("where the body lifts off (no contact for λh) next to the contact zone, at the scale "
                         "of the values there, the gap on the right axis", fontsize=9)
    else:
        middle.text(0.5, 0.5, "no lift-off: every contact node is in contact", transform=middle.transAxes,
                    ha="center", va="center")
    middle.set_ylabel(_with_unit("contact pressure", stress))


# --------------------------------------------------------------------------- convergence


def plot_convergence(directory: Path, study: dict, theoretical_rate: float = 1.0) -> list[Path]:
    """Error against h (log-log, each segment labelled with its observed rate, the h^rate slope
    of Theorem 3.7 for reference) and against seconds, from convergence.json's content.

    Rates the study flags as biased (a nested reference only one refinement finer) are
    marked with an asterisk and explained under the figure.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    plt = _pyplot()
    written = []
    rows_all = study["rows"]
    methods = sorted({row["method"] for row in rows_all})
    length = (study.get("units") or {}).get("length", "")
    units_of_norm = error_units(study.get("units"))
    biased = bool(study.get("warnings")) and study.get("reference_extra") == 1
    for x_key, name, x_label in zip(("h", "total_seconds"), CONVERGENCE_PNGS,
                                    (_with_unit("h, largest triangle diameter", length),
                                     "time (s): mesh + assembly + solve")):
        figure, axes = plt.subplots(2, 3, figsize=(14, 8.5))
        for axis, norm in zip(axes.ravel(), NORM_NAMES):
            every_x = []
            for method in methods:
                rows = [r for r in rows_all if r["method"] == method]
                x = np.array([r[x_key] for r in rows], dtype=float)
                y = np.array([r[norm] if r[norm] is not None else np.nan for r in rows], dtype=float)
                keep = np.isfinite(y) & (y > 0) & (x > 0)
                if not keep.any():
                    continue
                line, = axis.loglog(x[keep], y[keep], "-o", ms=4, label=shown(method, 40))
                every_x.extend(x[keep])
                if x_key == "h":
                    rates = study.get("rates", {}).get(method, {}).get(norm, [])
                    for i in range(len(x) - 1):
                        if i < len(rates) and rates[i] is not None and keep[i] and keep[i + 1]:
                            mark = "*" if biased and i == len(x) - 2 else ""
                            axis.annotate(f"{rates[i]:.2f}{mark}", (np.sqrt(x[i] * x[i + 1]), np.sqrt(y[i] * y[i + 1])),
                                          textcoords="offset points", xytext=(4, 4 if method == methods[0] else -12),
                                          fontsize=7, color=line.get_color())
            if x_key == "h" and every_x:
                mine = [r for r in rows_all if r["method"] == methods[0] and r[norm] is not None and r[norm] > 0]
                if len(mine) > 1:
                    x0, y0 = mine[0]["h"], mine[0][norm]
                    xs = np.array([r["h"] for r in mine])
                    axis.loglog(xs, y0 * (xs / x0) ** theoretical_rate, "k--", lw=0.8,
                                label=f"slope {theoretical_rate:g} (h^{theoretical_rate:g})")
                axis.xaxis.set_major_locator(FixedLocator(sorted(set(every_x))))
                axis.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
                axis.xaxis.set_minor_formatter(NullFormatter())
            axis.set_title(_LABELS[norm], fontsize=10)
            axis.set_xlabel(x_label, fontsize=8)
            axis.set_ylabel(f"error ({units_of_norm[norm]})", fontsize=8)
            if not every_x:
                axis.text(0.5, 0.5, "no positive error on any level", transform=axis.transAxes, ha="center")
                continue
            axis.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            axis.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.2g}" if v > 0 else ""))
            axis.yaxis.set_minor_formatter(NullFormatter())
            axis.tick_params(labelsize=7)
            axis.grid(True, which="both", alpha=0.25)
            axis.legend(fontsize=7)
        top_line = (heading((study.get("case") or {}).get("title", ""), chars_across(1400 * 0.7, 11), lines=1)
                    + f" — reference: {shown(study['reference'], 80)}")
        if x_key == "h":
            top_line += "\nnumbers on the segments: observed rates between consecutive levels"
        figure.suptitle(top_line, fontsize=11)
        if biased:
            figure.text(0.01, 0.005, "* " + shown(study["warnings"][0], 300), fontsize=8, color="darkred")
        try:
            written.append(_save(figure, Path(directory) / name, layout={"rect": (0, 0.025 if biased else 0, 1, 1)}))
        finally:
            plt.close(figure)
    return written



# --------------------------------------------------------------------------- sweep


def plot_sweep(path: Path, table: dict, units: dict | None = None) -> Path:
    """sweep.png from sweep.json's content: each point's error against its seconds, one colour per
    group (its swept values outside mesh.*), the Pareto fronts drawn and numbered.

    ``units``: the base case's units (default: the table's ``units``, if it has them); the
    error, an energy norm, is in force^½ (2D, per unit thickness). None: "each point's case
    units" (the sweep sets them)."""
    import itertools

    from matplotlib.ticker import FuncFormatter

    from contactfem.sweep_table import pareto_series

    plt = _pyplot()
    series = list(pareto_series(table))
    figure, axes = plt.subplots(figsize=(8.5, 6))
    try:
        colours = itertools.cycle(plt.rcParams["axes.prop_cycle"].by_key()["color"])
        for (group, rows, front), colour in zip(series, colours):
            axes.scatter([r["seconds"]["total"] for r in rows], [r["error"] for r in rows], s=24, color=colour,
                         label=shown(group, 80) or "all points", zorder=3)
            axes.plot([r["seconds"]["total"] for r in front], [r["error"] for r in front], "-", color=colour, lw=1.2)
            axes.scatter([r["seconds"]["total"] for r in front], [r["error"] for r in front], s=90,
                         facecolors="none", edgecolors="black", lw=1.0, zorder=4)
            for r in front:
                axes.annotate(str(r["index"]), (r["seconds"]["total"], r["error"]), textcoords="offset points",
                              xytext=(5, 4), fontsize=7)
        kinds = {r["error_kind"] for _, rows, _ in series for r in rows}
        if series:
            axes.set_xscale("log")
            axes.set_yscale("log")
            seconds = FuncFormatter(lambda value, _: f"{value:g}")
            axes.xaxis.set_major_formatter(seconds)
            axes.xaxis.set_minor_formatter(seconds)
            axes.tick_params(axis="x", which="minor", labelsize=7)
            axes.scatter([], [], s=90, facecolors="none", edgecolors="black", label="Pareto front (point number)")
            axes.legend(fontsize=7, loc="best")
        else:
            axes.text(0.5, 0.5, "no point has an error to plot\n(one solved point per group, or none solved)",
                      ha="center", va="center", transform=axes.transAxes)
        units = units or table.get("units")
        unit = error_units(units)["displacement_energy"] if units else "each point's case units"
        axes.set_xlabel("time per point (s): meshing, assembly, solve, report")
        axes.set_ylabel(("energy-norm error ‖u − u_h‖" if kinds == {"exact"} else
                         "|‖u_h‖ − ‖u_finest‖|, energy norm (finest point of the group)" if kinds == {"finest"} else
                         "error (energy norm)") + f" ({unit})")
        failed = sum(r["status"] != "ok" for r in table["points"])
        axes.set_title(heading(table["sweep"]["title"], chars_across(8.5 * 110, 10, 110) - 40, lines=1)
                       + ": error against time" + (f" ({failed} point(s) without figures)" if failed else ""),
                       fontsize=10)
        axes.grid(True, which="both", alpha=0.3)
        return _save(figure, Path(path))
    finally:
        plt.close(figure)
