"""Every JSON file the commands write follows the JSON Schema shipped for it in contactfem/schemas/,
and the case's units reach report.json, the study files, solution.h5 and solution.vtu."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import h5py
import meshio
import pytest
import yaml
from conftest import make_runner, square_case_dict
from jsonschema import Draft202012Validator

from contactfem.cli import main
from contactfem.io.registry import (
    ADAPT_JSON,
    CHECK_OUTPUT,
    COMPARE_JSON,
    CONVERGENCE_JSON,
    JSON_SCHEMAS,
    PLOT_OUTPUT,
    REPORT_JSON,
    SWEEP_JSON,
    schema_path,
)

ROOT = Path(__file__).resolve().parents[1]
MILLIMETRES = {"length": "mm", "force": "N", "stress": "MPa"}
#: Shipped cases whose check --json is validated too: a profile, a segment obstacle with a
#: polygon of arcs, a load path with a platen, a polygon with a hole.
CHECKED = ("rough", "flat_punch", "hertz_platen", "hole")


def _run(*args):
    result = make_runner().invoke(main, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    assert result.exit_code == 0, result.stderr
    return result


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, list[Path]]:
    """Each writing command run once on small cases: file name -> the files written."""
    tmp = tmp_path_factory.mktemp("schemas")
    square = square_case_dict(divisions=8)
    square["units"] = {"length": "mm", "force": "N"}
    small = tmp / "small.yaml"
    small.write_text(yaml.safe_dump(square), encoding="utf-8")
    manufactured = yaml.safe_load((ROOT / "cases" / "manufactured.yaml").read_text(encoding="utf-8"))
    manufactured["mesh"]["divisions"] = [16, 8]
    exact = tmp / "exact.yaml"
    exact.write_text(yaml.safe_dump(manufactured), encoding="utf-8")
    _run("solve", small, "--out", tmp / "solve", "--quiet")
    _run("solve", exact, "--method", "standard", "--out", tmp / "exact", "--quiet")
    _run("compare", small, "--out", tmp / "compare", "--quiet")
    _run("converge", small, "--levels", "2", "--out", tmp / "converge", "--quiet")
    _run("converge", exact, "--levels", "2", "--method", "positive", "--out", tmp / "converge-exact", "--quiet")
    _run("adapt", exact, "--max-unknowns", "2500", "--out", tmp / "adapt", "--quiet")
    # What check --json and plot --json print, kept as files.
    for name, case in (("square", small), ("exact", exact), *((c, ROOT / "cases" / f"{c}.yaml") for c in CHECKED)):
        printed = _run("check", case, "--json").stdout
        (tmp / f"check-{name}").mkdir()
        (tmp / f"check-{name}" / CHECK_OUTPUT).write_text(printed, encoding="utf-8")
    for drawn in ("solve", "compare", "converge"):
        printed = _run("plot", tmp / drawn, "--out", tmp / f"plot-{drawn}", "--json", "--size", "400x300").stdout
        (tmp / f"plot-{drawn}" / PLOT_OUTPUT).write_text(printed, encoding="utf-8")
    return {name: sorted(tmp.glob(f"*/{name}")) for name in JSON_SCHEMAS}


def _validator(name: str) -> Draft202012Validator:
    return Draft202012Validator(json.loads(schema_path(name).read_text(encoding="utf-8")))


def test_every_schema_is_a_valid_json_schema_shipped_with_the_package():
    for name, file_name in JSON_SCHEMAS.items():
        path = schema_path(name)
        assert path.is_file() and path.name == file_name
        Draft202012Validator.check_schema(json.loads(path.read_text(encoding="utf-8")))
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert "schemas/*.json" in package_data["package-data"]["contactfem"]


@pytest.mark.parametrize("name", [REPORT_JSON, COMPARE_JSON, CONVERGENCE_JSON, ADAPT_JSON, CHECK_OUTPUT, PLOT_OUTPUT])
def test_every_written_json_follows_its_schema(written, name):
    files = written[name]
    assert files, f"no {name} was written"
    validator = _validator(name)
    for path in files:
        content = json.loads(path.read_text(encoding="utf-8"))
        problems = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(content)]
        assert problems == [], (path, problems[:5])
        assert content["schema_version"] >= 1


def test_the_schemas_refuse_what_a_script_could_not_rely_on(written):
    report = json.loads(written[REPORT_JSON][0].read_text(encoding="utf-8"))
    validator = _validator(REPORT_JSON)
    for broken in ({k: v for k, v in report.items() if k != "units"}, {**report, "schema_version": 99},
                   {**report, "contact_zone": {**report["contact_zone"], "intervals": [{"abscissa": [0]}]}}):
        assert not validator.is_valid(broken)
    compare = json.loads(written[COMPARE_JSON][0].read_text(encoding="utf-8"))
    assert not _validator(COMPARE_JSON).is_valid({k: v for k, v in compare.items() if k != "profiles"})
    check = json.loads(written[CHECK_OUTPUT][0].read_text(encoding="utf-8"))
    validator = _validator(CHECK_OUTPUT)
    for broken in ({k: v for k, v in check.items() if k != "units"}, {**check, "schema_version": 2},
                   {**check, "output": {**check["output"], "formats": ["vtu", "png"]}},
                   {**check, "geometry": {"kind": "rectangle", "files": []}}, {**check, "extra": 1}):
        assert not validator.is_valid(broken)
    plot = json.loads(written[PLOT_OUTPUT][0].read_text(encoding="utf-8"))
    validator = _validator(PLOT_OUTPUT)
    for broken in ({k: v for k, v in plot.items() if k != "files"}, {**plot, "files": ["report.json"]},
                   {**plot, "size": [400]}):
        assert not validator.is_valid(broken)


def test_what_check_and_plot_print_says_what_it_describes(written):
    """check --json: the case's units and the files a solve writes; plot --json: the PNGs of
    each kind of result directory, deformed.png's factors only for a solve."""
    squares = [p for p in written[CHECK_OUTPUT] if p.parent.name == "check-square"]
    check = json.loads(squares[0].read_text(encoding="utf-8"))
    assert check["units"] == MILLIMETRES
    assert check["output"]["formats"] == ["vtu", "h5", "csv", "json"]
    assert "contact.csv" in check["output"]["files"]
    platen = json.loads(next(p for p in written[CHECK_OUTPUT] if p.parent.name == "check-hertz_platen").read_text())
    assert "path" in platen["output"]["formats"] and "path.png" in platen["output"]["files"]
    plots = {p.parent.name: json.loads(p.read_text(encoding="utf-8")) for p in written[PLOT_OUTPUT]}
    assert [Path(f).name for f in plots["plot-solve"]["files"]] == ["deformed.png", "contact_profile.png"]
    assert plots["plot-solve"]["scale"] > 0 and plots["plot-solve"]["size"] == [400, 300]
    assert [Path(f).name for f in plots["plot-compare"]["files"]] == ["compare.png"]
    assert plots["plot-compare"]["scale"] is None
    assert [Path(f).name for f in plots["plot-converge"]["files"]] == ["convergence_h.png", "convergence_time.png"]


