"""A benchmark's sizes, one after another here or as tasks on Dask (contactfem.engines, the
engine of ``contactfem sweep`` and ``converge``).

Each size's own function starts a fresh subprocess (``--single N``) wherever it runs, so
that the size's peak memory is its own, not a long-lived worker's high-water mark. Sizes run
side by side share the cores: time them with ``--workers 1`` or without Dask (the default).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from contextlib import nullcontext


def add_engine_options(parser: argparse.ArgumentParser) -> None:
    """--scheduler and --workers, as the ``contactfem`` commands spell them."""
    parser.add_argument("--scheduler", metavar="ADDRESS", default=None,
                        help="run the sizes on the Dask cluster of this scheduler, e.g. tcp://10.0.0.5:8786")
    parser.add_argument("--workers", type=int, default=None,
                        help="run the sizes on a local Dask cluster of this many workers (default: no Dask, "
                             "one size after another)")


def run_sizes(run_one: Callable[[int], object], sizes: list[int], *, scheduler: str | None = None,
              workers: int | None = None, lost: Callable[[int, str], object],
              finished: Callable[[object], None] | None = None) -> list:
    """``run_one(size)`` of each size, in the order of ``sizes``; ``finished(value)`` as each
    ends; ``lost(size, reason)`` stands for a size whose task raised or whose workers died."""
    from contactfem.engines import SerialEngine, in_order, open_engine

    def one(task: dict, function: Callable[[int], object]) -> object:
        # Nested, so that Dask sends it by value: the workers need not import this file.
        return function(task["size"])

    dask = scheduler is not None or workers is not None
    tasks = [{"index": i, "size": size} for i, size in enumerate(sizes)]
    with open_engine(scheduler, workers, len(tasks)) if dask else nullcontext(SerialEngine()) as engine:
        if engine.note:
            print(f"note: {engine.note}", flush=True)
        return in_order(engine, one, tasks, run_one, lost=lambda task, reason: lost(task["size"], reason),
                        name="size", progress=None if finished is None else
                        lambda task, value, done, total: finished(value))
