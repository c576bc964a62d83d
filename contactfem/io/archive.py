"""Reading back what contactfem wrote, as untrusted input.

A results directory is only as sound as whatever last wrote to it: a disk error, a copy
cut short, another program, or anyone with write access can leave any bytes under the
names contactfem reads back. Every such file is read here, against a declared layout,
before anything is computed from it:

- the file itself (:func:`contactfem.io.untrusted.open_regular`): a regular file (not a
  FIFO or a device), not empty, its size taken from the descriptor that is then read;
- an HDF5 file (:func:`read_hdf5_file` here, with a :class:`Layout`), parsed in a child
  process with a deadline (:mod:`contactfem.io.isolated`: a damaged file can hang or
  crash the HDF5 library itself): the ``format`` and
  ``schema_version`` attributes first; then, before any data is read, each expected
  dataset's presence as a hard link (a soft or external link is refused, never
  followed), that it is a dataset and not a group, its dtype kind, rank and shape, the
  sizes datasets share (one displacement row per point: a named size is bound by the
  first dataset that has it), its storage (contiguous or compact as contactfem writes
  it: no filters, no external or virtual storage, all of it allocated) and the total
  of the declared sizes against the file's size; then the data, with index ranges
  (triangles within the point count, non-negative), finiteness, magnitudes and allowed
  values; attributes only by name, their type and shape checked before their value is
  read, strings bounded (:data:`MAX_ATTRIBUTE_BYTES`);
- a JSON file (:func:`contactfem.io.json_layout.read_json_file` with a tree of
  :class:`~contactfem.io.json_layout.Node`): at most a given
  size read, strict JSON (no NaN or Infinity), then the keys the commands use, their
  types, ranges (finite numbers) and consistent lengths.

A violation is an :class:`~contactfem.errors.ArchiveError` whose one line names the
file, the dataset, attribute or key, and what was expected; the command line exits 2 on
it (bad input). Nothing here writes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.errors import ArchiveError
from contactfem.io.isolated import run_isolated
from contactfem.io.untrusted import MAX_MAGNITUDE, Where, number_text, open_regular, reason, shortened

__all__ = ["MAX_ATTRIBUTES", "MAX_ATTRIBUTE_BYTES", "MAX_MAGNITUDE", "PARSE_SECONDS", "Array", "Attribute", "Layout",
           "Series", "TextData", "read_hdf5_file"]

#: A string attribute (a title, a unit, a part name) is refused above this many bytes.
MAX_ATTRIBUTE_BYTES = 4096
#: At most this many attributes on one object, and this many datasets in a :class:`Series`.
MAX_ATTRIBUTES = 64
#: An HDF5 file is parsed in a child process (:mod:`contactfem.io.isolated`) given this
#: many seconds, plus one per PARSE_BYTES_PER_SECOND bytes of the file, to answer.
PARSE_SECONDS = 10.0
PARSE_BYTES_PER_SECOND = 50e6
#: The signature every HDF5 file written without a user block starts with.
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


# --------------------------------------------------------------------------- HDF5 layouts


@dataclass(frozen=True)
class Array:
    """A dataset the layout expects.

    ``shape`` gives each dimension as a number or as the name of a size shared between
    datasets (the first dataset of the layout with that name binds it; ``sizes`` of the
    :class:`Layout` says what each name counts). ``kinds`` are the numpy dtype kinds
    accepted ("f" floats, "iu" integers, "iub" integers or booleans) and ``dtype`` the one
    returned (None: as stored). ``index_of`` makes the values row indices of that size,
    from ``lowest`` (-1 where -1 means none) to the size less one; ``flags`` allows only 0
    and 1; ``finite`` refuses NaN, infinities and magnitudes above :data:`MAX_MAGNITUDE`.
    ``at_least`` bounds the first dimension from below. The dataset is part of schema
    versions ``since`` to ``until`` (None: to the newest); ``optional`` ones may be absent.
    """

    path: str
    kinds: str
    shape: tuple[int | str, ...]
    dtype: str | None = None
    finite: bool = False
    index_of: str | None = None
    lowest: int = 0
    flags: bool = False
    at_least: int = 0
    since: int = 1
    until: int | None = None
    optional: bool = False


@dataclass(frozen=True)
class TextData:
    """A scalar UTF-8 string dataset of at most ``max_bytes`` bytes."""

    path: str
    max_bytes: int


@dataclass(frozen=True)
class Attribute:
    """An attribute of the group ``group`` (``"/"`` for the root).

    ``kind`` is "text" (a string of at most :data:`MAX_ATTRIBUTE_BYTES` bytes, one of
    ``choices`` when given), "integer", "vector" (floats of shape ``shape``, finite), or
    "texts" (a list of strings, whose count binds the size ``size``). ``unit`` makes a
    vector's length 1 (a normal).
    """

    group: str
    name: str
    kind: str
    shape: tuple[int, ...] = ()
    choices: tuple[str, ...] = ()
    unit: bool = False
    size: str | None = None
    max_items: int = 10_000
    since: int = 1
    optional: bool = False


@dataclass(frozen=True)
class Series:
    """A group of any number (up to :data:`MAX_ATTRIBUTES`) of one-dimensional numeric
    datasets of at most ``max_length`` values each, read as stored (the Newton history)."""

    path: str
    max_length: int
    optional: bool = True


@dataclass(frozen=True)
class Layout:
    """What an HDF5 file written by contactfem holds: its ``format`` attribute, the schema
    versions read (1 to ``newest``), and its datasets, strings, attributes and series.
    ``sizes`` describes each named size in words ("the rows of /mesh/points"). The root's
    other attributes are read too when they are scalars (strings bounded). ``rules`` check
    what the datasets must satisfy together, once all are read: each returns (dataset,
    what is wrong and what was expected) or None."""

    format: str
    newest: int
    sizes: dict[str, str]
    arrays: tuple[Array, ...]
    texts: tuple[TextData, ...] = ()
    attributes: tuple[Attribute, ...] = ()
    series: tuple[Series, ...] = ()
    rules: tuple[Callable[[dict], tuple[str, str] | None], ...] = ()


# --------------------------------------------------------------------------- HDF5 reading


class _HDF5:
    """One HDF5 file being read against a layout."""

    def __init__(self, where: Where, handle: Any, size: int, layout: Layout) -> None:
        self.where = where
        self.file = handle
        self.size = size
        self.layout = layout
        self.sizes: dict[str, tuple[int, str]] = {}
        self.version = 0

    @contextmanager
    def reading(self, name: str) -> Iterator[None]:
        """HDF5's own errors while reading ``name`` as one refusal naming it."""
        try:
            yield
        except (ArchiveError, MemoryError):
            raise
        except Exception as error:  # noqa: BLE001 - h5py raises OSError, KeyError, ValueError, RuntimeError...
            raise self.where.fail(name, f"cannot be read ({reason(error)}); the file is damaged") from None

    def fail(self, name: str, problem: str) -> ArchiveError:
        return self.where.fail(name, problem)

    # ----------------------------------------------------------------- objects

    def find(self, path: str, kind: str, optional: bool = False) -> Any | None:
        """The object at ``path`` (kind "dataset" or "group"), reached through hard links only."""
        import h5py

        node = self.file
        parts = [p for p in path.split("/") if p]
        for depth, part in enumerate(parts):
            here = "/" + "/".join(parts[: depth + 1])
            last = depth == len(parts) - 1
            with self.reading(here):
                link = node.get(part, getlink=True)
            if link is None:
                if optional:
                    return None
                expected = "a dataset" if last and kind == "dataset" else "a group"
                raise self.fail(here, f"missing; expected {expected}")
            if not isinstance(link, h5py.HardLink):
                what = "an external link" if isinstance(link, h5py.ExternalLink) else "a soft link"
                raise self.fail(here, f"is {what}; expected {'a dataset' if last and kind == 'dataset' else 'a group'} "
                                      "stored in the file itself (links are not followed)")
            with self.reading(here):
                cls = node.get(part, getclass=True)
                item = node[part]
            wanted = h5py.Dataset if last and kind == "dataset" else h5py.Group
            if cls is not wanted:
                found = {h5py.Dataset: "a dataset", h5py.Group: "a group"}.get(cls, "a named type")
                raise self.fail(here, f"is {found}; expected {'a dataset' if wanted is h5py.Dataset else 'a group'}")
            node = item
        return node

    def check_storage(self, name: str, dataset: Any) -> int:
        """The dataset's declared size in bytes, once its storage is as contactfem writes it."""
        import h5py

        with self.reading(name):
            plist = dataset.id.get_create_plist()
            layout = plist.get_layout()
            filters = plist.get_nfilters()
            external = plist.get_external_count()
            stored = dataset.id.get_storage_size()
            declared = int(np.prod(dataset.shape, dtype=object)) * dataset.dtype.itemsize if dataset.shape else \
                dataset.dtype.itemsize
        if layout not in (h5py.h5d.CONTIGUOUS, h5py.h5d.COMPACT):
            kind = {h5py.h5d.CHUNKED: "chunked", h5py.h5d.VIRTUAL: "virtual"}.get(layout, "of another layout")
            raise self.fail(name, f"is stored {kind}; expected contiguous storage, as contactfem writes it "
                                  "(h5repack -l CONTI restores it)")
        if filters or external:
            raise self.fail(name, "has filters or external storage; expected its data in the file, uncompressed")
        if declared > self.size:
            raise self.fail(name, f"declares {declared} bytes, more than the file's {self.size}; "
                                  "expected a shape the file can hold")
        if stored < declared:
            raise self.fail(name, f"holds {stored} of its {declared} bytes; expected all of its data in the file")
        return declared

    # ----------------------------------------------------------------- sizes

    def bind(self, size: str, value: int, origin: str) -> None:
        self.sizes.setdefault(size, (value, origin))

    def describe(self, size: str) -> str:
        value, origin = self.sizes[size]
        words = self.layout.sizes.get(size, size)
        return f"{size} = {value}, {words}" if origin in words else f"{size} = {value}, from {origin}"

    def check_shape(self, array: Array, shape: tuple[int, ...]) -> None:
        if len(shape) != len(array.shape):
            raise self.fail(array.path, f"has {len(shape)} dimension(s) {shape}; expected shape "
                                        f"{self.shown_shape(array.shape)}")
        for dimension, (expected, found) in enumerate(zip(array.shape, shape)):
            if isinstance(expected, str):
                if expected not in self.sizes:
                    self.bind(expected, found, array.path)
                    continue
                value = self.sizes[expected][0]
                if found != value:
                    raise self.fail(array.path, f"has shape {shape}; expected {self.shown_shape(array.shape)} "
                                                f"({self.describe(expected)})")
            elif found != expected:
                raise self.fail(array.path, f"has shape {shape}; expected {self.shown_shape(array.shape)}")
        if shape and shape[0] < array.at_least:
            raise self.fail(array.path, f"has {shape[0]} rows; expected at least {array.at_least}")

    def shown_shape(self, shape: tuple[int | str, ...]) -> str:
        return "(" + ", ".join(str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"

    # ----------------------------------------------------------------- attributes

    def attribute(self, spec: Attribute, group: Any) -> Any:
        import h5py

        name = f"{spec.group.rstrip('/')}/@{spec.name}" if spec.group != "/" else f"@{spec.name}"
        with self.reading(name):
            present = spec.name in group.attrs
        if not present:
            if spec.optional:
                return None
            raise self.fail(name, f"missing; expected {self.attribute_words(spec)}")
        with self.reading(name):
            identifier = group.attrs.get_id(spec.name)
            shape, dtype = identifier.shape, identifier.dtype
        if spec.kind == "text":
            return self.text_attribute(name, group, spec.name, shape, dtype, spec.choices)
        if spec.kind == "integer":
            if shape not in ((), (1,)) or dtype.kind not in "iu":
                raise self.fail(name, f"is {self.attribute_type(shape, dtype)}; expected an integer")
            with self.reading(name):
                value = int(np.asarray(group.attrs[spec.name]).reshape(-1)[0])
            return value
        if spec.kind == "vector":
            if tuple(shape or ()) != spec.shape or dtype.kind not in "fiu":
                raise self.fail(name, f"is {self.attribute_type(shape, dtype)}; expected {self.attribute_words(spec)}")
            with self.reading(name):
                value = np.asarray(group.attrs[spec.name], dtype=np.float64)
            bad = self.first_bad_value(value)
            if bad is not None:
                raise self.fail(name, f"holds {bad}; expected finite numbers")
            if spec.unit and not abs(float(np.linalg.norm(value)) - 1.0) <= 1e-6:
                raise self.fail(name, f"is {value.tolist()}; expected a unit vector (length 1)")
            return value.tolist()
        if spec.kind == "texts":
            if h5py.check_string_dtype(dtype) is None or len(shape or ()) != 1:
                raise self.fail(name, f"is {self.attribute_type(shape, dtype)}; expected a list of strings")
            if shape[0] > spec.max_items:
                raise self.fail(name, f"holds {shape[0]} strings; expected at most {spec.max_items}")
            self.check_fixed_text(name, dtype)
            with self.reading(name):
                values = group.attrs[spec.name]
            texts = [self.decoded(name, value) for value in np.asarray(values, dtype=object).tolist()]
            if spec.size is not None:
                self.bind(spec.size, len(texts), name)
            return texts
        raise ValueError(f"unknown attribute kind {spec.kind!r}")

    def attribute_words(self, spec: Attribute) -> str:
        if spec.kind == "vector":
            return f"{'a unit vector' if spec.unit else 'finite numbers'} of shape {self.shown_shape(spec.shape)}"
        return {"text": "a string", "integer": "an integer", "texts": "a list of strings"}[spec.kind]

    def attribute_type(self, shape: tuple | None, dtype: np.dtype) -> str:
        import h5py

        kind = "strings" if h5py.check_string_dtype(dtype) is not None else {
            "f": "floats", "i": "integers", "u": "integers", "b": "booleans"}.get(dtype.kind, f"of type {dtype}")
        return f"{kind} of shape {tuple(shape) if shape is not None else 'none'}"

    def check_fixed_text(self, name: str, dtype: np.dtype) -> None:
        """A fixed-length string's declared size, before it is read (a variable-length one
        lies in the file's heap, so reading it is bounded by the file's size: it is
        checked once read)."""
        import h5py

        info = h5py.check_string_dtype(dtype)
        if info is not None and info.length is not None and info.length > MAX_ATTRIBUTE_BYTES:
            raise self.fail(name, f"declares strings of {info.length} bytes; expected at most {MAX_ATTRIBUTE_BYTES}")

    def text_attribute(self, name: str, group: Any, key: str, shape: tuple | None, dtype: np.dtype,
                       choices: tuple[str, ...] = ()) -> str:
        import h5py

        if h5py.check_string_dtype(dtype) is None or shape not in ((), (1,)):
            raise self.fail(name, f"is {self.attribute_type(shape, dtype)}; expected a string")
        self.check_fixed_text(name, dtype)
        with self.reading(name):
            value = group.attrs[key]
        value = np.asarray(value, dtype=object).reshape(-1)[0] if not isinstance(value, (str, bytes)) else value
        text = self.decoded(name, value)
        if choices and text not in choices:
            raise self.fail(name, f"is {shortened(repr(text), 60)}; expected one of {', '.join(choices)}")
        return text

    def decoded(self, name: str, value: Any) -> str:
        if isinstance(value, bytes):
            if len(value) > MAX_ATTRIBUTE_BYTES:
                raise self.fail(name, f"is a string of {len(value)} bytes; expected at most {MAX_ATTRIBUTE_BYTES}")
            try:
                value = value.decode("utf-8")
            except UnicodeDecodeError:
                raise self.fail(name, "is not UTF-8 text; expected a UTF-8 string") from None
        if not isinstance(value, str):
            raise self.fail(name, f"is {type(value).__name__}; expected a string")
        size = len(value.encode("utf-8", "surrogatepass"))
        if size > MAX_ATTRIBUTE_BYTES:
            raise self.fail(name, f"is a string of {size} bytes; expected at most {MAX_ATTRIBUTE_BYTES}")
        return value

    def free_attributes(self, group: Any, known: set[str]) -> dict[str, Any]:
        """The root's other attributes: scalars (strings bounded), or refused."""
        import h5py

        with self.reading("/"):
            count = len(group.attrs)
        if count > MAX_ATTRIBUTES:
            raise self.fail("/", f"has {count} attributes; expected at most {MAX_ATTRIBUTES}")
        with self.reading("/"):
            names = list(group.attrs.keys())
        values: dict[str, Any] = {}
        for key in names:
            if key in known:
                continue
            if not isinstance(key, str):
                raise self.fail("/", f"has an attribute named {shortened(repr(key), 60)}; expected UTF-8 names")
            name = f"@{shortened(key, 60)}"
            if len(key.encode("utf-8", "surrogatepass")) > 255:
                raise self.fail(name, "has a name longer than 255 bytes; expected a short name")
            with self.reading(name):
                identifier = group.attrs.get_id(key)
                shape, dtype = identifier.shape, identifier.dtype
            if h5py.check_string_dtype(dtype) is not None:
                values[key] = self.text_attribute(name, group, key, shape, dtype)
            elif shape == () and dtype.kind in "iufb":
                with self.reading(name):
                    value = group.attrs[key]
                values[key] = value.item() if isinstance(value, np.generic) else value
            else:
                raise self.fail(name, f"is {self.attribute_type(shape, dtype)}; expected a string or a number")
        return values

    # ----------------------------------------------------------------- data

    def first_bad_value(self, values: np.ndarray) -> str | None:
        """'NaN at row 3' for the first value that is not finite or too large, or None."""
        flat = values.reshape(-1)
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(flat) <= MAX_MAGNITUDE)
        if not bad.any():
            return None
        first = int(np.flatnonzero(bad)[0])
        return f"{number_text(flat[first])} at {self.position(values.shape, first)}"

    @staticmethod
    def position(shape: tuple[int, ...], flat_index: int) -> str:
        if len(shape) <= 1:
            return f"row {flat_index}"
        index = np.unravel_index(flat_index, shape)
        return f"row {int(index[0])}, column {', '.join(str(int(i)) for i in index[1:])}"

    def check_values(self, array: Array, values: np.ndarray) -> np.ndarray:
        if array.finite:
            bad = self.first_bad_value(values)
            if bad is not None:
                raise self.fail(array.path, f"holds {bad}; expected finite numbers of magnitude at most "
                                            f"{MAX_MAGNITUDE:g}")
        if array.index_of is not None and values.size:
            if array.index_of not in self.sizes:
                raise self.fail(array.path, f"indexes {array.index_of}, which nothing in the file gives")
            count = self.sizes[array.index_of][0]
            flat = values.reshape(-1)
            outside = (flat < array.lowest) | (flat >= count)
            if outside.any():
                first = int(np.flatnonzero(outside)[0])
                at = f"{number_text(flat[first])} at {self.position(values.shape, first)}"
                raise self.fail(array.path, f"holds {at}; expected indices from {array.lowest} to {count - 1} "
                                            f"({self.describe(array.index_of)})")
        if array.flags and values.size:
            flat = values.reshape(-1)
            outside = (flat != 0) & (flat != 1)
            if outside.any():
                first = int(np.flatnonzero(outside)[0])
                at = f"{number_text(flat[first])} at {self.position(values.shape, first)}"
                raise self.fail(array.path, f"holds {at}; expected 0 or 1")
        if array.dtype is not None:
            values = values.astype(array.dtype, copy=False)
        return values


