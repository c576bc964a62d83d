"""contact_profile.png and compare.png stay readable at any number of contact patches.

Above a threshold of patches a profile is drawn as envelopes per pixel column, the
patches as a strip, and a zoom panel shows the densest stretch of patches node by node
with the gap; what is drawn is bounded by the picture's pixels, not by the number of
nodes or patches; the patch count and the contact fraction are written on the picture.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_cli import invoke

ROOT = Path(__file__).resolve().parents[1]


def synthetic_profile(patches: int, width: int = 3, apart: int = 6, seed: int = 0,
                      cluster: tuple[int, int] | None = None) -> dict:
    """A result (``read_hdf5``'s dict, the contact part) of ``patches`` patches of ``width``
    nodes, ``apart`` free nodes between them (1 inside ``cluster``, a range of patch numbers),
    on nodes 1e-3 apart: random pressures on the patches, random gaps between."""
    rng = np.random.default_rng(seed)
    active = [False] * 5
    for p in range(patches):
        active += [True] * width + [False] * (1 if cluster and cluster[0] <= p < cluster[1] else apart)
    active = np.array(active + [False] * 5)
    n = len(active)
    s = np.arange(n) * 1e-3
    nodes = np.arange(n)
    return {
        "attrs": {"length_unit": "m", "stress_unit": "Pa", "method": "positive", "title": "synthetic"},
        "mesh": {"points": np.column_stack([s, np.zeros(n)])},
        "contact": {"nodes": nodes, "active": active, "abscissa": s,
                    "multiplier": np.where(active, rng.uniform(1e3, 2e4, n), 0.0),
                    "gap": np.where(active, 0.0, rng.uniform(1e-6, 1e-4, n)), "normal_displacement": np.zeros(n),
                    "edges": np.column_stack([nodes[:-1], nodes[1:]])},
    }


def synthetic_compare(patches: int, **options) -> dict:
    """compare.json's content for the profile of :func:`synthetic_profile`, θh oscillating."""
    from contactfem.plots import zone_intervals

    contact = synthetic_profile(patches, **options)["contact"]
    s, active = contact["abscissa"], contact["active"]
    theta = contact["multiplier"] * 1.2 - np.where(active, 0.0, 500.0 * np.sin(np.arange(len(s))))
    intervals = zone_intervals(s, active, contact["edges"], contact["nodes"])
    return {"case": {"title": "synthetic"}, "units": {"length": "m", "force": "N", "stress": "Pa"},
            "profiles": {"abscissa": s.tolist(), "lambda": contact["multiplier"].tolist(), "theta": theta.tolist(),
                         "gap": contact["gap"].tolist(), "active": {"positive": active.tolist()}},
            "methods": {"positive": {"contact_zone": {"intervals": [{"abscissa": list(i)} for i in intervals]}}}}


def _drawn(axis) -> tuple[int, int, int]:
    """(artists, vertices, markers) drawn in ``axis``: lines, collections, patches and texts;
    the points of its lines and collections' paths; the points drawn with a marker."""
    artists = len(axis.lines) + len(axis.collections) + len(axis.patches) + len(axis.texts)
    vertices = sum(len(line.get_xdata()) for line in axis.lines)
    vertices += sum(len(path.vertices) for collection in axis.collections for path in collection.get_paths())
    markers = sum(len(line.get_xdata()) for line in axis.lines if line.get_marker() not in (None, "None", "", " "))
    return artists, vertices, markers


def _texts(figure) -> str:
    from contactfem.picture_text import _texts as texts

    return "\n".join(text.get_text() for text in texts(figure))


@pytest.fixture
def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    yield plt
    plt.close("all")


@pytest.mark.parametrize("draw", ["profile", "compare"])
def test_what_is_drawn_is_bounded_whatever_the_number_of_patches(draw, pyplot):
    """30, 300 and 3 000 patches: the same artists in every full-length panel, their points
    bounded by the panel's pixel columns, no per-node marker; the zoom panel at most about
    ZOOM_NODES nodes; the patch count and the contact fraction in the picture's text."""
    from contactfem.plots import compare_figure, profile_figure
    from contactfem.profile_view import ZOOM_NODES

    counts = {}
    for patches in (30, 300, 3000):
        if draw == "profile":
            figure, info = profile_figure(synthetic_profile(patches), size=(1200, 900))
            columns = int(0.8 * 1200)
        else:
            figure, info = compare_figure(synthetic_compare(patches))
            columns = int(0.8 * 900)
        assert info["dense"] and info["patches"] == patches and info["window"] is not None
        assert 0.2 < info["fraction"] < 0.4
        text = _texts(figure)
        assert f"{patches} contact patches" in text and "contact fraction" in text
        drawn = {}
        for name in ("pressure", "gap"):
            artists, vertices, markers = _drawn(info["axes"][name])
            assert vertices <= 12 * columns + 100, (patches, name, vertices)
            assert markers == 0, (patches, name)
            drawn[name] = artists
        _, _, markers = _drawn(info["axes"]["zoom"])
        assert 0 < markers <= 3 * (ZOOM_NODES + 20)
        counts[patches] = drawn
        pyplot.close(figure)
    assert counts[30] == counts[300] == counts[3000]


def test_the_zoom_frames_the_densest_patches_and_shows_the_gap(pyplot):
    """A profile whose patches 100 to 120 are packed (one free node between them): the zoom
    window holds them; its panel draws the gap on a second axis, zero at the pressure's zero."""
    from contactfem.plots import profile_figure
    from contactfem.profile_view import ZOOM_MARGIN_NODES, ZOOM_NODES

    data = synthetic_profile(300, cluster=(100, 120))
    figure, info = profile_figure(data, size=(1200, 900))
    s, active = data["contact"]["abscissa"], data["contact"]["active"]
    starts = s[np.flatnonzero(active[1:] & ~active[:-1]) + 1]
    low, high = info["window"]
    assert np.sum((starts[100:120] >= low) & (starts[100:120] + 2e-3 <= high)) >= 18
    assert high - low <= (ZOOM_NODES + 2 * ZOOM_MARGIN_NODES + 4) * 1e-3
    zoom = info["axes"]["zoom"]
    twins = [axis for axis in figure.axes if axis is not zoom and axis.bbox.bounds == zoom.bbox.bounds]
    assert len(twins) == 1
    gap = twins[0]
    assert any("gap" in line.get_label() for line in gap.lines)
    assert "gap" in gap.get_ylabel()
    p_low, p_high = zoom.get_ylim()
    g_low, g_high = gap.get_ylim()
    assert -p_low / (p_high - p_low) == pytest.approx(-g_low / (g_high - g_low), abs=1e-6)


def test_a_few_patches_are_drawn_node_by_node_as_before(pyplot):
    """The square (one patch): two panels, node by node with the active nodes marked, no
    zoom; the title gives the patch count and the contact fraction."""
    from conftest import case_from, square_case_dict

    from contactfem.io.registry import result_data, write_result
    from contactfem.plots import profile_figure
    from contactfem.render import load_result
    from contactfem.report import build_report
    from contactfem.solve import solve_case

    case = case_from(square_case_dict(8))
    result = solve_case(case)
    data = result_data(case, result, build_report(case, result))
    import tempfile

    with tempfile.TemporaryDirectory() as directory:
        write_result(data, Path(directory), ("h5",))
        loaded = load_result(directory)
    figure, info = profile_figure(loaded, size=(1200, 900))
    assert not info["dense"] and info["window"] is None and set(info["axes"]) == {"pressure", "gap"}
    _, _, markers = _drawn(info["axes"]["pressure"])
    assert markers >= len(loaded["contact"]["nodes"])
    active = loaded["contact"]["active"].astype(bool)
    assert "1 contact patch," in _texts(figure)
    assert info["fraction"] == pytest.approx(active.mean())  # evenly spaced nodes

    figure, info = profile_figure(loaded, size=(1200, 900), window=(0.4, 0.6))
    assert info["axes"]["zoom"].get_xlim() == pytest.approx((0.4, 0.6))


def test_contact_fraction_and_windows():
    from contactfem.profile_view import column_envelope, contact_fraction, densest_window, merged_intervals

    s = np.linspace(0.0, 1.0, 11)
    active = np.zeros(11, bool)
    active[3:6] = True
    assert contact_fraction(s, active) == pytest.approx(3 / 11)
    assert contact_fraction(s[::-1], active[::-1]) == pytest.approx(3 / 11)
    assert contact_fraction(np.zeros(0), np.zeros(0, bool)) == 0.0
    x, low, high = column_envelope(s, np.arange(11.0), 0.0, 1.0, 2)
    assert x.tolist() == [0.25, 0.75] and low.tolist() == [0, 5] and high.tolist() == [4, 10]
    assert merged_intervals([(0.0, 0.1), (0.105, 0.2), (0.5, 0.5)], 0.01) == [(0.0, 0.2), (0.5, 0.5)]
    assert densest_window(s, []) is None
    fine = np.linspace(0.0, 1.0, 1001)
    patches = [(0.1, 0.101), (0.5, 0.501), (0.503, 0.504), (0.506, 0.507), (0.9, 0.901)]
    low, high = densest_window(fine, patches, nodes=20)
    assert low <= 0.5 and high >= 0.507 and high - low < 0.03


@pytest.fixture(scope="module")
def rough(tmp_path_factory):
    """cases/rough.yaml (4 001 profile points) solved with --plot, and compared."""
    root = tmp_path_factory.mktemp("rough")
    case = ROOT / "cases" / "rough.yaml"
    result = invoke("solve", case, "--out", root / "solve", "--plot", "--quiet")
    assert result.exit_code == 0, result.stderr
    result = invoke("compare", case, "--out", root / "compare", "--quiet")
    assert result.exit_code == 0, result.stderr
    return root


def test_the_rough_profile_is_drawn_as_envelopes_with_a_zoom(rough, pyplot):
    """contact_profile.png of the rough block (about a hundred patches): envelopes, the
    patches as a strip, a zoom with the gap; the patch count is report.json's."""
    from contactfem.plots import profile_figure
    from contactfem.render import load_result

    report = json.loads((rough / "solve" / "report.json").read_text())
    patches = len(report["contact_zone"]["intervals"])
    assert patches > 50
    data = load_result(rough / "solve")
    figure, info = profile_figure(data, size=(1200, 900))
    assert info["dense"] and info["patches"] == patches and info["window"] is not None
    assert f"{patches} contact patches" in _texts(figure)
    for name in ("pressure", "gap"):
        assert _drawn(info["axes"][name])[2] == 0
    assert (rough / "solve" / "contact_profile.png").read_bytes()[:4] == b"\x89PNG"


def test_the_rough_compare_is_drawn_as_envelopes_with_a_zoom_showing_the_gap(rough, pyplot):
    from contactfem.plots import compare_figure

    figures = json.loads((rough / "compare" / "compare.json").read_text())
    figure, info = compare_figure(figures)
    patches = len(figures["methods"]["positive"]["contact_zone"]["intervals"])
    assert info["dense"] and info["patches"] == patches
    assert f"{patches} contact patches" in _texts(figure)
    zoom = info["axes"]["zoom"]
    twins = [axis for axis in figure.axes if axis is not zoom and axis.bbox.bounds == zoom.bbox.bounds]
    assert twins and "gap" in twins[0].get_ylabel()
    assert (rough / "compare" / "compare.png").read_bytes()[:4] == b"\x89PNG"


def test_the_lift_off_panel_shows_the_gap_too(pyplot):
    """compare.png of a few patches keeps its lift-off panel, now with the gap on its right axis."""
    from contactfem.plots import compare_figure

    figures = synthetic_compare(3)
    figure, info = compare_figure(figures)
    assert not info["dense"] and info["window"] is None
    middle = info["axes"]["zoom"]
    twins = [axis for axis in figure.axes if axis is not middle and axis.bbox.bounds == middle.bbox.bounds]
    assert twins and any("gap" in line.get_label() for line in twins[0].lines)


def test_plot_zooms_on_a_window_given_by_an_option(rough, tmp_path, pyplot):
    """`plot --zoom FROM:TO` sets the zoom window of contact_profile.png (and compare.png); a
    window holding the whole of ΓC's 4 001 nodes is drawn as envelopes, not node by node;
    a window that is not FROM < TO is refused."""
    from contactfem.plots import profile_figure
    from contactfem.render import load_result

    result = invoke("plot", rough / "solve", "--zoom", "0.36:0.38", "--out", tmp_path / "figs", "--quiet")
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "figs" / "contact_profile.png").read_bytes()[:4] == b"\x89PNG"
    result = invoke("plot", rough / "compare", "--zoom", "0.6:0.62", "--out", tmp_path / "cmp", "--quiet")
    assert result.exit_code == 0, result.stderr
    for bad in ("0.4:0.3", "a:b", "0.1", "nan:1"):
        refused = invoke("plot", rough / "solve", "--zoom", bad, "--out", tmp_path / "no")
        assert refused.exit_code == 2 and "--zoom" in refused.stderr, bad

    data = load_result(rough / "solve")
    figure, info = profile_figure(data, size=(1200, 900), window=(0.36, 0.38))
    assert info["window"] == (0.36, 0.38) and info["axes"]["zoom"].get_xlim() == pytest.approx((0.36, 0.38))
    figure, info = profile_figure(data, size=(1200, 900), window=(0.0, 1.0))
    _, vertices, markers = _drawn(info["axes"]["zoom"])
    assert markers == 0 and vertices <= 12 * 960 + 100
    assert "as envelopes per pixel column" in info["axes"]["zoom"].get_title()
