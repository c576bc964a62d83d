"""PNG figures of the studies (matplotlib, off-screen), each written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from contactfem.io.atomic import atomic_path
from contactfem.io.registry import CONVERGENCE_PNGS
from contactfem.norms import NORM_NAMES

_LABELS = {
    "displacement_l2": "‖u − u_ref‖ L²",
    "displacement_h1_semi": "|u − u_ref| H¹",
    "displacement_h1": "‖u − u_ref‖ H¹",
    "displacement_energy": "energy norm",
    "multiplier_l2": "‖λ − λ_ref‖ L²(ΓC)",
    "multiplier_h_minus_half": "‖λ − λ_ref‖ H^-1/2(ΓC)",
}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: Path) -> Path:
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=110)
    return path


def plot_contact_profiles(path: Path, outcomes: dict, title: str = "") -> Path:
    """λh, θh and the gap g0 − u_n along ΓC, against the abscissa along the obstacle."""
    plt = _pyplot()
    positive = outcomes["positive"]
    contact = positive.problem.contact
    s = contact.abscissa
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    top.plot(s, positive.solution.contact.multiplier, "-o", ms=3, label="λh (positive, method 4)")
    if "standard" in outcomes:
        top.plot(s, outcomes["standard"].solution.contact.multiplier, "-s", ms=3,
                 label="θh (standard, method 5)")
    top.axhline(0.0, color="k", lw=0.8)
    top.set_ylabel("contact pressure")
    top.legend()
    top.set_title(title)
    gap = contact.gap - positive.solution.contact.normal_displacement
    bottom.plot(s, gap, "-", color="tab:green")
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_ylabel("gap g0 − u_n")
    bottom.set_xlabel("position along the obstacle")
    figure.tight_layout()
    try:
        return _save(figure, path)
    finally:
        plt.close(figure)


def plot_convergence(directory: Path, study: dict, theoretical_rate: float = 1.0) -> list[Path]:
    """Error against h (log-log, with the h^rate slope of Theorem 3.7) and against seconds."""
    plt = _pyplot()
    written = []
    methods = sorted({row["method"] for row in study["rows"]})
    for x_key, name, x_label in zip(("h", "total_seconds"), CONVERGENCE_PNGS,
                                    ("h (largest triangle diameter)", "seconds (mesh + assembly + solve)")):
        figure, axes = plt.subplots(2, 3, figsize=(13, 7.5))
        for axis, norm in zip(axes.ravel(), NORM_NAMES):
            for method in methods:
                rows = [r for r in study["rows"] if r["method"] == method]
                x = np.array([r[x_key] for r in rows])
                y = np.array([r[norm] for r in rows])
                keep = y > 0
                axis.loglog(x[keep], y[keep], "-o", ms=4, label=method)
            if x_key == "h" and len(rows) > 1 and np.any(y > 0):
                x0, y0 = x[keep][0], y[keep][0]
                axis.loglog(x, y0 * (x / x0) ** theoretical_rate, "k--", lw=0.8,
                            label=f"h^{theoretical_rate:g}")
            axis.xaxis.set_minor_formatter(plt.NullFormatter())
            axis.set_title(_LABELS[norm], fontsize=10)
            axis.set_xlabel(x_label, fontsize=8)
            axis.legend(fontsize=7)
        figure.suptitle(f"{study['case']['title']} — reference: {study['reference']}")
        figure.tight_layout()
        try:
            written.append(_save(figure, Path(directory) / name))
        finally:
            plt.close(figure)
    return written


def plot_result_profile(path: Path, data: dict, size: tuple[int, int] = (1200, 900), title: str = "") -> Path:
    """Contact pressure and gap g0 − u_n along ΓC of one result (``read_hdf5``'s dict).

    The abscissa is the arc length along ΓC from its first contact node (the nodes are
    stored sorted along ΓC); the active nodes are marked and the contact zone shaded.
    The PNG is exactly ``size`` pixels.
    """
    plt = _pyplot()
    points = np.asarray(data["mesh"]["points"], dtype=float)
    contact = data["contact"]
    nodes = np.asarray(contact["nodes"], dtype=np.int64)
    active = np.asarray(contact["active"], dtype=bool)
    xy = points[nodes]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))]) if len(xy) else xy[:, 0]
    multiplier = np.asarray(contact["multiplier"], dtype=float)
    gap = np.asarray(contact["gap"], dtype=float) - np.asarray(contact["normal_displacement"], dtype=float)
    method = data["attrs"].get("method", "")
    symbol = {"positive": "λh (positive, method 4)", "standard": "θh (standard, method 5)"}.get(method, "multiplier")
    dpi = 100
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, sharex=True)
    for axis in (top, bottom):
        for start, stop in _runs(active):
            axis.axvspan(s[start], s[stop], color="tab:red", alpha=0.12, lw=0)
        axis.axhline(0.0, color="k", lw=0.8)
    top.plot(s, multiplier, "-o", ms=3, color="tab:blue", label=symbol)
    top.plot(s[active], multiplier[active], "o", ms=5, color="tab:red", label="active nodes (in contact)")
    top.set_ylabel("contact pressure")
    top.legend(fontsize=9)
    top.set_title(title or "contact boundary ΓC")
    bottom.plot(s, gap, "-", color="tab:green", label="gap g0 − u_n")
    bottom.plot(s[active], gap[active], "o", ms=5, color="tab:red")
    bottom.set_ylabel("gap g0 − u_n (length)")
    bottom.set_xlabel("arc length along ΓC")
    bottom.legend(fontsize=9)
    figure.tight_layout()
    try:
        with atomic_path(path) as temporary:
            figure.savefig(temporary, format="png", dpi=dpi)
        return path
    finally:
        plt.close(figure)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [start, stop] of consecutive True entries (a single node gives start = stop)."""
    runs, start = [], None
    for i, value in enumerate(np.asarray(mask, dtype=bool)):
        if value and start is None:
            start = i
        if not value and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, len(mask) - 1))
    return runs
