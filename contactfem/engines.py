"""Where independent tasks run: one after another in this process, or as tasks on a Dask cluster.

One mechanism for every study that runs independent solves (a sweep's points, a convergence
study's levels, a benchmark's sizes): :func:`open_engine` chooses and starts the cluster (a
LocalCluster of single-threaded workers with a memory limit each, an existing scheduler, or
this process when Dask is not installed), :meth:`SerialEngine.map` and :meth:`DaskEngine.map`
yield each task's value as it finishes and turn a task that raised or whose workers died
into the caller's own record (``lost``), and an interrupted map cancels what is left on the
cluster. Data every task reads (a convergence study's reference solution) is handed to the
workers once by :meth:`~DaskEngine.shared`, not sent with each task.

Dask (distributed) is an optional dependency, imported only here and only when used.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager, nullcontext
from typing import Any

from contactfem.case import shortened
from contactfem.errors import CaseError, SolverError
from contactfem.estimate import MemoryLimit, memory_budget
from contactfem.timings import clock

#: Dask re-runs a task that raised this many times (a worker that dies is handled by the
#: scheduler itself: it reschedules the task on another worker, up to
#: ``distributed.scheduler.allowed-failures`` deaths).
RETRIES = 2
#: Solves run one per worker process: BLAS and OpenMP threads would only compete.
SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                   "VECLIB_MAXIMUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}
INSTALL_HINT = "pip install -e '.[dask]'"
#: How long to wait for an existing scheduler to answer.
CONNECT_TIMEOUT = "10s"

#: ``lost(task, reason)``: the value a task stands for when it raised or its workers died.
Lost = Callable[[dict, str], Any]


def worker_memory_limit() -> MemoryLimit | None:
    """The memory limit of the Dask worker running this task (None: not in a worker, or it
    has none). Its nanny kills a worker past it, so the size guard refuses against it: a
    task too large for its worker is refused at once instead of killing three workers in
    turn."""
    try:
        from distributed import get_worker

        limit = get_worker().memory_manager.memory_limit
    except (ImportError, ValueError, AttributeError):
        return None
    if not limit:
        return None
    return MemoryLimit(int(limit), f"this Dask worker's memory limit of {limit / 2**30:.3g} GiB")


def worker_budget():
    """A context in which the size guard refuses against this worker's memory limit (nothing
    outside a Dask worker)."""
    limit = worker_memory_limit()
    return memory_budget(limit) if limit is not None else nullcontext()


class DaskMissing(ImportError):
    """Dask (distributed) is not installed."""


def _raising(task: dict, reason: str):
    raise SolverError(f"task {task.get('index')}: {reason}")


class SerialEngine:
    """The tasks one after another in this process."""

    kind = "serial"
    scheduler = None
    workers = 1
    note: str | None = None
    startup_seconds = 0.0

    @contextmanager
    def shared(self, value: Any) -> Iterator[Any]:
        """``value`` itself: the tasks run here."""
        yield value

    def map(self, function: Callable[..., Any], tasks: list[dict], *shared: Any,
            lost: Lost = _raising, name: str = "task") -> Iterator[tuple[dict, Any]]:
        """``(task, function(task, *shared))`` for each task, in order."""
        for task in tasks:
            try:
                value = function(task, *shared)
            except Exception as error:  # noqa: BLE001 - as on a Dask worker: the task's own message
                value = lost(task, f"{type(error).__name__}: {error}")
            yield task, value


class DaskEngine:
    """The tasks on ``client``'s cluster, yielded as they finish."""

    kind = "dask"
    note: str | None = None

    def __init__(self, client, scheduler: str | None = None, retries: int = RETRIES,
                 startup_seconds: float = 0.0) -> None:
        self.client = client
        self.scheduler = scheduler
        self.retries = retries
        self.startup_seconds = startup_seconds

    @property
    def workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    @contextmanager
    def shared(self, value: Any) -> Iterator[Any]:
        """A future of ``value``, serialised once and copied to every worker: passed to
        :meth:`map`, each task receives the value without it being sent with the task."""
        [future] = self.client.scatter([value], broadcast=True, hash=False)
        try:
            yield future
        finally:
            future.release()

    def map(self, function: Callable[..., Any], tasks: list[dict], *shared: Any,
            lost: Lost = _raising, name: str = "task") -> Iterator[tuple[dict, Any]]:
        """``(task, function(task, *shared))`` for each task as it finishes (``task['index']``
        names its Dask key); cancels what is left when the caller stops early (Ctrl-C)."""
        from distributed import KilledWorker, as_completed

        token = os.urandom(4).hex()
        futures = {self.client.submit(function, task, *shared, key=f"contactfem-{name}-{task['index']}-{token}",
                                      retries=self.retries, pure=False): task for task in tasks}
        try:
            for future in as_completed(list(futures), loop=self.client.loop):
                task = futures.pop(future)
                try:
                    value = future.result()
                except KilledWorker:
                    value = lost(task, f"every worker that ran this {name} died (killed, or over its memory limit)")
                except Exception as error:  # noqa: BLE001 - any task exception becomes the task's message
                    value = lost(task, f"{type(error).__name__}: {error}")
                future.release()
                yield task, value
        finally:
            if futures:  # interrupted: nothing left should keep running on the cluster
                self.client.cancel(list(futures))


