"""Damaged results read back: whatever bytes lie under solution.h5, compare.json or
convergence.json, ``contactfem plot`` refuses them with exit code 2 and one line naming
the file, the dataset (or key) and what was expected, quickly, without a traceback and
without writing anything; a sweep's damaged stored point is solved again.

The HDF5 corruptions start from a real solution.h5 (the square at 4 divisions) and change
one thing each; the first ones are the examples of the issue that asked for this.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import struct
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import make_runner, square_case_dict

from contactfem.cli import main
from contactfem.errors import ArchiveError
from contactfem.io import read_hdf5
from contactfem.io import archive
from contactfem.io.archive import MAX_ATTRIBUTE_BYTES, MAX_MAGNITUDE
from contactfem.io.isolated import can_isolate, run_isolated
from contactfem.io.readback import MAX_COMPARE_BYTES, read_compare, read_convergence, read_point_record
from contactfem.sweep import POINT_SCHEMA_VERSION

ROOT = Path(__file__).resolve().parents[1]
SQUARE_TEXT = (ROOT / "cases" / "square.yaml").read_text(encoding="utf-8").replace("divisions: 32", "divisions: 4")
#: A refusal comes this fast, whatever the file (the slowest here read a few MB).
SECONDS = 2.0


def invoke(*args: object):
    return make_runner().invoke(main, [str(a) for a in args])


def assert_refused(result, *fragments: str) -> str:
    """Exit 2, one ``error:`` line holding each fragment, no traceback, nothing on stdout."""
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == 2, (result.exit_code, result.stderr, result.stdout)
    assert "Traceback" not in result.stderr and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("error: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert len(lines[0]) < 600, len(lines[0])
    return lines[0]


def snapshot(directory: Path) -> dict[str, tuple[int, int]]:
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in directory.iterdir()}


def refuse_plot(directory: Path, *fragments: str) -> str:
    """``plot`` on ``directory`` (and with --out to a new directory): refused fast, nothing written."""
    before = snapshot(directory)
    out = directory.parent / "figures"
    clock = time.perf_counter()
    line = assert_refused(invoke("plot", directory, "--quiet"), *fragments)
    elapsed = time.perf_counter() - clock
    assert elapsed < SECONDS, f"refused after {elapsed:.2f} s"
    assert snapshot(directory) == before, "the result directory changed"
    assert_refused(invoke("plot", directory, "--out", out, "--quiet"), *fragments)
    assert not out.exists(), f"{out} was created"
    return line


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> Path:
    """A real result directory of a quick solve of cases/square.yaml (4 divisions)."""
    base = tmp_path_factory.mktemp("archive")
    case = base / "square.yaml"
    case.write_text(SQUARE_TEXT, encoding="utf-8")
    out = base / "square"
    result = invoke("solve", case, "--out", out, "--quiet")
    assert result.exit_code == 0, result.stderr
    return out


@pytest.fixture
def damaged(solved, tmp_path) -> Path:
    """A copy of the solve's solution.h5 alone in a fresh directory, to damage."""
    directory = tmp_path / "result"
    directory.mkdir()
    shutil.copy2(solved / "solution.h5", directory / "solution.h5")
    return directory


def edit(change: Callable[[h5py.File], None]) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        with h5py.File(path, "a") as f:
            change(f)
    return apply


def replace(name: str, value) -> Callable[[Path], None]:
    def change(f: h5py.File) -> None:
        del f[name]
        f[name] = value
    return edit(change)


