"""Typed access to the YAML data of a case: each check refuses in one line naming the
file, the dotted key, the value and what was expected."""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Any

from contactfem.case import limits
from contactfem.case.messages import key_path, range_text, refusal, shortened, show_value
from contactfem.errors import CaseError
from contactfem.expressions import Expression, ExpressionError, compile_expression


class Reader:
    """Typed access to a YAML mapping that reports errors with the file and dotted key."""

    def __init__(self, filename: str) -> None:
        self.filename = filename
        #: The SHA-256 of each data file the case reads (a profile, an outline, a mesh),
        #: hashed with its text, and their paths.
        self.inputs: list[bytes] = []
        self.input_paths: list[Path] = []
        #: Bytes read from data files so far, against limits.MAX_DATA_FILE_BYTES for all of them.
        self.data_bytes = 0

    def fail(self, key: str, value: Any, expected: str) -> CaseError:
        return refusal(self.filename, key, value, expected)

    def mapping(self, data: Any, key: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, data, "expected a mapping of keys to values")
        for name in data:
            if not isinstance(name, str) or name not in allowed:
                shown = shortened(name if isinstance(name, str) else show_value(name), 64)
                close = difflib.get_close_matches(name, allowed, n=1) if isinstance(name, str) else []
                hint = f" (did you mean {close[0]}?)" if close else ""
                raise CaseError(
                    f"{self.filename}: {key_path(key, shown)}: unknown key{hint}; "
                    f"expected one of {', '.join(allowed)}"
                )
        for name in required:
            if name not in data:
                raise CaseError(f"{self.filename}: {key_path(key, name)}: missing (required)")
        return data

    def number(self, value: Any, key: str, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, high_open: bool = False, expected: str | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            # YAML 1.1 reads "1e6" (no dot) as a string: accept plain numeric strings.
            if isinstance(value, str):
                try:
                    value = float(value)
                except ValueError:
                    raise self.fail(key, value, "expected a number") from None
            else:
                raise self.fail(key, value, "expected a number")
        rule = expected or range_text(low, high, low_open, high_open)
        try:
            value = float(value)
        except OverflowError:
            raise self.fail(key, value, f"expected a finite number{', ' + rule if rule else ''}") from None
        if not math.isfinite(value):
            raise self.fail(key, value, f"expected a finite number{', ' + rule if rule else ''}")
        if low is not None and (value < low or (low_open and value == low)):
            raise self.fail(key, value, rule)
        if high is not None and (value > high or (high_open and value == high)):
            raise self.fail(key, value, rule)
        return value

    def integer(self, value: Any, key: str, *, low: int, high: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, value, f"expected an integer in [{low}, {high}]")
        if not low <= value <= high:
            raise self.fail(key, value, f"expected an integer in [{low}, {high}]")
        return value

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(key, value, "expected true or false")
        return value

    def choice(self, value: Any, key: str, choices: tuple[str, ...]) -> str:
        if not isinstance(value, str) or value not in choices:
            raise self.fail(key, value, f"expected one of {', '.join(choices)}")
        return value

    NAME_EXPECTED = "a part name (a non-empty string of at most 64 printable characters)"

    @staticmethod
    def is_name(value: Any) -> bool:
        return isinstance(value, str) and bool(value.strip()) and len(value) <= 64 and value.isprintable()

    def name(self, value: Any, key: str) -> str:
        if not self.is_name(value):
            raise self.fail(key, value, f"expected {self.NAME_EXPECTED}")
        return value

    def point(self, value: Any, key: str) -> tuple[float, float]:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise self.fail(key, value, "expected a point [x, y]")
        return (self.number(value[0], f"{key}[0]", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT),
                self.number(value[1], f"{key}[1]", low=-limits.SCALE_LIMIT, high=limits.SCALE_LIMIT))

    def expression(self, value: Any, key: str) -> Expression:
        try:
            return compile_expression(value)
        except ExpressionError as error:
            raise self.fail(key, value, str(error)) from None

    def vector_field(self, value: Any, key: str, *, allow_free: bool = False) -> tuple[Expression | None, ...]:
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            what = "[x, y] components (numbers or expressions in x and y"
            what += ", or null for a free component)" if allow_free else ")"
            raise self.fail(key, value, f"expected two {what}")
        components = []
        for i, item in enumerate(value):
            if item is None and allow_free:
                components.append(None)
            else:
                components.append(self.expression(item, f"{key}[{i}]"))
        return tuple(components)
