"""Pictures (`contactfem plot`, `solve --plot`), the starter case (`init`), the series PVD
files of compare/converge and the terminal progress renderer."""

from __future__ import annotations

import io
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest
from PIL import Image
from test_cli import invoke

ROOT = Path(__file__).resolve().parents[1]
SQUARE = ROOT / "cases" / "square.yaml"


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    out = tmp_path_factory.mktemp("pictures") / "square"
    result = invoke("solve", SQUARE, "--out", out, "--plot", "--quiet")
    assert result.exit_code == 0, result.stderr
    return out


def _check_picture(path: Path, size: tuple[int, int]) -> None:
    image = Image.open(path).convert("RGB")
    assert image.size == size
    pixels = np.asarray(image, dtype=float)
    assert pixels.std() > 10, f"{path} looks blank"
    codes = pixels.reshape(-1, 3).astype(np.int64) @ np.array([65536, 256, 1])
    colours = np.unique(codes)
    assert len(colours) > 50, f"{path} has only {len(colours)} colours"


def test_solve_plot_writes_both_pictures(solved):
    for name in ("deformed.png", "contact_profile.png"):
        _check_picture(solved / name, (1200, 900))


def test_plot_command_size_scale_out_and_json(solved, tmp_path):
    result = invoke("plot", solved, "--size", "640x480", "--scale", "25", "--out", tmp_path / "figs", "--json")
    assert result.exit_code == 0, result.stderr
    made = json.loads(result.stdout)
    assert made["scale"] == 25 and made["size"] == [640, 480]
    for name in made["files"]:
        _check_picture(Path(name), (640, 480))
    # The deformed picture shows the stress colours (viridis) and the red contact zone.
    pixels = np.asarray(Image.open(tmp_path / "figs" / "deformed.png").convert("RGB")).reshape(-1, 3).astype(int)
    red = (pixels[:, 0] > 180) & (pixels[:, 1] < 80) & (pixels[:, 2] < 80)
    assert red.sum() > 50


def test_auto_scale_makes_largest_displacement_a_tenth_of_the_size():
    from contactfem.render import auto_scale

    points = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]])
    u = np.array([[0.0, 0.0], [0.001, 0.0], [0.0, -0.002]])
    assert np.isclose(auto_scale(points, u) * 0.002, 0.5)
    assert auto_scale(points, np.zeros_like(u)) == 1.0


@pytest.mark.parametrize("args, message", [
    (("--size", "12x9"), "between 100 and 8000"),
    (("--size", "big"), "WIDTHxHEIGHT"),
    (("--scale", "-1"), "positive number"),
])
def test_plot_refuses_bad_options(solved, args, message):
    result = invoke("plot", solved, *args)
    assert result.exit_code == 2 and message in result.stderr


def test_plot_without_result_is_bad_input(tmp_path):
    result = invoke("plot", tmp_path)
    assert result.exit_code == 2 and "no solution.h5" in result.stderr


def test_init_writes_a_case_that_checks_and_never_overwrites(tmp_path):
    path = tmp_path / "start.yaml"
    assert invoke("init", path).exit_code == 0
    text = path.read_text()
    assert text.lstrip().startswith("#") and "obstacle:" in text
    check = invoke("check", path, "--json")
    assert check.exit_code == 0, check.stderr
    assert json.loads(check.stdout)["contact_nodes"] > 0
    again = invoke("init", path)
    assert again.exit_code == 2 and "already exists" in again.stderr
    assert path.read_text() == text
    assert invoke("init", tmp_path / "start.txt").exit_code == 2


