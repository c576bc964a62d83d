"""The pictures of the studies: convergence_h.png, convergence_time.png and sweep.png label
their axes with units; adapt.png draws the final mesh coloured by the error indicator."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import square_case_dict
from test_cli import invoke

from contactfem.norms import NORM_NAMES


@pytest.fixture
def drawn(monkeypatch):
    """The axis labels and texts of every figure the pictures write, by file name."""
    from contactfem import picture_text, plots

    seen: dict[str, dict] = {}
    save = picture_text.save_png

    def recording(figure, path, **options):
        seen[Path(path).name] = {
            "axes": [(axis.get_xlabel(), axis.get_ylabel(), axis.get_title()) for axis in figure.axes],
            "texts": [text.get_text() for text in picture_text._texts(figure)],
            "collections": [(len(collection.get_paths()), np.array(collection.get_facecolors()))
                            for axis in figure.axes for collection in axis.collections],
        }
        return save(figure, path, **options)

    monkeypatch.setattr(plots, "save_png", recording)
    monkeypatch.setattr(picture_text, "save_png", recording)
    return seen


def _study(units: dict) -> dict:
    rows = [{"level": level, "method": "positive", "h": h, "total_seconds": seconds,
             **{norm: error for norm in NORM_NAMES}}
            for level, (h, seconds, error) in enumerate([(0.1, 0.5, 1e-2), (0.05, 2.0, 5e-3)])]
    return {"case": {"title": "study"}, "units": units, "reference": "exact", "reference_extra": None,
            "rows": rows, "rates": {"positive": {norm: [1.0] for norm in NORM_NAMES}}, "warnings": []}


def test_convergence_pictures_label_their_axes_with_the_cases_units(drawn, tmp_path):
    from contactfem.plots import plot_convergence

    plot_convergence(tmp_path, _study({"length": "mm", "force": "kN", "stress": "GPa"}))
    by_h, by_time = drawn["convergence_h.png"]["axes"], drawn["convergence_time.png"]["axes"]
    assert len(by_h) == len(by_time) == len(NORM_NAMES)
    assert all(x == "h, largest triangle diameter (mm)" for x, _, _ in by_h)
    assert all(x.startswith("time (s)") for x, _, _ in by_time)
    expected = {"displacement_l2": "mm²", "displacement_h1_semi": "mm", "displacement_h1": "mixed: mm², mm",
                "displacement_energy": "kN^½", "multiplier_l2": "GPa·mm^½",
                "multiplier_h_minus_half": "mixed: GPa·mm, GPa"}
    for axes in (by_h, by_time):
        assert [y for _, y, _ in axes] == [f"error ({expected[norm]})" for norm in NORM_NAMES]


def test_error_units_without_units_say_so():
    from contactfem.plots import error_units

    assert set(error_units(None).values()) == {"the case's units"}


def test_sweep_png_labels_time_and_error_with_units(drawn, tmp_path, monkeypatch):
    """sweep.png of a sweep whose base case is in mm and kN: time in s, error in kN^½."""
    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "distributed", None)
    base = square_case_dict(4)
    base["units"] = {"length": "mm", "force": "kN"}
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    sweep = tmp_path / "sweep.yaml"
    sweep.write_text(yaml.safe_dump({"case": "base.yaml", "grid": {"mesh.divisions": [2, 4, 6]}}))
    result = invoke("sweep", sweep, "--out", tmp_path / "out", "--quiet")
    assert result.exit_code == 0, result.stderr
    (x, y, _), = drawn["sweep.png"]["axes"]
    assert x.startswith("time per point (s)") and y.endswith("(kN^½)")
    assert json.loads((tmp_path / "out" / "sweep.json").read_text())["counts"]["points"] == 3


def test_sweep_png_of_swept_units_says_each_points_units(drawn, tmp_path):
    from contactfem.plots import plot_sweep

    table = {"sweep": {"title": "t"}, "keys": ["units.length"],
             "points": [{"index": i, "status": "ok", "group": "", "error": e, "error_kind": "finest",
                         "seconds": {"total": t}, "pareto": True} for i, (e, t) in enumerate([(1e-2, 1), (1e-3, 2)])]}
    plot_sweep(tmp_path / "sweep.png", table)
    (_, y, _), = drawn["sweep.png"]["axes"]
    assert y.endswith("(each point's case units)")


def test_adapt_writes_the_final_mesh_coloured_by_the_indicator(drawn, tmp_path):
    """adapt.png beside adapt.json, through the pictures' writer: every triangle of the final
    mesh filled with its own colour of η_T (a logarithmic scale), the colour bar and the
    steps' panel in the case's units (energy norm: N^½)."""
    root = Path(__file__).resolve().parents[1]
    result = invoke("adapt", root / "cases" / "manufactured.yaml", "--max-unknowns", "2000", "--out", tmp_path,
                    "--quiet")
    assert result.exit_code == 0, result.stderr
    assert (tmp_path / "adapt.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "adapt.json").is_file()
    report = json.loads((tmp_path / "report.json").read_text())
    picture = drawn["adapt.png"]
    paths, faces = picture["collections"][0]
    assert paths == report["mesh"]["triangles"]
    assert len(np.unique(faces.round(3), axis=0)) > 20
    assert any("error indicator η_T (N^½)" == y for _, y, _ in picture["axes"])
    assert any(y == "η and error (N^½)" for _, y, _ in picture["axes"])
    history = json.loads((tmp_path / "adapt.json").read_text())
    assert any(f"{len(history['steps'])} steps" in title for _, _, title in picture["axes"])
