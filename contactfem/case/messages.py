"""The pieces of a refusal's one line: a dotted key, a value shown short, a range in words."""

from __future__ import annotations

from typing import Any

from contactfem.errors import CaseError

#: How a manufactured displacement whose fields cannot be derived is refused (a reason follows).
CANNOT_DERIVE = "cannot derive the stress and body force"


def refusal(filename: str, key: str, value: Any, expected: str) -> CaseError:
    """The one-line refusal ``file: key = value: expected`` (``file: value: expected`` without a key)."""
    shown = show_value(value)
    where = f"{key} = {shown}" if key else shown
    return CaseError(f"{filename}: {where}: {expected}")


def key_path(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix else key


def show_value(value: Any) -> str:
    try:
        text = repr(value) if isinstance(value, str) else str(value)
    except (ValueError, RecursionError):  # an integer past Python's 4300-digit str() limit
        text = f"<{type(value).__name__} too large to print>"
    return text if len(text) <= 80 else text[:77] + "..."


def shortened(text: str, limit: int = 120) -> str:
    """``text`` cut in the middle to at most ``limit`` characters (a path keeps its end, the file name)."""
    if len(text) <= limit:
        return text
    tail = (limit - 3) * 2 // 3
    return text[: limit - 3 - tail] + "..." + text[-tail:]


def range_text(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"must be in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if low is not None:
        return f"must be {'>' if low_open else '>='} {low:g}"
    if high is not None:
        return f"must be {'<' if high_open else '<='} {high:g}"
    return ""


def error_reason(error: BaseException) -> str:
    return getattr(error, "strerror", None) or str(error)