def test_units_reach_every_output(written):
    """units: {length: mm, force: N}: MPa for stresses, in report.json, compare.json,
    convergence.json, solution.h5's attributes and the metadata of solution.vtu and contact.vtu."""
    solve = next(p.parent for p in written[REPORT_JSON] if p.parent.name == "solve")
    assert json.loads((solve / REPORT_JSON).read_text())["units"] == MILLIMETRES
    compare = next(p for p in written[COMPARE_JSON])
    assert json.loads(compare.read_text())["units"] == MILLIMETRES
    converge = next(p for p in written[CONVERGENCE_JSON] if p.parent.name == "converge")
    assert json.loads(converge.read_text())["units"] == MILLIMETRES
    with h5py.File(solve / "solution.h5", "r") as f:
        assert (f.attrs["length_unit"], f.attrs["force_unit"], f.attrs["stress_unit"]) == ("mm", "N", "MPa")
    for vtu in ("solution.vtu", "contact.vtu"):
        metadata = meshio.read(solve / vtu).field_data
        assert bytes(metadata["stress_unit"]).decode() == "MPa" and bytes(metadata["length_unit"]).decode() == "mm"
        assert bytes(metadata["case_file"]).decode().endswith("small.yaml")
    exact = next(p for p in written[REPORT_JSON] if p.parent.name == "exact")
    assert json.loads(exact.read_text())["units"] == {"length": "m", "force": "N", "stress": "Pa"}  # the default


def test_a_nested_reference_one_level_finer_is_flagged(written):
    """The last rates against a reference only one refinement finer are biased high: the study says so."""
    nested = json.loads(next(p for p in written[CONVERGENCE_JSON] if p.parent.name == "converge").read_text())
    assert nested["reference_extra"] == 1 and "biased high" in nested["warnings"][0]
    exact = json.loads(next(p for p in written[CONVERGENCE_JSON] if p.parent.name == "converge-exact").read_text())
    assert exact["reference_extra"] is None and exact["warnings"] == []


@pytest.mark.parametrize("units, message", [
    ({"length": ""}, "units.length"),
    ({"force": "k N"}, "units.force"),
    ({"lenght": "m"}, "did you mean length"),
])
def test_bad_units_are_refused_naming_the_key(tmp_path, units, message):
    data = square_case_dict(divisions=4)
    data["units"] = units
    path = tmp_path / "units.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = make_runner().invoke(main, ["check", str(path)])
    assert result.exit_code == 2 and message in result.stderr and len(result.stderr.splitlines()) == 1
