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
