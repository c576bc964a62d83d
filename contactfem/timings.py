"""The wall clock, read only to report seconds: no result and no decision depends on it."""

from __future__ import annotations

import time


def clock() -> float:
    """Seconds on a monotonic clock (an origin of its own): differences are elapsed time."""
    return time.perf_counter()