def _insert(tree: dict, path: str, value: Any) -> None:
    parts = [p for p in path.split("/") if p]
    node = tree
    for part in parts[:-1]:
        node = node.setdefault(part, {"attrs": {}})
    node[parts[-1]] = value


def _group_of(tree: dict, path: str) -> dict:
    node = tree
    for part in [p for p in path.split("/") if p]:
        node = node.setdefault(part, {"attrs": {}})
    return node


def read_hdf5_file(path: Path | str, layout: Layout, what: str) -> dict[str, Any]:
    """Read the HDF5 file ``path`` against ``layout`` (see the module docstring for what is
    checked, and in which order); ``what`` names the file's kind in refusals.

    Returns
    -------
    dict
        One entry per dataset, nested by group; every group (and the root) has an
        ``"attrs"`` dict. Datasets are numpy arrays (in the :class:`Array`'s dtype), string
        datasets str, attributes str, int, float or lists.

    Raises
    ------
    ArchiveError
        On the first violation: one line naming the file and the dataset or attribute.
    """
    path = Path(path)
    where = Where(path)
    fd, size = open_regular(path, what)
    with os.fdopen(fd, "rb") as stream:
        if stream.read(len(HDF5_SIGNATURE)) != HDF5_SIGNATURE:
            raise where.fail("", f"is not an HDF5 file; expected {what}")
        stream.seek(0)
        seconds = PARSE_SECONDS + size / PARSE_BYTES_PER_SECOND
        return run_isolated(lambda: _parse(stream, size, where, layout, what), seconds, where.shown)


