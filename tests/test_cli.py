"""End-to-end tests of the ``contactfem`` command line through click's CliRunner.

Every shipped case is solved with both methods into a temporary directory and every
output file is read back with the library a user would use (meshio, h5py, json).
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from conftest import make_runner

from contactfem import __version__
from contactfem.cli import main
from contactfem.methods import METHOD_NAMES

ROOT = Path(__file__).resolve().parents[1]
CASES = sorted((ROOT / "cases").glob("*.yaml"))
OUTPUT_FILES = ("solution.vtu", "contact.vtu", "solution.pvd", "solution.h5", "report.json")
REPORT_KEYS = ("schema_version", "method", "mesh", "newton", "sign_conditions", "contact_zone", "errors",
               "contact_force", "equilibrium", "timings")




def invoke(*args: str):
    result = make_runner().invoke(main, [str(a) for a in args])
    # An exception other than SystemExit is a crash that CliRunner swallowed: show it.
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


def solve(case: Path, out: Path, *extra: str):
    result = invoke("solve", case, "--out", out, *extra)
    assert result.exit_code == 0, result.stderr
    return result


def test_shipped_cases_found():
    assert {c.stem for c in CASES} >= {"square", "hertz", "hole", "punch"}


@pytest.mark.parametrize("method", METHOD_NAMES)
@pytest.mark.parametrize("case", CASES, ids=[c.stem for c in CASES])
def test_solve_shipped_case_writes_readable_outputs(case, method, tmp_path):
    """Each shipped case solves with each method; every output file reads back consistently."""
    out = tmp_path / "out"
    solve(case, out, "--method", method, "--quiet")
    for name in OUTPUT_FILES:
        assert (out / name).is_file(), name

    # solution.vtu: triangles, 3-component displacement, per-triangle stress and von Mises.
    body = meshio.read(out / "solution.vtu")
    n_points = len(body.points)
    triangles = body.get_cells_type("triangle")
    assert len(triangles) > 0
    displacement_vtu = body.point_data["displacement"]
    assert displacement_vtu.shape == (n_points, 3)
    assert np.all(displacement_vtu[:, 2] == 0)
    assert np.all(np.isfinite(displacement_vtu))
    stress = body.cell_data_dict["stress"]["triangle"]
    von_mises = body.cell_data_dict["von_mises"]["triangle"]
    assert len(stress) == len(triangles)
    assert von_mises.shape == (len(triangles),)
    assert np.all(np.isfinite(stress)) and np.all(von_mises >= 0)

    # contact.vtu: the contact boundary as line cells with the contact fields.
    contact = meshio.read(out / "contact.vtu")
    lines = contact.get_cells_type("line")
    assert len(lines) > 0
    for name in ("contact_pressure", "gap", "active", "normal_displacement"):
        assert name in contact.point_data, name
        assert len(contact.point_data[name]) == len(contact.points)

    # solution.h5: the four groups, the case text verbatim, the same displacement as the VTU.
    with h5py.File(out / "solution.h5", "r") as h5:
        for group in ("mesh", "fields", "contact", "newton"):
            assert isinstance(h5[group], h5py.Group), group
        stored = h5["case"][()]
        stored = stored.decode("utf-8") if isinstance(stored, bytes) else stored
        assert stored == case.read_text(encoding="utf-8")
        displacement_h5 = h5["fields/displacement"][()]
        n_triangles_h5 = len(h5["mesh/triangles"])
    assert displacement_h5.shape == (n_points, 2)
    np.testing.assert_allclose(displacement_vtu[:, :2], displacement_h5, rtol=0, atol=1e-12)
    assert n_triangles_h5 == len(triangles)

    # report.json: the documented keys, converged, in equilibrium.
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    for key in REPORT_KEYS:
        assert key in report, key
    assert report["method"]["name"] == method
    assert report["solver"]["status"] == "converged"
    assert report["equilibrium"]["relative_force_residual"] < 1e-10
    assert report["mesh"]["nodes"] == n_points
    assert report["mesh"]["triangles"] == len(triangles)
    assert isinstance(report["newton"], list) and len(report["newton"]) == report["solver"]["iterations"]

    # solution.pvd names both pieces.
    pvd = (out / "solution.pvd").read_text(encoding="utf-8")
    assert "solution.vtu" in pvd and "contact.vtu" in pvd


def test_json_flag_prints_the_report(tmp_path):
    """--json prints valid JSON on stdout, equal to report.json apart from the timings."""
    out = tmp_path / "out"
    result = solve(ROOT / "cases" / "square.yaml", out, "--json")
    printed = json.loads(result.stdout)
    written = json.loads((out / "report.json").read_text(encoding="utf-8"))
    printed.pop("timings")
    written.pop("timings")
    assert printed == written
    assert result.stderr == ""


def test_quiet_prints_nothing(tmp_path):
    out = tmp_path / "out"
    result = solve(ROOT / "cases" / "square.yaml", out, "--quiet")
    assert result.stdout == ""
    assert result.stderr == ""
    assert (out / "report.json").is_file()


def test_default_summary_mentions_outputs(tmp_path):
    out = tmp_path / "out"
    result = solve(ROOT / "cases" / "square.yaml", out)
    assert "Newton" in result.stdout
    assert "report.json" in result.stdout


def test_check_prints_parts_and_unknowns(tmp_path):
    case = ROOT / "cases" / "square.yaml"
    result = invoke("check", case)
    assert result.exit_code == 0, result.stderr
    for part, kind in (("left", "clamped"), ("top", "traction"), ("right", "free"), ("bottom", "contact")):
        assert f"{part}: {kind}" in result.stdout
    assert "unknowns" in result.stdout
    # The unknowns printed are those the solver reports.
    out = tmp_path / "out"
    solve(case, out, "--quiet")
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert f"unknowns   {report['unknowns']['displacement']} displacement" in result.stdout


@pytest.mark.parametrize("case", CASES, ids=[c.stem for c in CASES])
def test_check_json_is_valid(case):
    result = invoke("check", case, "--json")
    assert result.exit_code == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["unknowns"] > 0
    assert summary["contact_nodes"] > 0
    assert "contact" in summary["parts"].values()
    assert summary["mesh"]["triangles"] > 0


def test_check_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = invoke("check", ROOT / "cases" / "square.yaml")
    assert result.exit_code == 0
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [(), ("solve",), ("check",)], ids=["main", "solve", "check"])
def test_help_shows_an_example(command):
    result = invoke(*command, "--help")
    assert result.exit_code == 0
    assert "Example" in result.stdout
    assert "contactfem " in result.stdout


def test_version():
    result = invoke("--version")
    assert result.exit_code == 0
    assert "contactfem" in result.stdout
    assert __version__ in result.stdout


def test_python_dash_m_runs_the_command_line(tmp_path):
    """``python -m contactfem`` is the same command: it solves, and refuses bad input in one
    line with exit code 2."""
    import subprocess
    import sys

    solved = subprocess.run([sys.executable, "-m", "contactfem", "solve", str(ROOT / "cases" / "square.yaml"),
                             "--out", str(tmp_path / "out"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert solved.returncode == 0, solved.stderr
    assert (tmp_path / "out" / "report.json").is_file()
    missing = subprocess.run([sys.executable, "-m", "contactfem", "solve", str(tmp_path / "none.yaml")],
                             capture_output=True, text=True, timeout=300)
    assert missing.returncode == 2
    assert len(missing.stderr.strip().splitlines()) == 1 and "none.yaml" in missing.stderr


def test_refine_quadruples_triangles(tmp_path):
    case = ROOT / "cases" / "square.yaml"
    solve(case, tmp_path / "coarse", "--quiet")
    solve(case, tmp_path / "fine", "--quiet", "--refine", "1")
    coarse = json.loads((tmp_path / "coarse" / "report.json").read_text(encoding="utf-8"))
    fine = json.loads((tmp_path / "fine" / "report.json").read_text(encoding="utf-8"))
    assert fine["mesh"]["triangles"] == 4 * coarse["mesh"]["triangles"]
    assert fine["solver"]["status"] == "converged"


# --------------------------------------------------------------------------- which files a solve writes


def test_the_default_outputs_are_one_list_everywhere(tmp_path):
    """The case layer's default output formats are the registry's, the starter case's (written
    from it) and the documentation's; the starter case solves to exactly those files."""
    import yaml

    from contactfem.case.names import DEFAULT_FORMATS
    from contactfem.io import registry
    from contactfem.starter import starter_case

    assert registry.DEFAULT_FORMATS == DEFAULT_FORMATS and "csv" in DEFAULT_FORMATS
    listed = f"[{', '.join(DEFAULT_FORMATS)}]"
    assert yaml.safe_load(starter_case(Path("case.yaml")))["output"]["files"] == list(DEFAULT_FORMATS)
    for page in ("docs/outputs.md", "docs/case-reference.md", "docs/tutorial.md", "docs/commands.md"):
        text = (ROOT / page).read_text(encoding="utf-8")
        assert listed in text, page
        assert "files: [vtu, h5, json]" not in text, page  # the old, wrong, default
    case = tmp_path / "case.yaml"
    assert invoke("init", case).exit_code == 0
    out = tmp_path / "out"
    solve(case, out, "--quiet")
    expected = [name for fmt in DEFAULT_FORMATS for name in registry.FORMATS[fmt].files]
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(expected)


