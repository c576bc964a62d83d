"""PNG figures of the contact profiles and of the studies (matplotlib, off-screen), each written atomically.

Every profile is drawn against the position along the obstacle (the coordinate along its
tangent t = (−n_y, n_x)): the abscissa of report.json's contact_zone intervals, of
``/contact/abscissa`` in solution.h5, of contact.csv and of compare.json's profiles. The
contact zone is shaded over exactly those intervals.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from contactfem.io.registry import COMPARE_JSON, CONVERGENCE_PNGS
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
    as two collections: an artist per interval took 2 s for a rough profile's 1 150."""
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


def plot_result_profile(path: Path, data: dict, size: tuple[int, int] = (1200, 900), title: str = "") -> Path:
    """Contact pressure and gap g0 − u_n along ΓC of one result (``read_hdf5``'s dict).

    The abscissa is the position along the obstacle (``/contact/abscissa``); the active
    nodes are marked, the contact zone shaded over report.json's intervals, and the exact
    pressure overlaid when the file has one (``/contact/exact_pressure``). The PNG is
    exactly ``size`` pixels.
    """
    plt = _pyplot()
    attrs = data.get("attrs", {})
    length, stress = _unit(attrs.get("length_unit", "")), _unit(attrs.get("stress_unit", ""))
    contact = data["contact"]
    nodes = np.asarray(contact["nodes"], dtype=np.int64)
    active = np.asarray(contact["active"], dtype=bool)
    if "abscissa" in contact:
        s = np.asarray(contact["abscissa"], dtype=float)
    else:  # files older than schema 2: arc length from the first contact node
        xy = np.asarray(data["mesh"]["points"], dtype=float)[nodes]
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]) if len(xy) else xy[:, 0]
    order = np.argsort(s, kind="stable")
    multiplier = np.asarray(contact["multiplier"], dtype=float)
    gap = np.asarray(contact["gap"], dtype=float) - np.asarray(contact["normal_displacement"], dtype=float)
    intervals = zone_intervals(s, active, contact.get("edges"), nodes)
    method = attrs.get("method", "")
    symbol = _SYMBOLS.get(method, "multiplier")
    dpi = 100
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, sharex=True)
    try:
        for axis in (top, bottom):
            _shade(axis, intervals)
            axis.axhline(0.0, color="k", lw=0.8)
            axis.grid(True, alpha=0.3)
        top.plot(s[order], multiplier[order], "-o", ms=3, color="tab:blue", label=symbol)
        top.plot(s[active], multiplier[active], "o", ms=5, color="tab:red", label="active nodes (in contact)")
        if "exact_pressure" in contact:
            exact = np.asarray(contact["exact_pressure"], dtype=float)
            finite = np.isfinite(exact[order])
            top.plot(s[order][finite], exact[order][finite], "--", color="black", lw=1.2,
                     label="exact pressure −σnn(u_exact)")
        top.set_ylabel(_with_unit("contact pressure", stress))
        top.legend(fontsize=9)
        top.set_title(heading(title or "contact boundary ΓC", chars_across(size[0], 11, dpi), lines=1) + "\n"
                      + _zone_text(intervals, length), fontsize=11)
        bottom.plot(s[order], gap[order], "-", color="tab:green", label="gap g0 − u_n")
        bottom.plot(s[active], gap[active], "o", ms=5, color="tab:red")
        bottom.set_ylabel(_with_unit("gap g0 − u_n", length))
        bottom.set_xlabel(_with_unit(_ALONG, length) + "  (report.json's contact_zone abscissa)")
        bottom.legend(fontsize=9)
        return _save(figure, path, dpi=dpi)
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


def compare_profiles(outcomes: dict) -> dict:
    """compare.json's ``profiles`` and ``units``-less figures from the two solves (as :func:`plot_compare` reads)."""
    positive = outcomes["positive"]
    contact = positive.problem.contact
    points = positive.problem.mesh.points[contact.nodes]
    profiles = {
        "abscissa": contact.abscissa.tolist(), "x": points[:, 0].tolist(), "y": points[:, 1].tolist(),
        "lambda": positive.solution.contact.multiplier.tolist(),
        "gap": (contact.gap - positive.solution.contact.normal_displacement).tolist(),
        "active": {name: o.solution.contact.active.astype(bool).tolist() for name, o in outcomes.items()},
    }
    if "standard" in outcomes:
        profiles["theta"] = outcomes["standard"].solution.contact.multiplier.tolist()
    intervals = [list(i) for i in zone_intervals(contact.abscissa, positive.solution.contact.active,
                                                 contact.edges, contact.nodes)]
    return {"profiles": profiles,
            "methods": {"positive": {"contact_zone": {"intervals": [{"abscissa": i} for i in intervals]}}}}