def _parse(stream: Any, size: int, where: Where, layout: Layout, what: str) -> dict[str, Any]:
    import h5py

    try:
        handle = h5py.File(stream, "r")
    except MemoryError:
        raise
    except Exception as error:  # noqa: BLE001 - whatever HDF5 says about a damaged file
        raise where.fail("", f"cannot be read as HDF5 ({reason(error)}); expected {what}") from None
    with handle:
        return _read_layout(_HDF5(where, handle, size, layout), what)


def _read_layout(reader: _HDF5, what: str) -> dict[str, Any]:
    """What the file is, its attributes, every dataset's metadata, and only then the data."""
    tree: dict[str, Any] = {"attrs": _identify(reader, what)}
    _read_attributes(reader, tree)
    planned, total = _plan(reader, tree)
    if total > reader.size:
        raise reader.fail("", f"declares {total} bytes of data, more than its own {reader.size}; the file is damaged")
    for spec, dataset in planned:
        _insert(tree, spec.path, _load(reader, spec, dataset))
    for rule in reader.layout.rules:
        with np.errstate(all="ignore"):
            broken = rule(tree)
        if broken is not None:
            raise reader.fail(*broken)
    return tree


def _identify(reader: _HDF5, what: str) -> dict[str, Any]:
    """The format and schema_version attributes, before anything else is read."""
    layout, root = reader.layout, reader.file
    with reader.reading("/"):
        has_format = "format" in root.attrs
    if not has_format:
        raise reader.fail("@format", f"missing; expected {layout.format!r}: not {what}")
    with reader.reading("@format"):
        identifier = root.attrs.get_id("format")
    found = reader.text_attribute("@format", root, "format", identifier.shape, identifier.dtype)
    if found != layout.format:
        raise reader.fail("@format", f"is {shortened(repr(found), 60)}; expected {layout.format!r}: not {what}")
    expected = f"an integer from 1 to {layout.newest}"
    with reader.reading("/"):
        has_version = "schema_version" in root.attrs
    if not has_version:
        raise reader.fail("@schema_version", f"missing; expected {expected}")
    with reader.reading("@schema_version"):
        identifier = root.attrs.get_id("schema_version")
        shape, dtype = identifier.shape, identifier.dtype
    if shape not in ((), (1,)) or dtype.kind not in "iu":
        shown = reader.attribute_type(shape, dtype)
        if h5py_is_string(dtype) and shape in ((), (1,)):
            text = reader.text_attribute("@schema_version", root, "schema_version", shape, dtype)
            shown = shortened(repr(text), 60)
        raise reader.fail("@schema_version", f"is {shown}; expected {expected}")
    with reader.reading("@schema_version"):
        version = int(np.asarray(root.attrs["schema_version"]).reshape(-1)[0])
    if version > layout.newest:
        raise reader.fail("@schema_version", f"is {version}, newer than {layout.newest}, the one this contactfem "
                                             "reads; expected a file written by this version or an earlier one")
    if version < 1:
        raise reader.fail("@schema_version", f"is {version}; expected {expected}")
    reader.version = version
    return {"format": found, "schema_version": version}


