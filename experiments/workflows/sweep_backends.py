"""Execution backends of sweeps: the same chunk tasks on local processes or on dask.distributed.

A task is a picklable object; ``fn(task)`` computes one chunk, writes its file atomically and
returns a small report dict. The backends only schedule: results never depend on the backend,
the number of workers or the order of completion (each chunk's random numbers come from its
own seed blocks, see :mod:`experiments.workflows.sweep`).

- ``local``: :class:`concurrent.futures.ProcessPoolExecutor` with one process per core (one
  task in-process when there is a single task or worker, avoiding the process start-up).
- ``dask``: a :class:`dask.distributed.LocalCluster` (processes, one thread each) when no
  address is given, or any running cluster at ``scheduler`` (``tcp://host:8786``). An
  unreachable scheduler raises :class:`SchedulerUnreachableError` within ``timeout_s``.

On Ctrl-C the pending tasks are cancelled and :class:`KeyboardInterrupt` propagates; chunks
already written stay on disk (atomic writes), so rerunning the same command resumes.
"""

from __future__ import annotations

import os
from typing import Callable, Sequence

from skysim.exceptions import InvalidParameterError, MissingDependencyError, SkysimError

__all__ = ["BACKENDS", "SchedulerUnreachableError", "run_tasks", "default_workers"]

BACKENDS = ("local", "dask")


class SchedulerUnreachableError(SkysimError, RuntimeError):
    """No dask scheduler answers at the given address."""


def default_workers() -> int:
    """Usable cores of this process (affinity-aware), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _progress(total: int, enabled: bool, desc: str):
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit="chunk", disable=not enabled)


def _run_local(fn, tasks, workers, bar, on_done):
    if workers == 1 or len(tasks) == 1:
        for t in tasks:
            on_done(fn(t))
            bar.update(1)
        return
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    pool = ProcessPoolExecutor(max_workers=min(workers, len(tasks)), initializer=_worker_init)
    try:
        pending = {pool.submit(fn, t) for t in tasks}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                on_done(fut.result())
                bar.update(1)
    except BaseException:
        # Ctrl-C or a failed chunk: stop now, not after the queued chunks (finished chunks
        # are on disk; the caller removes the temporary files of the chunks cut short)
        procs = list((getattr(pool, "_processes", None) or {}).values())  # before shutdown
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        raise
    pool.shutdown(wait=True)


def _worker_init() -> None:
    """Worker processes leave Ctrl-C to the parent, which stops them (SIGTERM: the pool's
    worker loop would catch an exception raised in a signal handler and carry on)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _connect(scheduler: str | None, workers: int, timeout_s: float):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the environment
        from skysim.extras import missing_extra_message
        raise MissingDependencyError(missing_extra_message("distributed", "the dask backend"),
                                     name="distributed") from exc
    if scheduler:
        try:
            return Client(scheduler, timeout=f"{timeout_s}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise SchedulerUnreachableError(
                f"no dask scheduler reachable at {scheduler!r} within {timeout_s:g} s ({exc}); "
                "start one with `dask scheduler` (and `dask worker ADDRESS`), check the "
                "address, or omit --scheduler to use a local cluster") from exc
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), cluster


def _run_dask(fn, tasks, workers, bar, on_done, scheduler, timeout_s):
    from dask.distributed import as_completed
    client, cluster = _connect(scheduler, workers, timeout_s)
    futures = []
    try:
        futures = client.map(fn, list(tasks), pure=False)
        for fut in as_completed(futures):
            on_done(fut.result())
            bar.update(1)
    except BaseException:
        client.cancel(futures)
        raise
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_tasks(fn: Callable, tasks: Sequence, *, backend: str = "local",
              scheduler: str | None = None, workers: int | None = None,
              progress: bool = True, on_done: Callable | None = None,
              timeout_s: float = 10.0, desc: str = "sweep") -> list:
    """Run ``fn`` on every task; return the reports in completion order.

    Parameters
    ----------
    fn : callable
        A module-level function (picklable) computing and writing one chunk.
    tasks : sequence of picklable tasks
    backend : {"local", "dask"}
    scheduler : str, optional
        dask scheduler address; None starts a LocalCluster with ``workers`` workers.
    workers : int, optional
        Processes (local) or LocalCluster workers (dask); default: usable cores.
    progress : bool
        tqdm progress bar on the console.
    on_done : callable, optional
        Called with each report as it arrives (e.g. to log).
    timeout_s : float
        Connection timeout for ``scheduler`` [s].

    Raises
    ------
    InvalidParameterError
        For an unknown backend, or ``scheduler`` with the local backend.
    SchedulerUnreachableError
        If ``scheduler`` does not answer.
    """
    if backend not in BACKENDS:
        raise InvalidParameterError(f"unknown backend {backend!r}; valid: {', '.join(BACKENDS)}")
    if scheduler and backend != "dask":
        raise InvalidParameterError("--scheduler needs --backend dask")
    workers = workers or default_workers()
    if workers < 1:
        raise InvalidParameterError(f"workers must be >= 1; got {workers}")
    reports = []

    def done(report):
        reports.append(report)
        if on_done is not None:
            on_done(report)

    if not tasks:
        return reports
    with _progress(len(tasks), progress, desc) as bar:
        if backend == "local":
            _run_local(fn, tasks, workers, bar, done)
        else:
            _run_dask(fn, tasks, workers, bar, done, scheduler, timeout_s)
    return reports