def test_compare_and_converge_write_series_pvd(tmp_path):
    import yaml
    from conftest import square_case_dict

    small = tmp_path / "small.yaml"
    small.write_text(yaml.safe_dump(square_case_dict(divisions=8)))
    assert invoke("compare", small, "--out", tmp_path / "cmp", "--quiet").exit_code == 0
    root = ET.parse(tmp_path / "cmp" / "compare.pvd").getroot()
    sets = root.findall("./Collection/DataSet")
    assert [(d.get("timestep"), d.get("part")) for d in sets] == [("0", "0"), ("0", "1"), ("1", "0"), ("1", "1")]
    for d in sets:
        mesh = meshio.read(tmp_path / "cmp" / d.get("file"))
        assert ("contact_pressure" if d.get("part") == "1" else "von_mises") in (
            mesh.point_data if d.get("part") == "1" else mesh.cell_data)
    result = invoke("converge", small, "--levels", "2", "--method", "positive", "--out", tmp_path / "cv",
                    "--quiet")
    assert result.exit_code == 0, result.stderr
    sets = ET.parse(tmp_path / "cv" / "convergence-positive.pvd").getroot().findall("./Collection/DataSet")
    sizes = [len(meshio.read(tmp_path / "cv" / d.get("file")).points) for d in sets if d.get("part") == "0"]
    assert len(sizes) == 2 and sizes[1] > sizes[0]


def test_progress_renders_stages_and_details():
    from rich.console import Console

    from contactfem.progress import StageProgress

    buffer = io.StringIO()
    progress = StageProgress(Console(file=buffer, force_terminal=True, width=100))
    for message in ("meshing", "  1089 nodes, 2048 triangles", "solving", "  Newton 1: 3 active", "writing VTU"):
        progress(message)
    progress.close()
    progress.close()
    shown = buffer.getvalue()
    for text in ("meshing", "1089 nodes", "Newton 1", "writing VTU"):
        assert text in shown


def test_every_command_has_examples():
    from contactfem.cli import main

    for name in main.commands:
        result = invoke(name, "--help")
        assert result.exit_code == 0 and "Example" in result.stdout, name


# --------------------------------------------------------------------------- what deformed.png shows


SHIPPED = sorted((ROOT / "cases").glob("*.yaml"))


