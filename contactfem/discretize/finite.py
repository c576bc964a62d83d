"""Refusal of data that is not finite (or too large to integrate) where the discrete problem uses it."""

from __future__ import annotations

import numpy as np

from contactfem.case import SCALE_LIMIT, Case
from contactfem.errors import CaseError
from contactfem.expressions import Expression


def check_finite(case: Case, key: str, fields: tuple[Expression | None, ...], where: np.ndarray) -> None:
    for i, expression in enumerate(fields):
        if expression is None:
            continue
        values = np.broadcast_to(expression(where[:, 0], where[:, 1]), len(where))
        refuse_non_finite(case, f"{key}[{i}]" if len(fields) > 1 else key, expression, values, where)


def refuse_non_finite(case: Case, key: str, field: Expression, values: np.ndarray, where: np.ndarray) -> None:
    # Values beyond SCALE_LIMIT would overflow once integrated and solved (NaN residuals).
    bad = ~(np.abs(values) <= SCALE_LIMIT)
    if bad.any():
        x, y = where[np.argmax(bad)]
        value = values.flat[np.argmax(bad)]
        what = "not finite" if not np.isfinite(value) else f"{value:.3g} exceeds {SCALE_LIMIT:g} in magnitude"
        raise CaseError(
            f"{case.source.name}: {key} = {field.text!r}: {what} at ({x:g}, {y:g}); "
            "expected finite values on the whole part"
        )