def _read_attributes(reader: _HDF5, tree: dict[str, Any]) -> None:
    """The layout's attributes by name (types and shapes checked before values are read),
    then the root's other scalar attributes."""
    layout, root = reader.layout, reader.file
    groups: dict[str, Any] = {"/": root}
    for spec in layout.attributes:
        if spec.since > reader.version:
            continue
        group = groups.get(spec.group)
        if group is None:
            group = groups[spec.group] = reader.find(spec.group, "group")
        value = reader.attribute(spec, group)
        if value is not None:
            _group_of(tree, spec.group)["attrs"][spec.name] = value
    known = {"format", "schema_version"} | {s.name for s in layout.attributes if s.group == "/"}
    tree["attrs"].update(reader.free_attributes(root, known))


def _plan(reader: _HDF5, tree: dict[str, Any]) -> tuple[list[tuple[Array | TextData, Any]], int]:
    """Every dataset to read, its presence, type, shape and storage checked, and the total of
    their declared sizes: nothing of their data is read yet."""
    layout, version = reader.layout, reader.version
    planned: list[tuple[Array | TextData, Any]] = []
    total = 0
    for array in layout.arrays:
        if array.since > version or (array.until is not None and array.until < version):
            continue
        dataset = reader.find(array.path, "dataset", optional=array.optional)
        if dataset is None:
            continue
        with reader.reading(array.path):
            shape, dtype = tuple(dataset.shape or ()), dataset.dtype
        if dtype.kind not in array.kinds or dtype.itemsize > 8:
            raise reader.fail(array.path, f"has dtype {dtype}; expected {_kinds(array.kinds)}")
        reader.check_shape(array, shape)
        total += reader.check_storage(array.path, dataset)
        planned.append((array, dataset))
    for text in layout.texts:
        dataset = reader.find(text.path, "dataset")
        with reader.reading(text.path):
            shape, dtype = dataset.shape, dataset.dtype
        if not h5py_is_string(dtype) or shape not in ((), (1,)):
            raise reader.fail(text.path, f"is {reader.attribute_type(shape, dtype)}; expected one UTF-8 string")
        total += reader.check_storage(text.path, dataset)
        planned.append((text, dataset))
    for series in layout.series:
        members, size = _plan_series(reader, series)
        if members is not None:
            _group_of(tree, series.path)
            planned += members
            total += size
    return planned, total


