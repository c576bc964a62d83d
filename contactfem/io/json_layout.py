"""Reading a JSON file contactfem wrote, as untrusted input, against a tree of expected
values (:class:`Node`): :func:`read_json_file`. See :mod:`contactfem.io.archive` for why
and :mod:`contactfem.io.readback` for the files' layouts."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.errors import ArchiveError
from contactfem.io.untrusted import MAX_MAGNITUDE, Where, number_text, open_regular, read_all, reason, shortened

__all__ = ["Boolean", "Choice", "Integer", "Items", "Mapping", "Node", "Number", "Object", "Text", "read_json_file"]

#: A string a JSON layout does not bound otherwise.
DEFAULT_TEXT_BYTES = 4096


class Node:
    """What one JSON value must be; :meth:`check` returns it (possibly converted) or raises."""

    nullable: bool = False

    def words(self) -> str:
        raise NotImplementedError

    def check(self, value: Any, key: str, context: _JSON) -> Any:
        raise NotImplementedError

    def accepts_null(self, value: Any) -> bool:
        return value is None and self.nullable

    def or_null(self) -> str:
        return " or null" if self.nullable else ""


def _found(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) and abs(value) >= 10**30:
        return "a very large integer"
    if isinstance(value, (int, float)):
        return number_text(value)
    if isinstance(value, str):
        return shortened(repr(value), 60)
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    return "an object"


@dataclass
class Number(Node):
    """A finite number (an integer too) of magnitude at most :data:`MAX_MAGNITUDE`, at least
    ``minimum`` (above it with ``positive``)."""

    minimum: float | None = None
    positive: bool = False
    nullable: bool = False

    def words(self) -> str:
        bound = "" if self.minimum is None else f" {'>' if self.positive else '>='} {self.minimum:g}"
        return f"a finite number{bound}{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= MAX_MAGNITUDE:
            raise context.fail(key, value, self.words())
        if self.minimum is not None and (value < self.minimum or (self.positive and value == self.minimum)):
            raise context.fail(key, value, self.words())
        return value


@dataclass
class Integer(Node):
    minimum: int | None = None
    nullable: bool = False

    def words(self) -> str:
        return f"an integer{'' if self.minimum is None else f' >= {self.minimum}'}{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if isinstance(value, bool) or not isinstance(value, int) or (self.minimum is not None and value < self.minimum):
            raise context.fail(key, value, self.words())
        return value


@dataclass
class Boolean(Node):
    nullable: bool = False

    def words(self) -> str:
        return f"true or false{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value) or isinstance(value, bool):
            return value
        raise context.fail(key, value, self.words())


@dataclass
class Text(Node):
    """A string of at most ``max_bytes`` bytes (UTF-8)."""

    max_bytes: int = DEFAULT_TEXT_BYTES
    nullable: bool = False

    def words(self) -> str:
        return f"a string of at most {self.max_bytes} bytes{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if not isinstance(value, str) or len(value) > self.max_bytes \
                or len(value.encode("utf-8", "surrogatepass")) > self.max_bytes:
            shown = f"a string of {len(value.encode('utf-8', 'surrogatepass'))} bytes" if isinstance(value, str) \
                else None
            raise context.fail(key, value, self.words(), shown)
        return value


@dataclass
class Choice(Node):
    choices: tuple = ()
    nullable: bool = False

    def words(self) -> str:
        return "one of " + ", ".join(json.dumps(c) for c in self.choices) + self.or_null()

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if isinstance(value, bool) or value not in self.choices or type(value) is not type(self.choices[0]):
            raise context.fail(key, value, self.words())
        return value


@dataclass
class Items(Node):
    """A list of ``item`` values; ``size`` names a length shared with other lists (the first
    list with that name binds it), ``length`` fixes it, ``max_items`` bounds it."""

    item: Node = field(default_factory=lambda: Number())
    size: str | None = None
    length: int | None = None
    max_items: int = 10_000_000
    nullable: bool = False

    def words(self) -> str:
        count = f"{self.length} " if self.length is not None else ""
        return f"a list of {count}items, each {self.item.words()}{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if not isinstance(value, list):
            raise context.fail(key, value, self.words())
        if self.length is not None and len(value) != self.length:
            raise context.fail(key, value, f"a list of exactly {self.length} items")
        if len(value) > self.max_items:
            raise context.fail(key, value, f"a list of at most {self.max_items} items")
        if self.size is not None:
            if self.size in context.sizes:
                expected, origin = context.sizes[self.size]
                if len(value) != expected:
                    raise context.fail(key, value, f"a list of {expected} items, one per item of {origin}")
            else:
                context.sizes[self.size] = (len(value), key)
        if type(self.item) is Number and _plain_numbers(value, self.item):
            return value  # the common case, checked at once; otherwise item by item, to name the first bad one
        return [self.item.check(v, f"{key}[{i}]", context) for i, v in enumerate(value)]


def _plain_numbers(values: list, node: Number) -> bool:
    """Whether every value is an int or float ``node`` accepts (null aside), without a call per value."""
    if not all(type(v) is float or type(v) is int for v in values):
        return False
    try:
        numbers = np.asarray(values, dtype=np.float64) if values else np.zeros(0)
    except (OverflowError, ValueError):  # an integer beyond float64
        return False
    with np.errstate(invalid="ignore", over="ignore"):
        if not (np.abs(numbers) <= MAX_MAGNITUDE).all():
            return False
        if node.minimum is not None:
            low = numbers > node.minimum if node.positive else numbers >= node.minimum
            return bool(low.all())
    return True


@dataclass
class Object(Node):
    """A JSON object with the ``required`` keys and possibly the ``optional`` ones (other
    keys are kept, unchecked: nothing reads them). ``rule``, given the checked object,
    returns (key, what was expected) for a combination of values it refuses, or None."""

    required: dict[str, Node] = field(default_factory=dict)
    optional: dict[str, Node] = field(default_factory=dict)
    nullable: bool = False
    rule: Callable[[dict], tuple[str, str] | None] | None = None

    def words(self) -> str:
        return f"an object{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if not isinstance(value, dict):
            raise context.fail(key, value, self.words())
        out = dict(value)
        for name, node in self.required.items():
            inner = f"{key}.{name}" if key else name
            if name not in value:
                raise context.missing(inner, node.words())
            out[name] = node.check(value[name], inner, context)
        for name, node in self.optional.items():
            if name in value:
                out[name] = node.check(value[name], f"{key}.{name}" if key else name, context)
        broken = self.rule(out) if self.rule is not None else None
        if broken is not None:
            name, expected = broken
            raise context.fail(f"{key}.{name}" if key else name, out.get(name), expected)
        return out


@dataclass
class Mapping(Node):
    """An object of any keys (at most ``max_items``, each a short string), each value a ``value``."""

    value: Node = field(default_factory=lambda: Number())
    max_items: int = 1000
    nullable: bool = False

    def words(self) -> str:
        return f"an object whose values are each {self.value.words()}{self.or_null()}"

    def check(self, value, key, context):
        if self.accepts_null(value):
            return value
        if not isinstance(value, dict):
            raise context.fail(key, value, self.words())
        if len(value) > self.max_items:
            raise context.fail(key, value, f"an object of at most {self.max_items} keys")
        out = {}
        for name, item in value.items():
            if len(name) > 255:
                raise context.fail(key, value, "keys of at most 255 characters", f"a key of {len(name)} characters")
            out[name] = self.value.check(item, f"{key}.{name}" if key else name, context)
        return out


class _JSON:
    def __init__(self, where: Where) -> None:
        self.where = where
        self.sizes: dict[str, tuple[int, str]] = {}

    def fail(self, key: str, value: Any, expected: str, shown: str | None = None) -> ArchiveError:
        return self.where.fail(shortened(key or "the top level", 80),
                               f"is {shown or _found(value)}; expected {expected}")

    def missing(self, key: str, expected: str) -> ArchiveError:
        return self.where.fail(shortened(key, 80), f"missing; expected {expected}")


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def read_json_file(path: Path | str, node: Node, what: str, max_bytes: int) -> Any:
    """Read the JSON file ``path`` of at most ``max_bytes`` bytes and check it against ``node``.

    Refused: not a regular file, empty, larger than ``max_bytes`` (known from its size,
    before it is read), not UTF-8, not strict JSON (NaN, Infinity, integers past Python's
    digit limit; nesting past the interpreter's recursion limit), or a value ``node`` does
    not accept (a number that overflowed to infinity among them); ``what`` names the
    file's kind in refusals. Only what ``node`` describes is traversed.
    """
    path = Path(path)
    where = Where(path)
    fd, size = open_regular(path, what)
    try:
        if size > max_bytes:
            raise where.fail("", f"is {size} bytes; expected {what} of at most {max_bytes} bytes")
        try:
            data = read_all(fd, size, where, what)
        except OSError as error:
            raise where.fail("", f"cannot be read ({reason(error)})") from None
    finally:
        os.close(fd)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise where.fail("", f"is not UTF-8 text (byte {error.start}); expected {what}") from None
    try:
        value = json.loads(text, parse_constant=_no_constant)
    except (ValueError, RecursionError) as error:
        problem = shortened(str(error).splitlines()[0] if str(error) else type(error).__name__, 160)
        raise where.fail("", f"is not valid JSON ({problem}); expected {what}") from None
    return node.check(value, "", _JSON(where))
