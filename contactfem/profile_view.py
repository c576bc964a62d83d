"""Profiles along ΓC that stay readable at any number of contact patches.

A rough profile touches in hundreds of patches: drawn node by node, its markers and
pressure spikes merge into a block. Above :data:`ENVELOPE_PATCHES` patches (or more
than one node every two pixel columns), contact_profile.png and compare.png draw

- each profile over the whole of ΓC as its envelope: the largest and smallest value of
  each pixel column (:func:`column_envelope`), filled between; no per-node marker;
- the contact zone as a strip along the panel's foot, its patches closer than a pixel
  column merged (:func:`merged_intervals`);
- a zoom panel on a window (:func:`densest_window`: the stretch of ΓC holding the most
  patches, at most :data:`ZOOM_NODES` nodes wide; or a window the user gives), node by
  node, with the pressure and, on a second axis, the gap g0 − u_n;

so that what is drawn is bounded by the picture's pixels, not by the number of nodes or
patches. Every profile picture writes the patch count and the contact fraction
(:func:`patch_note`).
"""

from __future__ import annotations

import numpy as np

#: More contact patches than this, and a profile is drawn as envelopes with a zoom panel.
ENVELOPE_PATCHES = 20
#: ... or more contact nodes than this fraction of the panel's pixel columns.
NODES_PER_COLUMN = 0.5
#: The zoom window holds at most about this many contact nodes.
ZOOM_NODES = 100
#: The window's margin on each side of the patches it frames, in node spacings.
ZOOM_MARGIN_NODES = 4
CONTACT_RED = "tab:red"
GAP_GREEN = "tab:green"


def tributary_lengths(s_sorted: np.ndarray) -> np.ndarray:
    """Each node's share of ΓC's length along the obstacle (``s_sorted`` in increasing order):
    half the distance to each neighbour, an end node counting its one half twice (so that on
    evenly spaced nodes every share is the spacing)."""
    s = np.asarray(s_sorted, dtype=float)
    if len(s) < 2:
        return np.ones(len(s))
    half = 0.5 * np.diff(s)
    share = np.zeros(len(s))
    share[:-1] += half
    share[1:] += half
    share[0] += half[0]
    share[-1] += half[-1]
    return share


def contact_fraction(s: np.ndarray, active: np.ndarray) -> float:
    """The share of ΓC's length (along the obstacle) in contact: each node counts for its
    :func:`tributary_lengths`; 0 without contact nodes."""
    s = np.asarray(s, dtype=float)
    active = np.asarray(active, dtype=bool)
    if len(s) == 0:
        return 0.0
    order = np.argsort(s, kind="stable")
    share = tributary_lengths(s[order])
    total = float(share.sum())
    if not total > 0:
        return float(active.mean())
    return float(share[active[order]].sum() / total)


def patch_note(patches: int, fraction: float) -> str:
    """The line every profile picture carries: ``"129 contact patches, contact fraction 12.3 %
    (the active nodes' share of ΓC's length)"``."""
    noun = "contact patch" if patches == 1 else "contact patches"
    return f"{patches} {noun}, contact fraction {100 * fraction:.3g} % (the active nodes' share of ΓC's length)"


def is_dense(patches: int, nodes: int, columns: int) -> bool:
    """Whether a profile of ``nodes`` contact nodes in ``patches`` patches is drawn as envelopes
    on a panel ``columns`` pixels wide."""
    return patches > ENVELOPE_PATCHES or nodes > NODES_PER_COLUMN * columns