def _plan_series(reader: _HDF5, series: Series) -> tuple[list[tuple[Array, Any]] | None, int]:
    group = reader.find(series.path, "group", optional=series.optional)
    if group is None:
        return None, 0
    with reader.reading(series.path):
        count = len(group)
    if count > MAX_ATTRIBUTES:
        raise reader.fail(series.path, f"has {count} members; expected at most {MAX_ATTRIBUTES}")
    with reader.reading(series.path):
        names = list(group.keys())
    members, total = [], 0
    for key in names:
        if not isinstance(key, str) or len(key) > 255:
            raise reader.fail(series.path, f"has a member named {shortened(repr(key), 60)}; expected short UTF-8 names")
        # Read as stored: no dtype, no checks of values beyond its type and length.
        array = Array(f"{series.path}/{key}", "iufb", ("_",))
        dataset = reader.find(array.path, "dataset")
        with reader.reading(array.path):
            shape, dtype = tuple(dataset.shape or ()), dataset.dtype
        if dtype.kind not in "iufb" or dtype.itemsize > 8:
            raise reader.fail(array.path, f"has dtype {dtype}; expected numbers")
        if len(shape) != 1 or shape[0] > series.max_length:
            raise reader.fail(array.path, f"has shape {shape}; expected one dimension of at most "
                                          f"{series.max_length} values")
        total += reader.check_storage(array.path, dataset)
        members.append((array, dataset))
    return members, total


