"""Running a sweep's tasks (the study's configurations): in this process, on local processes
or on a Dask cluster, with results in task order whatever order they finish in.

    with local_jobs(2) as workers:                    # spawned processes, threads shared out
        results = run_tasks(measure, tasks, workers)
    with dask_cluster("tcp://host:8786") as workers:  # distributed.Client(...).get_executor()
        results = run_tasks(measure, tasks, workers)

A task whose worker died (killed, out of memory) is run once more; one that fails again comes
back as a Failure naming it, and the others finish. Any concurrent.futures.Executor serves
(`Workers(executor)`); only local_jobs can replace a pool broken by a dead process.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass

from ..runtime import backend

SCHEDULER_TIMEOUT = 5.0     # seconds to wait for a Dask scheduler to answer
RETRIES = 1                 # further attempts at a task whose worker failed


@dataclass(frozen=True)
class Failure:
    """A task that did not finish: `error` says why (after RETRIES more attempts)."""

    error: str


@dataclass(frozen=True)
class Incident:
    """A task whose worker failed once: `error`; `recovered` when its retry finished."""

    task: int
    error: str
    recovered: bool


class Workers:
    """Where tasks run: an Executor, and what the timings of its tasks are (`timing`:
    "serial", or how many ran at once). `threads`: the Taichi CPU threads each task uses
    (None: all cores)."""

    def __init__(self, executor: Executor, timing: str, threads: int | None = None):
        self.executor, self.timing, self.threads = executor, timing, threads

    def renew(self) -> bool:
        """Replace a broken executor; False when this one cannot be."""
        return False

    def stop(self) -> None:
        """Cancel what has not started (Ctrl-C)."""
        self.executor.shutdown(wait=False, cancel_futures=True)


class _LocalJobs(Workers):
    def __init__(self, jobs: int):
        self.jobs = jobs
        threads = max(1, backend.cpu_cores() // jobs)
        super().__init__(self._pool(), f"{jobs} jobs at once, {threads} threads each", threads)

    def _pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"))

    def renew(self) -> bool:
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.executor = self._pool()
        return True

    def stop(self) -> None:
        super().stop()
        for child in multiprocessing.active_children():   # no orphan keeps computing
            child.terminate()


def as_workers(executor) -> Workers | None:
    """None, Workers, or any concurrent.futures.Executor (its timings labelled as taken with
    other tasks at once) as Workers."""
    if executor is None or isinstance(executor, Workers):
        return executor
    if not isinstance(executor, Executor):
        raise TypeError(f"executor must be a concurrent.futures.Executor or sweep.Workers, "
                        f"got {executor!r}")
    return Workers(executor, f"{type(executor).__name__}, tasks at once")


class _DaskWorkers(Workers):
    def stop(self) -> None:
        self.executor.shutdown(wait=False)      # Dask's: cancels what runs and waits


@contextmanager
def local_jobs(jobs: int):
    """Workers on `jobs` spawned processes, each task using cores / jobs Taichi threads."""
    workers = _LocalJobs(jobs)
    try:
        yield workers
    finally:
        workers.executor.shutdown(wait=True, cancel_futures=True)


@contextmanager
def dask_cluster(address: str, timeout: float = SCHEDULER_TIMEOUT):
    """Workers of the Dask distributed cluster whose scheduler is at `address` (needs the
    optional extra `ti_cloth[dask]`); ConnectionError, naming it, when it does not answer
    within `timeout` seconds."""
    try:
        from distributed import Client
    except ImportError as err:
        raise ImportError("--scheduler needs Dask distributed: pip install 'ti_cloth[dask]'") from err
    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError) as err:
        raise ConnectionError(f"no Dask scheduler answered at {address} within {timeout:g} s "
                              f"({type(err).__name__}: {err}); start one with `dask scheduler` "
                              "and workers with `dask worker <address> --nthreads 1`") from None
    try:
        count = len(client.scheduler_info().get("workers", {}))
        yield _DaskWorkers(client.get_executor(), f"Dask cluster at {address}, {count} workers")
    finally:
        client.close()


def run_tasks(function: Callable, tasks: Sequence, workers: Workers | None = None,
              on_done: Callable[[int], None] | None = None) -> tuple[list, list[Incident]]:
    """([function(task) or a Failure, in task order], incidents in task order). Without
    workers the tasks run here, one after the other, and an exception propagates. on_done(i)
    hears of each finished task.

    A task that raised is run once more. A dead process breaks a local pool and every task in
    it, so the pool is renewed and those tasks run again one at a time: one that breaks the
    pool alone is the one at fault, and fails."""
    on_done = on_done or (lambda i: None)
    if workers is None:
        results = []
        for i, task in enumerate(tasks):
            results.append(function(task))
            on_done(i)
        return results, []
    results: list = [None] * len(tasks)
    errors: dict[int, str] = {}          # the first error of each task that had to run again
    careful: list[int] = []              # lost in a broken pool: to run one at a time

    def finish(i, value):
        results[i] = value
        on_done(i)

    try:
        running = {workers.executor.submit(function, task): i for i, task in enumerate(tasks)}
        solo = None                          # the task running alone, from `careful`
        while running or careful:
            if not running:
                solo = careful.pop(0)
                running[workers.executor.submit(function, tasks[solo])] = solo
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            lost, again, broken = [], [], False
            for future in done:
                i = running.pop(future)
                error = future.exception()
                message = "" if error is None else f"{type(error).__name__}: {error}"
                broken |= isinstance(error, BrokenProcessPool)
                if error is None:
                    finish(i, future.result())
                elif i == solo or (i in errors and not isinstance(error, BrokenProcessPool)):
                    finish(i, Failure(message))          # its second failure
                elif isinstance(error, BrokenProcessPool):
                    errors.setdefault(i, message)
                    lost.append(i)
                else:
                    errors[i] = message
                    again.append(i)
            solo = None
            if broken:                         # the pool is gone, with every task in it
                lost += running.values()
                running = {}
                for i in lost:
                    errors.setdefault(i, "BrokenProcessPool: a worker process died")
                if workers.renew():
                    careful += sorted(lost)
                else:
                    for i in lost + careful:
                        finish(i, Failure(errors[i]))
                    careful = []
            for i in again:
                running[workers.executor.submit(function, tasks[i])] = i
    except BaseException:
        workers.stop()
        raise
    incidents = [Incident(i, errors[i], not isinstance(results[i], Failure)) for i in sorted(errors)]
    return results, incidents