def column_envelope(s: np.ndarray, values: np.ndarray, low: float, high: float,
                    columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The envelope of ``values`` (at abscissae ``s``) over ``columns`` equal columns of [low, high]:
    (column centres, smallest, largest value) of the columns holding a finite value."""
    s = np.asarray(s, dtype=float)
    values = np.asarray(values, dtype=float)
    columns = max(int(columns), 1)
    keep = np.isfinite(s) & np.isfinite(values)
    s, values = s[keep], values[keep]
    width = (high - low) / columns if high > low else 1.0
    index = np.clip(((s - low) / width).astype(np.int64), 0, columns - 1) if len(s) else np.zeros(0, np.int64)
    largest = np.full(columns, -np.inf)
    smallest = np.full(columns, np.inf)
    np.maximum.at(largest, index, values)
    np.minimum.at(smallest, index, values)
    filled = np.isfinite(largest)
    centres = low + (np.arange(columns) + 0.5) * width
    return centres[filled], smallest[filled], largest[filled]


def merged_intervals(intervals, resolution: float) -> list[tuple[float, float]]:
    """``intervals`` (sorted by start) with those closer than ``resolution`` merged: as drawn on
    a panel whose pixel column is ``resolution`` wide, at most one interval per two columns."""
    merged: list[list[float]] = []
    for low, high in sorted(intervals):
        if merged and low - merged[-1][1] < resolution:
            merged[-1][1] = max(merged[-1][1], high)
        else:
            merged.append([low, high])
    return [(low, high) for low, high in merged]


def densest_window(s: np.ndarray, intervals, nodes: int = ZOOM_NODES) -> tuple[float, float] | None:
    """The window [from, to] along ΓC holding the most contact patches among those at most
    ``nodes`` node spacings wide (ties: the first), tightened to its patches with a margin of
    :data:`ZOOM_MARGIN_NODES` spacings; None without patches.
    """
    s = np.sort(np.asarray(s, dtype=float))
    if not intervals or len(s) < 2:
        return None
    spacing = float(np.median(np.diff(s)))
    if not spacing > 0:
        spacing = float(np.ptp(s)) / max(len(s) - 1, 1) or 1.0
    width = nodes * spacing
    lows = np.array([low for low, _ in intervals], dtype=float)
    highs = np.array([high for _, high in intervals], dtype=float)
    order = np.argsort(lows, kind="stable")
    lows, highs = lows[order], highs[order]
    margin = ZOOM_MARGIN_NODES * spacing
    # The windows starting at each patch: how many patches lie wholly inside [low_i, low_i + width].
    ends = np.searchsorted(lows, lows + width, side="right")
    inside = [np.flatnonzero(highs[i:end] <= lows[i] + width) + i for i, end in enumerate(ends)]
    best = max(range(len(inside)), key=lambda i: (len(inside[i]), -i))
    if not len(inside[best]):
        # Every patch is wider than the window: frame where the first one ends (the body lifts off).
        centre = float(highs[0])
        return centre - 0.5 * width, centre + 0.5 * width
    start, stop = float(lows[best]) - margin, float(highs[inside[best]].max()) + margin
    if stop - start < 2 * margin + 4 * spacing:  # a patch of one node: a few spacings around it
        centre = 0.5 * (start + stop)
        start, stop = centre - margin - 2 * spacing, centre + margin + 2 * spacing
    return start, stop


def draw_envelope(axis, s: np.ndarray, values: np.ndarray, low: float, high: float, columns: int,
                  colour: str, label: str, alpha: float = 0.55) -> None:
    """``values`` over [low, high] as their per-column envelope: filled between the smallest and
    largest value of each pixel column (two artists, whatever the number of nodes)."""
    x, smallest, largest = column_envelope(s, values, low, high, columns)
    if not len(x):
        return
    axis.fill_between(x, smallest, largest, step="mid", color=colour, alpha=alpha, linewidth=0,
                      label=label)
    axis.plot(x, largest, "-", color=colour, lw=0.6, drawstyle="steps-mid")


def draw_strip(axis, intervals, resolution: float, label: str | None = "contact patches") -> None:
    """The contact patches as a strip along the foot of ``axis`` (5 % of its height), patches
    closer than ``resolution`` merged; one-node patches drawn a resolution wide."""
    from matplotlib.collections import PolyCollection

    spans = merged_intervals(intervals, resolution)
    if not spans:
        return
    across = axis.get_xaxis_transform()
    half = 0.5 * resolution
    boxes = [[(a - half * (b - a < resolution), 0), (b + half * (b - a < resolution), 0),
              (b + half * (b - a < resolution), 0.05), (a - half * (b - a < resolution), 0.05)] for a, b in spans]
    axis.add_collection(PolyCollection(boxes, transform=across, facecolors=CONTACT_RED, alpha=0.8, linewidths=0,
                                       label=label, zorder=3), autolim=False)


def mark_window(axis, window: tuple[float, float], label: str | None = None) -> None:
    """Outline the zoom window on a full-length panel (one artist)."""
    axis.axvspan(window[0], window[1], facecolor="none", edgecolor="black", linestyle=":", linewidth=1.0,
                 zorder=4, label=label)


def in_window(s: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """Indices (into ``s``) of the nodes inside ``window`` and one on each side, sorted along ΓC."""
    s = np.asarray(s, dtype=float)
    order = np.argsort(s, kind="stable")
    ordered = s[order]
    first = max(int(np.searchsorted(ordered, window[0], side="left")) - 1, 0)
    last = min(int(np.searchsorted(ordered, window[1], side="right")) + 1, len(s))
    return order[first:last]