def modify(name: str, how: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    def change(f: h5py.File) -> None:
        values = how(f[name][()])
        del f[name]
        f.create_dataset(name, data=values)
    return edit(change)


def set_item(index, value):
    def how(values: np.ndarray) -> np.ndarray:
        values = values.copy()
        values[index] = value
        return values
    return how


def set_attribute(group: str, name: str, value) -> Callable[[Path], None]:
    return edit(lambda f: f[group].attrs.__setitem__(name, value))


def delete(name: str) -> Callable[[Path], None]:
    return edit(lambda f: f.__delitem__(name))


def raw(transform: Callable[[bytes], bytes]) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        path.write_bytes(transform(path.read_bytes()))
    return apply


def huge_shape(f: h5py.File) -> None:
    # Declared, never allocated: the file stays small while the shape claims 16 GB.
    del f["mesh/points"]
    f.create_dataset("mesh/points", shape=(10**9, 2), dtype="f8")


def chunked_gzip(f: h5py.File) -> None:
    values = f["mesh/points"][()]
    del f["mesh/points"]
    f.create_dataset("mesh/points", data=values, chunks=(5, 2), compression="gzip")


def external_storage(tmp: Path) -> Callable[[Path], None]:
    def apply(path: Path) -> None:
        with h5py.File(path, "a") as f:
            values = f["mesh/points"][()]
            del f["mesh/points"]
            outside = path.parent / "outside.bin"
            values.tofile(outside)
            f.create_dataset("mesh/points", shape=values.shape, dtype=values.dtype,
                             external=[(str(outside), 0, values.nbytes)])
    return apply


def many_newton_members(f: h5py.File) -> None:
    for i in range(100):
        f[f"newton/extra{i}"] = np.zeros(2)


# (id, corruption, fragments of the one line) -- each names the dataset or attribute.
CORRUPTIONS = [
    # The examples of the issue.
    ("displacement-row-short", modify("fields/displacement", lambda u: u[:-1]),
     ("solution.h5: /fields/displacement: has shape (24, 2); expected (n, 2) (n = 25, the rows of /mesh/points)",)),
    ("triangle-index-1e6", modify("mesh/triangles", set_item((3, 1), 10**6)),
     ("/mesh/triangles: holds 1000000 at row 3, column 1; expected indices from 0 to 24",)),
    ("triangle-index-minus-1e9", modify("mesh/triangles", set_item((0, 0), -10**9)),
     ("/mesh/triangles: holds -1000000000 at row 0, column 0",)),
    ("displacement-all-nan", modify("fields/displacement", lambda u: np.full_like(u, np.nan)),
     ("/fields/displacement: holds nan at row 0, column 0; expected finite numbers",)),
    ("obstacle-normal-zero", set_attribute("contact", "obstacle_normal", np.zeros(2)),
     ("/contact/@obstacle_normal: is [0.0, 0.0]; expected a unit vector",)),
    ("abscissa-three-entries", modify("contact/abscissa", lambda s: s[:3]),
     ("/contact/abscissa: has shape (3,); expected (m,) (m = 4, the entries of /contact/nodes)",)),
    ("points-infinite", modify("mesh/points", set_item((2, 0), np.inf)),
     ("/mesh/points: holds inf at row 2, column 0",)),
    ("fields-group-missing", delete("fields"), ("/fields: missing; expected a group",)),
    ("schema-version-abc", set_attribute("/", "schema_version", "abc"),
     ("@schema_version: is 'abc'; expected an integer from 1 to 3",)),
    ("title-10-MB", set_attribute("/", "title", "x" * 10_000_000),
     (f"@title: is a string of 10000000 bytes; expected at most {MAX_ATTRIBUTE_BYTES}",)),
    # Types, shapes and sizes.
    ("points-complex-dtype", modify("mesh/points", lambda p: p.astype(np.complex128)),
     ("/mesh/points: has dtype complex128; expected floats",)),
    ("triangles-float-dtype", modify("mesh/triangles", lambda t: t.astype(np.float64)),
     ("/mesh/triangles: has dtype float64; expected integers",)),
    ("points-strings", replace("mesh/points", np.array([b"a", b"b"])), ("/mesh/points: has dtype |S1",)),
    ("displacement-3d", modify("fields/displacement", lambda u: u[:, :, None]),
     ("/fields/displacement: has 3 dimension(s) (25, 2, 1); expected shape (n, 2)",)),
    ("points-huge-declared-shape", edit(huge_shape),
     ("/mesh/points: declares 16000000000 bytes, more than the file's",)),
    ("stress-wrong-columns", modify("fields/stress", lambda s: s[:, :4]),
     ("/fields/stress: has shape (32, 4); expected (n_tri, 6)",)),
    ("von-mises-per-point", modify("fields/von_mises", lambda v: np.zeros(25)),
     ("/fields/von_mises: has shape (25,); expected (n_tri,) (n_tri = 32, the rows of /mesh/triangles)",)),
    ("points-too-large", modify("mesh/points", set_item((1, 1), 1e300)),
     ("/mesh/points: holds 1e+300 at row 1, column 1; expected finite numbers of magnitude at most "
      f"{MAX_MAGNITUDE:g}",)),
    ("contact-node-out-of-range", modify("contact/nodes", set_item(0, 25)),
     ("/contact/nodes: holds 25 at row 0; expected indices from 0 to 24",)),
    ("contact-edge-negative", modify("contact/edges", set_item((1, 1), -1)), ("/contact/edges: holds -1",)),
    ("edge-part-unknown", modify("mesh/edge_parts", set_item(0, 4)),
     ("/mesh/edge_parts: holds 4 at row 0; expected indices from 0 to 3 (parts = 4",)),
    ("edge-curve-below-minus-one", modify("mesh/edge_curves", set_item(0, -2)),
     ("/mesh/edge_curves: holds -2 at row 0; expected indices from -1 to -1",)),
    ("active-flag-two", modify("contact/active", set_item(0, 2)),
     ("/contact/active: holds 2 at row 0; expected 0 or 1",)),
    ("multiplier-nan", modify("contact/multiplier", set_item(1, np.nan)), ("/contact/multiplier: holds nan at row 1",)),
    ("gap-missing", delete("contact/gap"), ("/contact/gap: missing; expected a dataset",)),
    ("case-not-a-string", replace("case", np.zeros(3)), ("/case: is floats of shape (3,); expected one UTF-8 string",)),
    ("obstacle-point-shape", set_attribute("contact", "obstacle_point", np.zeros(3)),
     ("/contact/@obstacle_point: is floats of shape (3,); expected finite numbers of shape (2,)",)),
    ("obstacle-normal-nan", set_attribute("contact", "obstacle_normal", np.array([np.nan, 1.0])),
     ("/contact/@obstacle_normal: holds nan at row 0",)),
    ("method-unknown", set_attribute("/", "method", "magic"),
     ("@method: is 'magic'; expected one of positive, standard",)),
    ("part-names-numbers", set_attribute("mesh", "part_names", np.arange(4)),
     ("/mesh/@part_names: is integers of shape (4,); expected a list of strings",)),
    ("unit-not-utf8", set_attribute("/", "length_unit", np.bytes_(b"\xff\xfe")), ("@length_unit: is not UTF-8",)),
    ("attribute-array", set_attribute("/", "title", np.zeros(1000)),
     ("@title: is floats of shape (1000,); expected a string",)),
    ("schema-version-newer", set_attribute("/", "schema_version", 4), ("@schema_version: is 4, newer than 3",)),
    ("schema-version-zero", set_attribute("/", "schema_version", 0), ("@schema_version: is 0; expected an integer",)),
    ("schema-version-missing", edit(lambda f: f.attrs.__delitem__("schema_version")), ("@schema_version: missing",)),
    ("format-other", set_attribute("/", "format", "contactfem-path"),
     ("@format: is 'contactfem-path'; expected 'contactfem-solution'",)),
    ("newton-members-many", edit(many_newton_members), ("/newton: has 107 members; expected at most 64",)),
    ("newton-2d", replace("newton/active", np.zeros((3, 3))), ("/newton/active: has shape (3, 3)",)),
    # Links and storage.
    ("points-replaced-by-group", edit(lambda f: (f.__delitem__("mesh/points"), f.create_group("mesh/points"))),
     ("/mesh/points: is a group; expected a dataset",)),
    ("displacement-soft-link", replace("fields/displacement", h5py.SoftLink("/mesh/points")),
     ("/fields/displacement: is a soft link; expected a dataset stored in the file itself",)),
    ("triangles-external-link", replace("mesh/triangles", h5py.ExternalLink("/etc/passwd", "/x")),
     ("/mesh/triangles: is an external link",)),
    ("contact-group-soft-link", replace("contact", h5py.SoftLink("/mesh")), ("/contact: is a soft link",)),
    ("points-chunked-gzip", edit(chunked_gzip), ("/mesh/points: is stored chunked; expected contiguous storage",)),
    # The file itself.
    ("truncated", raw(lambda data: data[: len(data) // 2]), ("solution.h5: ",)),
    ("truncated-header", raw(lambda data: data[:100]), ("solution.h5: cannot be read as HDF5",)),
    ("not-hdf5", raw(lambda data: b"title: not an archive\n" * 10), ("solution.h5: is not an HDF5 file",)),
    ("empty", raw(lambda data: b""), ("solution.h5: is empty; expected a contactfem-solution file",)),
    ("zeroed-middle", raw(lambda data: data[:2048] + bytes(len(data) - 4096) + data[-2048:]), ("solution.h5: ",)),
]


@pytest.mark.parametrize("corrupt, fragments", [c[1:] for c in CORRUPTIONS], ids=[c[0] for c in CORRUPTIONS])
def test_plot_refuses_a_damaged_solution_h5(damaged, corrupt, fragments):
    corrupt(damaged / "solution.h5")
    refuse_plot(damaged, *fragments)


def heap_object_size(content: bytes, size: int) -> Callable[[Path], None]:
    """Set the size of the global heap object holding ``content`` (a variable-length
    string: a part name) to ``size``: one byte of the file."""
    def apply(path: Path) -> None:
        data = bytearray(path.read_bytes())
        position = data.index(b"GCOL") + 16  # signature, version, reserved, collection size
        while True:
            index, = struct.unpack_from("<H", data, position)
            length, = struct.unpack_from("<Q", data, position + 8)
            assert index != 0, f"{content!r} is not in the first global heap collection"
            if data[position + 16: position + 16 + length] == content:
                struct.pack_into("<Q", data, position + 8, size)
                break
            position += 16 + (length + 7) // 8 * 8
        path.write_bytes(bytes(data))
    return apply


def test_a_heap_that_hangs_hdf5_is_refused_in_time(damaged, monkeypatch):
    """One byte (a string's size in the global heap) sent HDF5 2.0 into an endless loop
    reading the first attribute: the file is parsed in a child process with a deadline."""
    monkeypatch.setattr(archive, "PARSE_SECONDS", 1.0)
    heap_object_size(b"bottom", 230)(damaged / "solution.h5")
    refuse_plot(damaged, "solution.h5: ")


@pytest.mark.skipif(not can_isolate(), reason="no fork here, or other threads run: parsed in this process")
def test_a_parser_that_hangs_or_crashes_is_one_line():
    clock = time.perf_counter()
    late = r"^x\.h5: HDF5 did not finish reading it within 0\.5 s; the file is damaged$"
    with pytest.raises(ArchiveError, match=late):
        run_isolated(lambda: time.sleep(30), 0.5, "x.h5")
    assert time.perf_counter() - clock < 5
    with pytest.raises(ArchiveError, match=r"^x\.h5: HDF5 crashed reading it \(SIGSEGV\); the file is damaged$"):
        run_isolated(lambda: os.kill(os.getpid(), signal.SIGSEGV), 5.0, "x.h5")
    with pytest.raises(ArchiveError, match="^refused$"):
        run_isolated(lambda: (_ for _ in ()).throw(ArchiveError("refused")), 5.0, "x.h5")
    assert run_isolated(lambda: {"a": np.arange(3)}, 5.0, "x.h5")["a"].tolist() == [0, 1, 2]


def test_external_raw_storage_is_refused_not_followed(damaged):
    external_storage(damaged)(damaged / "solution.h5")
    refuse_plot(damaged, "/mesh/points: has filters or external storage")


def test_a_special_file_or_directory_is_refused(damaged):
    (damaged / "solution.h5").unlink()
    os.mkfifo(damaged / "solution.h5")
    refuse_plot(damaged, "solution.h5: is not a regular file")


def test_a_damaged_archive_is_refused_by_read_hdf5_too(damaged):
    """The library's reader is the same: an ArchiveError naming the dataset."""
    modify("mesh/triangles", set_item((0, 0), 10**6))(damaged / "solution.h5")
    with pytest.raises(ArchiveError, match=r"/mesh/triangles: holds 1000000"):
        read_hdf5(damaged / "solution.h5")


def test_a_valid_archive_still_plots_and_reads_back(solved, tmp_path):
    out = tmp_path / "figures"
    result = invoke("plot", solved, "--out", out, "--json")
    assert result.exit_code == 0, result.stderr
    assert sorted(p.name for p in out.glob("*.png")) == ["contact_profile.png", "deformed.png"]
    data = read_hdf5(solved / "solution.h5")
    assert data["attrs"]["title"] == "square on a foundation with partial contact"
    assert data["mesh"]["points"].shape == (25, 2) and data["mesh"]["triangles"].dtype == np.int64
    assert data["contact"]["attrs"]["obstacle_normal"] == [0.0, -1.0]
    assert data["contact"]["active"].dtype == np.uint8


def test_the_older_schema_versions_still_read(damaged):
    """Schema 2 stored the stress as (n_tri, 4) and no exact pressure; schema 1 had no
    abscissa and no obstacle: both are read (and drawn) as before."""
    path = damaged / "solution.h5"
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 2
        stress = f["fields/stress"][()]
        del f["fields/stress"]
        f["fields/stress"] = stress[:, [0, 1, 3, 2]]
    assert read_hdf5(path)["fields"]["stress"].shape == (32, 4)
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 1
        del f["contact/abscissa"]
        for name in ("obstacle_point", "obstacle_normal"):
            del f["contact"].attrs[name]
    assert "abscissa" not in read_hdf5(path)["contact"]
    result = invoke("plot", damaged, "--quiet")
    assert result.exit_code == 0, result.stderr


# --------------------------------------------------------------------------- the JSON files


@pytest.fixture(scope="module")
def studies(tmp_path_factory) -> dict[str, Path]:
    """compare.json and convergence.json of the square at 8 divisions."""
    import yaml

    base = tmp_path_factory.mktemp("studies")
    case = base / "small.yaml"
    case.write_text(yaml.safe_dump(square_case_dict(divisions=8)))
    assert invoke("compare", case, "--out", base / "cmp", "--quiet").exit_code == 0
    assert invoke("converge", case, "--levels", "2", "--out", base / "cv", "--quiet").exit_code == 0
    return {"compare.json": base / "cmp" / "compare.json", "convergence.json": base / "cv" / "convergence.json"}


def _json_edit(change: Callable[[dict], object]) -> Callable[[str], str]:
    def apply(text: str) -> str:
        data = json.loads(text)
        change(data)
        return json.dumps(data)
    return apply


JSON_CORRUPTIONS = [
    ("compare.json", "lambda-short", _json_edit(lambda d: d["profiles"]["lambda"].pop()),
     ("compare.json: profiles.lambda: is a list of", "one per item of profiles.abscissa")),
    ("compare.json", "lambda-string", _json_edit(lambda d: d["profiles"]["lambda"].__setitem__(2, "x")),
     ("compare.json: profiles.lambda[2]: is 'x'; expected a finite number",)),
    ("compare.json", "nan-literal", lambda text: text.replace('"lambda": [', '"lambda": [NaN, ', 1),
     ("compare.json: is not valid JSON (NaN is not a JSON number)",)),
    ("compare.json", "overflowing-number", _json_edit(lambda d: d["profiles"]["gap"].__setitem__(0, 1e300)),
     ("compare.json: profiles.gap[0]: is 1e+300; expected a finite number",)),
    ("compare.json", "infinity-by-exponent", lambda text: text.replace('"gap": [', '"gap": [1e999, ', 1),
     ("compare.json: profiles.gap",)),
    ("compare.json", "active-not-boolean", _json_edit(lambda d: d["profiles"]["active"]["positive"].__setitem__(0, 1)),
     ("compare.json: profiles.active.positive[0]: is 1; expected true or false",)),
    ("compare.json", "profiles-missing", _json_edit(lambda d: d.pop("profiles")),
     ("compare.json: profiles: missing; expected an object",)),
    ("compare.json", "interval-of-three", _json_edit(
        lambda d: d["methods"]["positive"]["contact_zone"]["intervals"][0].__setitem__("abscissa", [0, 1, 2])),
     ("compare.json: methods.positive.contact_zone.intervals[0].abscissa: is a list of 3 items; expected a list of "
      "exactly 2 items",)),
    ("compare.json", "unit-a-number", _json_edit(lambda d: d["units"].__setitem__("length", 5)),
     ("compare.json: units.length: is 5; expected a string",)),
    ("compare.json", "schema-version-string", _json_edit(lambda d: d.__setitem__("schema_version", "1")),
     ("compare.json: schema_version: is '1'; expected one of 1",)),
    ("compare.json", "deeply-nested", lambda text: "[" * 100_000 + "]" * 100_000,
     ("compare.json: is not valid JSON",)),
    ("compare.json", "top-level-list", lambda text: "[]", ("compare.json: the top level: is a list of 0 items",)),
    ("compare.json", "not-utf8", lambda text: "\udcff", ("compare.json: is not UTF-8 text",)),
    ("compare.json", "empty", lambda text: "", ("compare.json: is empty",)),
    ("compare.json", "huge-integer", lambda text: text.replace('"gap": [', '"gap": [' + "9" * 5000 + ", ", 1),
     ("compare.json: is not valid JSON",)),
    ("convergence.json", "h-negative", _json_edit(lambda d: d["rows"][1].__setitem__("h", -0.5)),
     ("convergence.json: rows[1].h: is -0.5; expected a finite number > 0",)),
    ("convergence.json", "rows-object", _json_edit(lambda d: d.__setitem__("rows", {})),
     ("convergence.json: rows: is an object; expected a list",)),
    ("convergence.json", "norm-string", _json_edit(lambda d: d["rows"][0].__setitem__("multiplier_l2", "big")),
     ("convergence.json: rows[0].multiplier_l2: is 'big'; expected a finite number >= 0 or null",)),
    ("convergence.json", "method-a-list", _json_edit(lambda d: d["rows"][0].__setitem__("method", ["positive"])),
     ("convergence.json: rows[0].method: is a list of 1 items; expected a string",)),
    ("convergence.json", "rate-string",
     _json_edit(lambda d: d["rates"]["positive"].__setitem__("multiplier_l2", ["x"])),
     ("convergence.json: rates.positive.multiplier_l2[0]: is 'x'",)),
    ("convergence.json", "warnings-numbers", _json_edit(lambda d: d.__setitem__("warnings", [1])),
     ("convergence.json: warnings[0]: is 1; expected a string",)),
    ("convergence.json", "title-missing", _json_edit(lambda d: d["case"].pop("title")),
     ("convergence.json: case.title: missing; expected a string",)),
]


@pytest.mark.parametrize("name, corrupt, fragments", [(c[0], c[2], c[3]) for c in JSON_CORRUPTIONS],
                         ids=[f"{c[0]}-{c[1]}" for c in JSON_CORRUPTIONS])
def test_plot_refuses_a_damaged_study(studies, tmp_path, name, corrupt, fragments):
    directory = tmp_path / "result"
    directory.mkdir()
    text = corrupt(studies[name].read_text(encoding="utf-8"))
    (directory / name).write_bytes(text.encode("utf-8", "surrogateescape"))
    refuse_plot(directory, *fragments)


def test_an_oversized_study_is_refused_before_it_is_read(tmp_path):
    directory = tmp_path / "result"
    directory.mkdir()
    with open(directory / "compare.json", "wb") as stream:
        stream.truncate(MAX_COMPARE_BYTES + 1)  # sparse: nothing to read if it were read
    refuse_plot(directory, f"compare.json: is {MAX_COMPARE_BYTES + 1} bytes; expected compare.json as contactfem "
                           f"compare writes it of at most {MAX_COMPARE_BYTES} bytes")


def test_valid_studies_read_back(studies):
    assert len(read_compare(studies["compare.json"])["profiles"]["abscissa"]) > 0
    assert len(read_convergence(studies["convergence.json"])["rows"]) == 4


# --------------------------------------------------------------------------- a sweep's stored points


def test_a_damaged_stored_point_is_refused_by_its_reader(tmp_path):
    good = {"schema_version": POINT_SCHEMA_VERSION, "case_text": "x", "digest": "0" * 64, "status": "ok", "unknowns": 10,
            "seconds": {"total": 1.0}, "contact_zone": {"active_nodes": 2, "intervals": [[0.0, 1.0]]}}
    path = tmp_path / "point.json"
    path.write_text(json.dumps(good))
    assert read_point_record(path)["unknowns"] == 10
    for change, fragment in [
        ({"seconds": "abc"}, "seconds: is 'abc'; expected an object"),
        ({"unknowns": None}, "unknowns: is null; expected an integer for a point whose status is ok"),
        ({"errors": [1]}, "errors: is a list of 1 items"),
        ({"contact_zone": {"active_nodes": 2, "intervals": [[1.0]]}},
         "contact_zone.intervals[0]: is a list of 1 items"),
        ({"status": "great"}, "status: is 'great'"),
        ({"warnings": "none"}, "warnings: is 'none'"),
    ]:
        path.write_text(json.dumps({**good, **change}))
        with pytest.raises(ArchiveError, match=f"point.json: {fragment}".replace("[", r"\[").replace("]", r"\]")):
            read_point_record(path)


def test_a_sweep_solves_a_damaged_stored_point_again(tmp_path, monkeypatch):
    """A stored point whose figures are damaged (but whose schema and case text match) is
    not reused, which would break the table: it is solved again and its file replaced."""
    import sys

    import yaml

    from contactfem import sweep as sweeps

    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "distributed", None)
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(square_case_dict(4), sort_keys=False))
    plan = tmp_path / "sweep.yaml"
    plan.write_text(yaml.safe_dump({"case": "base.yaml", "points": [{"material.nu": 0.3}, {"material.nu": 0.4}]}))
    out = tmp_path / "out"
    assert invoke("sweep", plan, "--out", out, "--quiet").exit_code == 0
    stored = sorted((out / "points").glob("*.json"))
    assert len(stored) == 2
    damaged_point = json.loads(stored[0].read_text())
    damaged_point.update(seconds="abc", unknowns=None)
    stored[0].write_text(json.dumps(damaged_point))
    stored[1].write_text("[" * 100_000)
    result = invoke("sweep", plan, "--out", out, "--quiet", "--overwrite")
    assert result.exit_code == 0, result.stderr
    table = json.loads((out / "sweep.json").read_text())
    assert [row["reused"] for row in table["points"]] == [False, False]
    for path in stored:
        assert read_point_record(path)["status"] == "ok"
    reused = sweeps.finished_points(out / "points", sweeps.load_sweep(plan), read=read_point_record)
    assert reused.keys() == {p.stem for p in stored}


@pytest.mark.parametrize("payload", [b'{"a": 1}', b'{"a": '])
def test_a_json_file_that_cannot_be_read_is_one_line_naming_it(tmp_path, monkeypatch, payload):
    """An I/O error while a record is read (a disk or network file system failing) is an
    ArchiveError naming the file and the system's reason, whatever the file holds; once it
    was an UnboundLocalError, as the function's own later name shadowed the helper's."""
    import contactfem.io.json_layout as json_layout
    from contactfem.errors import ArchiveError

    path = tmp_path / "record.json"
    path.write_bytes(payload)

    def failing(*args, **kwargs):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(json_layout, "read_all", failing)
    with pytest.raises(ArchiveError, match=r"record\.json.*cannot be read \(.*Input/output error"):
        json_layout.read_json_file(path, json_layout.Object({}), "a record", 1 << 20)