def dask_setup(worker) -> None:
    """Dask's preload hook, run in each worker of the local cluster as it starts (a restarted one
    too): Ctrl-C on a terminal reaches the whole process group, but stopping is the command's
    job (it cancels the tasks and closes the cluster); a worker that took it would print its
    own traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def local_cluster_size(workers: int | None, pending: int) -> tuple[int, int]:
    """Workers and bytes of memory each for a cluster on this machine: ``workers`` or one per
    core, at most one per task to run, the machine's memory shared out among them."""
    from dask.system import CPU_COUNT
    from distributed.system import MEMORY_LIMIT

    count = max(1, min(workers if workers is not None else CPU_COUNT, pending))
    return count, int(MEMORY_LIMIT // count)


@contextmanager
def open_engine(scheduler: str | None = None, workers: int | None = None,
                pending: int = 1) -> Iterator[SerialEngine | DaskEngine]:
    """The engine tasks run on: a LocalCluster of ``workers`` processes by default (one thread
    each, single-threaded BLAS, a memory limit each), the cluster at ``scheduler`` if given,
    and this process if Dask is not installed (``engine.note`` then says how to install it).

    Raises
    ------
    CaseError
        ``scheduler`` is given but Dask is not installed or the scheduler does not answer.
    """
    try:
        import dask
        import distributed
    except ImportError:
        if scheduler is not None:
            raise CaseError(f"--scheduler {shortened(scheduler, 80)}: Dask is not installed; "
                            f"expected Dask for a cluster ({INSTALL_HINT})") from None
        engine = SerialEngine()
        engine.note = (f"Dask is not installed: the tasks run one after another in this process "
                       f"({INSTALL_HINT} runs them in parallel)")
        yield engine
        return
    import logging

    started = clock()
    if scheduler is not None:
        client = _connect(distributed, scheduler)
        try:
            yield DaskEngine(client, scheduler=scheduler, startup_seconds=clock() - started)
        finally:
            client.close()
        return
    count, memory = local_cluster_size(workers, pending)
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **SINGLE_THREADED}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
            cluster = distributed.LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                               memory_limit=memory, dashboard_address=None, env=SINGLE_THREADED,
                                               silence_logs=logging.ERROR, preload=[__name__])
    except (OSError, RuntimeError, TimeoutError) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise SolverError(f"cannot start a local Dask cluster of {count} worker(s) ({shortened(reason, 160)}); "
                          "a script that calls this must guard its entry point with if __name__ == '__main__'") from None
    try:
        client = distributed.Client(cluster, set_as_default=False)
        try:
            yield DaskEngine(client, startup_seconds=clock() - started)
        finally:
            client.close()
    finally:
        cluster.close()


def _connect(distributed, scheduler: str):
    """A client of the running scheduler at ``scheduler``; CaseError naming it when the address
    is malformed or nothing answers there."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(scheduler)
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(location)
    except (ValueError, TypeError) as error:
        raise CaseError(f"--scheduler {shortened(scheduler, 80)}: {' '.join(str(error).split())}; expected the "
                        "address of a running Dask scheduler, e.g. tcp://host:8786") from None
    try:
        return distributed.Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError, TypeError) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise CaseError(f"--scheduler {shortened(scheduler, 80)}: cannot connect ({shortened(reason, 160)}); "
                        "expected the address of a running Dask scheduler, e.g. tcp://host:8786") from None


def in_order(engine: SerialEngine | DaskEngine, function: Callable[..., Any], tasks: list[dict], *shared: Any,
             lost: Lost = _raising, name: str = "task",
             progress: Callable[[dict, Any, int, int], None] | None = None) -> list[Any]:
    """Every task's value in the order of ``tasks``, whatever order they finish in;
    ``progress(task, value, done, total)`` as each finishes, and may raise to stop."""
    values: dict[int, Any] = {}
    # closing: a progress that raises (a caller stopping early) cancels what is left at once.
    with closing(engine.map(function, tasks, *shared, lost=lost, name=name)) as finished:
        for done, (task, value) in enumerate(finished, start=1):
            values[id(task)] = value
            if progress is not None:
                progress(task, value, done, len(tasks))
    return [values[id(task)] for task in tasks]