@pytest.mark.parametrize("files, absent", [
    (["vtu", "h5", "json", "xdmf"], ["contact.csv"]),
    (["vtu", "h5", "csv", "json", "xdmf"], []),
    (["h5", "json"], ["solution.vtu", "contact.vtu", "solution.pvd", "contact.csv"]),
])
def test_a_solve_writes_exactly_the_listed_formats_and_says_which(files, absent, tmp_path):
    """output.files is the list written, no more and no less: xdmf added to a list without csv
    writes no contact.csv; check prints that list before the solve, the summary after it."""
    import yaml
    from conftest import square_case_dict

    from contactfem.io.registry import FORMATS

    data = square_case_dict(divisions=4)
    data["output"] = {"files": files}
    case = tmp_path / "case.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    expected = [name for fmt in FORMATS if fmt in files for name in FORMATS[fmt].files]
    check = invoke("check", case, "--json")
    assert check.exit_code == 0, check.stderr
    assert json.loads(check.stdout)["output"]["files"] == expected
    assert f"  output     results/case: {', '.join(expected)} (output.files: " in invoke("check", case).stdout
    out = tmp_path / "out"
    result = solve(case, out)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(expected)
    assert not any((out / name).exists() for name in absent)
    wrote = next(line for line in result.stdout.splitlines() if line.startswith("  wrote"))
    assert wrote.split(None, 1)[1].split(", ") == [str(out / name) for name in expected]