def plot_contact_profiles(path: Path, outcomes: dict, title: str = "") -> Path:
    """compare.png of the two solves: drawn from the compare.json beside ``path`` when it is
    there (the file a later ``contactfem plot`` redraws from), from ``outcomes`` otherwise."""
    beside = Path(path).parent / COMPARE_JSON
    figures = None
    if beside.is_file():
        try:
            figures = json.loads(beside.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            figures = None
    if not figures or "profiles" not in figures:
        figures = {**compare_profiles(outcomes), "case": {"title": title}}
    return plot_compare(path, figures, title=title)


def plot_compare(path: Path, figures: dict, title: str = "") -> Path:
    """λh, θh and the gap along ΓC from compare.json's content.

    Three panels: both multipliers over ΓC; the lift-off zone alone (the nodes where the
    positive method has no contact), where θh's oscillation below zero shows at its own
    scale; the gap g0 − u_n. The contact zone is shaded over the positive method's intervals.
    """
    plt = _pyplot()
    profiles = figures["profiles"]
    units = figures.get("units", {})
    length, stress = _unit(units.get("length", "")), _unit(units.get("stress", ""))
    s = np.asarray(profiles["abscissa"], dtype=float)
    lam = np.asarray(profiles["lambda"], dtype=float)
    theta = np.asarray(profiles["theta"], dtype=float) if "theta" in profiles else None
    gap = np.asarray(profiles["gap"], dtype=float)
    active = np.asarray(profiles["active"]["positive"], dtype=bool)
    order = np.argsort(s, kind="stable")
    zone = figures.get("methods", {}).get("positive", {}).get("contact_zone", {}).get("intervals", [])
    intervals = [tuple(i["abscissa"]) for i in zone]
    figure, (top, middle, bottom) = plt.subplots(3, 1, figsize=(9, 9.5), gridspec_kw={"height_ratios": [3, 2.2, 2]})
    try:
        for axis in (top, bottom):
            _shade(axis, intervals, label="contact zone")
            axis.axhline(0.0, color="k", lw=0.8)
            axis.grid(True, alpha=0.3)
        top.plot(s[order], lam[order], "-o", ms=3, label=_SYMBOLS["positive"])
        if theta is not None:
            top.plot(s[order], theta[order], "-s", ms=3, label=_SYMBOLS["standard"])
        top.set_ylabel(_with_unit("contact pressure", stress))
        top.set_title(heading(title or figures.get("case", {}).get("title", ""), chars_across(900, 11), lines=1)
                      + "\n" + _zone_text(intervals, length), fontsize=11)
        top.legend(fontsize=9)

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
            shown = s[pick]
            if theta is not None:
                # Frame the nodes where θh is not zero (its oscillation sits next to the zone's
                # edge), with a few nodes of margin, rather than the whole lift-off zone.
                moving = np.flatnonzero(np.abs(theta[pick]) > 1e-3 * np.abs(theta[pick]).max())
                if moving.size:
                    shown = shown[max(moving[0] - 4, 0):moving[-1] + 5]
            middle.set_xlim(float(shown.min()), float(shown.max()))
            middle.legend(fontsize=8)
            middle.set_title("where the body lifts off (no contact for λh) next to the contact zone, at the scale "
                             "of the values there", fontsize=9)
        else:
            middle.text(0.5, 0.5, "no lift-off: every contact node is in contact", transform=middle.transAxes,
                        ha="center", va="center")
        middle.set_ylabel(_with_unit("contact pressure", stress))
        bottom.plot(s[order], gap[order], "-", color="tab:green", label="gap g0 − u_n (positive)")
        bottom.set_ylabel(_with_unit("gap g0 − u_n", length))
        bottom.set_xlabel(_with_unit(_ALONG, length))
        bottom.sharex(top)
        bottom.legend(fontsize=8)
        return _save(figure, Path(path))
    finally:
        plt.close(figure)


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
    length = study.get("units", {}).get("length", "")
    biased = bool(study.get("warnings")) and study.get("reference_extra") == 1
    for x_key, name, x_label in zip(("h", "total_seconds"), CONVERGENCE_PNGS,
                                    (_with_unit("h (largest triangle diameter)", length),
                                     "seconds (mesh + assembly + solve)")):
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
            if not every_x:
                axis.text(0.5, 0.5, "no positive error on any level", transform=axis.transAxes, ha="center")
                continue
            axis.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            axis.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.0e}" if v > 0 else ""))
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


def plot_sweep(path: Path, table: dict) -> Path:
    """sweep.png from sweep.json's content: each point's error against its seconds, one colour per
    group (its swept values outside mesh.*), the Pareto fronts drawn and numbered."""
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
        axes.set_xlabel("seconds per point (meshing, assembly, solve, report)")
        axes.set_ylabel("energy-norm error ‖u − u_h‖" if kinds == {"exact"} else
                        "|‖u_h‖ − ‖u_finest‖|, energy norm (finest point of the group)" if kinds == {"finest"} else
                        "error (energy norm)")
        failed = sum(r["status"] != "ok" for r in table["points"])
        axes.set_title(heading(table["sweep"]["title"], chars_across(8.5 * 110, 10, 110) - 40, lines=1)
                       + ": error against time" + (f" ({failed} point(s) without figures)" if failed else ""),
                       fontsize=10)
        axes.grid(True, which="both", alpha=0.3)
        return _save(figure, Path(path))
    finally:
        plt.close(figure)