def _viridis_pixels(pixels: np.ndarray, tolerance: float = 6.0) -> np.ndarray:
    """Mask of the pixels (h, w, 3) whose colour is one of viridis's (the body's fill)."""
    from matplotlib import colormaps
    from scipy.spatial import cKDTree

    table = colormaps["viridis"](np.linspace(0, 1, 256))[:, :3] * 255
    codes = pixels.reshape(-1, 3).astype(np.int64) @ np.array([65536, 256, 1])
    colours, index = np.unique(codes, return_inverse=True)
    rgb = np.column_stack([colours // 65536, colours // 256 % 256, colours % 256]).astype(float)
    distance, _ = cKDTree(table).query(rgb)
    return (distance <= tolerance)[index.reshape(-1)].reshape(pixels.shape[:2])


def body_pixels_beyond_the_obstacle(png: Path, panel: dict, slack_pixels: float = 1.5) -> tuple[int, int, int]:
    """(body pixels of the panel, those lying on the obstacle's side of its drawn line by more than
    ``slack_pixels``, those within 3 pixels of the line on the body's side): every pixel of the
    panel is mapped back to (x, y) through the panel's pixel transform."""
    pixels = np.asarray(Image.open(png).convert("RGB"))
    body = _viridis_pixels(pixels)
    c0, r0, c1, r1 = panel["pixel_box"]
    rows, cols = np.nonzero(body)
    inside = (cols >= c0 + 2) & (cols <= c1 - 2) & (rows >= r0 + 2) & (rows <= r1 - 2)
    rows, cols = rows[inside], cols[inside]
    transform = np.asarray(panel["pixel_transform"])
    linear, offset = transform[:, :2], transform[:, 2]
    xy = np.linalg.solve(linear, (np.column_stack([cols + 0.5, rows + 0.5]) - offset).T).T
    pixel_size = 1.0 / abs(np.linalg.det(linear)) ** 0.5
    if len(panel["obstacle"]) == 5:  # a curved obstacle: depth below its drawn surface, at the closest point
        from contactfem.discretize.indenters import Polyline

        closest = Polyline(vertices=panel["obstacle"][3]).closest(xy)
        depth = np.where(closest.faces, -closest.gap, -np.inf)
        beyond = depth > slack_pixels * pixel_size
        touching = (depth <= 0) & (depth > -3 * pixel_size)
        return len(xy), int(beyond.sum()), int(touching.sum())
    point, normal, ends = panel["obstacle"]
    depth = (xy - point) @ normal  # > 0: on the obstacle's side of its line
    beyond = depth > slack_pixels * pixel_size
    if ends is not None:  # a segment: only what lies in front of it is inside the obstacle
        tangent = np.array([-normal[1], normal[0]])
        low, high = sorted(ends @ tangent)
        along = xy @ tangent
        beyond &= (along > low + slack_pixels * pixel_size) & (along < high - slack_pixels * pixel_size)
    touching = (depth <= 0) & (depth > -3 * pixel_size)
    return len(xy), int(beyond.sum()), int(touching.sum())


@pytest.fixture(scope="module")
def shipped_results(tmp_path_factory):
    """Every shipped case solved once (positive method), its solution.h5 written."""
    from contactfem.case import load_case
    from contactfem.io.registry import result_data, write_result
    from contactfem.report import build_report
    from contactfem.solve import solve_case

    root = tmp_path_factory.mktemp("shipped")
    out = {}
    for path in SHIPPED:
        case = load_case(path)
        result = solve_case(case, method="positive")
        directory = root / path.stem
        directory.mkdir()
        write_result(result_data(case, result, build_report(case, result)), directory, ("h5", "json"))
        out[path.stem] = directory
    return out


@pytest.mark.parametrize("name", [p.stem for p in SHIPPED])
def test_no_body_pixel_lies_beyond_the_obstacle(shipped_results, name, tmp_path):
    """deformed.png of every shipped case, read back from the PNG: no pixel of the body (its
    viridis fill) lies on the obstacle's side of the obstacle's drawn line, in either panel,
    and the body does reach the line (it is drawn touching where it is in contact)."""
    from contactfem.render import load_result, render_deformed

    data = load_result(shipped_results[name])
    drawn = render_deformed(data, tmp_path / "deformed.png", size=(1000, 750))
    _check_picture(tmp_path / "deformed.png", (1000, 750))
    for panel_name, panel in drawn["panels"].items():
        total, beyond, touching = body_pixels_beyond_the_obstacle(tmp_path / "deformed.png", panel)
        assert total > 2000, (panel_name, total)
        assert beyond == 0, (name, panel_name, beyond)
        assert touching > 0, (name, panel_name)


def test_the_pixel_check_sees_a_body_drawn_across_the_obstacle(shipped_results, tmp_path, monkeypatch):
    """The check above is not blind: the Hertz body magnified without cutting back (as before)
    puts thousands of body pixels into the obstacle."""
    from contactfem import render

    monkeypatch.setattr(render, "drawn_positions",
                        lambda points, u, factor, *args, **kwargs: (points + factor * u, np.zeros(len(points), bool)))
    data = render.load_result(shipped_results["hertz"])
    drawn = render.render_deformed(data, tmp_path / "deformed.png", size=(1000, 750), scale=55.9)
    _, beyond, _ = body_pixels_beyond_the_obstacle(tmp_path / "deformed.png", drawn["panels"]["body"])
    assert beyond > 1000


def test_drawn_positions_cut_back_only_towards_the_obstacle():
    """A point in contact is drawn on the line, one apart at no less than half its distance,
    one moving away is magnified in full; a finite segment limits only what is in front of it."""
    from contactfem.render import drawn_positions

    obstacle = (np.array([0.0, 0.0]), np.array([0.0, -1.0]), None)
    points = np.array([[0.0, 0.0], [1.0, 0.01], [2.0, 0.5], [3.0, 0.01]])
    u = np.array([[0.001, 0.0], [0.0, -0.009], [0.0, -0.001], [0.0, 0.002]])
    drawn, limited = drawn_positions(points, u, 100.0, obstacle)
    assert limited.tolist() == [False, True, False, False]
    np.testing.assert_allclose(drawn[0], [0.1, 0.0])
    np.testing.assert_allclose(drawn[1], [1.0, 0.5 * 0.001])  # true gap 0.001, drawn at half of it
    np.testing.assert_allclose(drawn[2], [2.0, 0.4])
    np.testing.assert_allclose(drawn[3], [3.0, 0.21])
    segment = (obstacle[0], obstacle[1], np.array([[0.5, 0.0], [1.5, 0.0]]))
    _, limited = drawn_positions(points + [[0, 0], [5, 0], [0, 0], [0, 0]], u, 100.0, segment)
    assert not limited.any()


def test_plot_draws_compare_and_converge_directories(tmp_path):
    """`plot` on a compare directory redraws compare.png from compare.json, on a converge
    directory the convergence PNGs from convergence.json; --json lists them."""
    import yaml
    from conftest import square_case_dict

    small = tmp_path / "small.yaml"
    small.write_text(yaml.safe_dump(square_case_dict(divisions=8)))
    assert invoke("compare", small, "--out", tmp_path / "cmp", "--quiet").exit_code == 0
    assert invoke("converge", small, "--levels", "2", "--out", tmp_path / "cv", "--quiet").exit_code == 0
    result = invoke("plot", tmp_path / "cmp", "--out", tmp_path / "cmp-figs", "--json")
    assert result.exit_code == 0, result.stderr
    made = json.loads(result.stdout)
    assert [Path(f).name for f in made["files"]] == ["compare.png"] and made["scale"] is None
    _check_picture(tmp_path / "cmp-figs" / "compare.png", Image.open(tmp_path / "cmp" / "compare.png").size)
    result = invoke("plot", tmp_path / "cv", "--quiet")
    assert result.exit_code == 0, result.stderr
    for name in ("convergence_h.png", "convergence_time.png"):
        assert (tmp_path / "cv" / name).read_bytes()[:4] == b"\x89PNG"
    (tmp_path / "cmp" / "compare.json").write_text("{}")
    refused = invoke("plot", tmp_path / "cmp")
    assert refused.exit_code == 2 and "profiles" in refused.stderr


def test_compare_json_profiles_are_what_compare_png_draws():
    """compare.json's profiles: one entry per contact node, sorted along the obstacle, in the
    abscissa of the contact zone's intervals (both methods' intervals lie on those abscissae)."""
    from conftest import case_from, square_case_dict

    from contactfem.studies import compare_methods

    figures, outcomes = compare_methods(case_from(square_case_dict(16)))
    profiles = figures["profiles"]
    s = np.asarray(profiles["abscissa"])
    assert np.all(np.diff(s) >= 0) and len(s) == figures["mesh"]["contact_nodes"]
    np.testing.assert_array_equal(profiles["theta"], outcomes["standard"].solution.contact.multiplier)
    for method in ("positive", "standard"):
        active = np.asarray(profiles["active"][method])
        for interval in figures["methods"][method]["contact_zone"]["intervals"]:
            assert interval["abscissa"][0] in s[active] and interval["abscissa"][1] in s[active]
    assert figures["units"] == {"length": "m", "force": "N", "stress": "Pa"}


def test_contact_zone_intervals_of_the_pictures_are_the_reports(shipped_results):
    """The intervals the profile shades are report.json's contact_zone intervals, on every shipped case."""
    from contactfem.plots import zone_intervals
    from contactfem.render import load_result

    for name, directory in shipped_results.items():
        contact = load_result(directory)["contact"]
        shaded = zone_intervals(contact["abscissa"], contact["active"].astype(bool), contact["edges"], contact["nodes"])
        report = json.loads((directory / "report.json").read_text()) if (directory / "report.json").exists() else None
        if report is not None:
            assert shaded == [tuple(i["abscissa"]) for i in report["contact_zone"]["intervals"]], name
        assert shaded, name


def test_a_zone_of_many_patches_is_told_by_its_count_extent_and_widest_patch():
    """The summary line and the pictures' titles list up to six intervals; a rough profile's
    thousands of patches would make a line of tens of kilobytes."""
    from contactfem.plots import ZONE_INTERVALS_LISTED, zone_text

    few = [(0.5, 1.0), (1.25, 1.5)]
    assert zone_text(few, "mm") == "[0.5, 1], [1.25, 1.5] mm"
    assert zone_text([]) == "none"
    many = [(0.01 * k, 0.01 * k + 0.001) for k in range(1, 1690)]
    many[700] = (7.01, 7.015)
    assert len(many) > ZONE_INTERVALS_LISTED
    assert zone_text(many, "m") == "1689 patches over [0.01, 16.89] m, the widest [7.01, 7.015]"