def _load(reader: _HDF5, spec: Array | TextData, dataset: Any) -> Any:
    """One planned dataset's data, checked."""
    with reader.reading(spec.path):
        raw = dataset[()]
    if isinstance(spec, Array):
        return reader.check_values(spec, np.asarray(raw))
    raw = np.asarray(raw, dtype=object).reshape(-1)[0] if not isinstance(raw, (str, bytes)) else raw
    if isinstance(raw, bytes):
        if len(raw) > spec.max_bytes:
            raise reader.fail(spec.path, f"is a string of {len(raw)} bytes; expected at most {spec.max_bytes}")
        try:
            raw = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise reader.fail(spec.path, "is not UTF-8 text; expected a UTF-8 string") from None
    if not isinstance(raw, str) or len(raw.encode("utf-8", "surrogatepass")) > spec.max_bytes:
        raise reader.fail(spec.path, f"is not a string of at most {spec.max_bytes} bytes")
    return raw


def h5py_is_string(dtype: np.dtype) -> bool:
    import h5py

    return h5py.check_string_dtype(dtype) is not None


def _kinds(kinds: str) -> str:
    words = {"f": "floats", "i": "integers", "u": "integers", "b": "booleans"}
    names = list(dict.fromkeys(words[k] for k in kinds))
    return " or ".join(names) + " (8 bytes at most)"
