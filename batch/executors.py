"""Where a batch's cases run: `local` worker processes or the workers of a Dask cluster.

Both run `plan_case` on each task in a process of its own — a local worker, or a Dask worker's child
process (`plan_in_child`) — one case at a time with one BLAS thread, in no more processes than there are
cases — and yield the (task, result) pairs of the cases finished since the last yield, in any order. A
worker that dies (killed, out of memory) fails the case it was planning, not the batch. Those processes
die with whoever started them (Linux: the parent-death signal), so a killed batch leaves no worker
writing behind it.
"""
from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing
import os
import signal
import sys
import threading
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Iterator

from breastplan import BadInputError

from .task import Task, plan_case

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
DASK_WORKER_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                      "distributed.worker.memory.monitor-interval": "1s", "distributed.admin.system-monitor.interval": "5s",
                      "distributed.scheduler.work-stealing": False, "distributed.worker.memory.spill": False,
                      "distributed.worker.memory.target": False, "distributed.worker.daemon": False}
"""A local cluster: no statistical profiler and slower housekeeping in the workers, whose event-loop wake-ups
take the interpreter lock and the CPU from the case being planned (with the defaults a case took up to twice
its time in a local worker process on a 2-core machine); no spilling to disk and no work stealing (each task
returns a small dict, and the scheduler's queue already hands a free worker the next case); workers that
are not daemons, so that they may start the process their cases run in (`plan_in_child`)."""
REACH_SECONDS, ANSWER_SECONDS = 20, 5
"""How long a batch waits for a Dask scheduler's address to take a connection, and then for what took it
to answer as a scheduler."""
ATTEMPTS = 2
"""A case whose worker died this many times is failed; the others it took down are retried."""
PR_SET_PDEATHSIG = 1

Results = Iterator[list[tuple[Task, dict]]]


def one_thread_environment() -> None:
    """One BLAS/OpenMP thread in this process and the processes it starts (set before numpy loads)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"


_STARTED = None
"""A local worker's queue of the cases it starts (`_local_worker`), by which the batch knows which were being
planned when a worker died."""


def _local_worker(parent: int, started=None) -> None:
    """A local worker's start: one thread, death with the batch, and where it says which case it starts."""
    global _STARTED
    _STARTED = started
    one_thread_environment()
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:   # the batch died before the signal was armed
            os._exit(1)


def run_local(tasks: list[Task], jobs: int) -> Results:
    """Plan `tasks` in `jobs` worker processes (spawned: no state shared with the batch). When a worker dies
    while several cases are being planned, each of them is planned again alone, so that only the one that kills
    its worker is charged (ATTEMPTS)."""
    attempts: Counter = Counter()
    pending, alone = list(tasks), []
    context = multiprocessing.get_context("spawn")
    while pending or alone:
        solo = bool(alone)
        todo = alone[:1] if solo else pending            # alone: one case in a pool of its own
        started = context.SimpleQueue()
        pool = ProcessPoolExecutor(1 if solo else min(jobs, len(todo)), mp_context=context,
                                   initializer=_local_worker, initargs=(os.getpid(), started))
        broken = []
        try:
            futures = {pool.submit(_started_and_planned, t): t for t in todo}
            waiting = set(futures)
            while waiting:
                done, waiting = wait(waiting, return_when=FIRST_COMPLETED)
                settled = []
                for future in done:
                    try:
                        settled.append((futures[future], future.result()))
                    except BrokenProcessPool:
                        broken.append(futures[future])
                if settled:
                    yield settled
        except BaseException:       # interrupted (Ctrl-C) or closed: the cases being planned are dropped, unfinished
            for process in list((pool._processes or {}).values()):      # Python < 3.14 has no public kill
                process.kill()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        running = set()                          # begun and not settled: the cases a worker was planning
        while broken and not started.empty():
            running.add(started.get())
        suspects = {t.case for t in broken} & running or {t.case for t in broken}
        if not solo and len(suspects) > 1:        # which of them killed its worker is not known: each tried alone
            alone = [t for t in broken if t.case in suspects]
            pending = [t for t in broken if t.case not in suspects]
            continue
        for task in broken:                       # the case being planned when a worker died is charged
            attempts[task.case] += task.case in suspects
        retry = [t for t in broken if attempts[t.case] < ATTEMPTS]
        alone, pending = (retry + alone[1:], pending) if solo else ([], retry)
        failed = [(t, _died(t)) for t in broken if attempts[t.case] >= ATTEMPTS]
        if failed:
            yield failed


def _started_and_planned(task: Task) -> dict:
    """`plan_case` in a local worker, once it has said it starts `task` (`_STARTED`)."""
    if _STARTED is not None:
        _STARTED.put(task.case)
    return plan_case(task)


def run_dask(tasks: list[Task], jobs: int, scheduler: str | None) -> Results:
    """Plan `tasks` on a Dask cluster: the scheduler at `scheduler`, or a local cluster of `jobs`
    single-threaded worker processes. The workers write the case folders: with a remote scheduler the
    output folder must be on storage they share."""
    from distributed import as_completed

    if not tasks:
        return
    with _cluster(scheduler, min(jobs, len(tasks))) as cluster, \
            dask_client(cluster if scheduler is None else scheduler) as client:
        futures = {client.submit(plan_in_child, t, pure=False, key=f"plan-{t.sha256[:12]}-{os.path.basename(t.case)}"): t
                   for t in tasks}
        for done in as_completed(futures).batches():
            yield [(futures[f], _dask_result(f, futures[f])) for f in done]


def _dask_result(future, task: Task) -> dict:
    from distributed.client import FutureCancelledError

    try:
        return future.result()
    except (FutureCancelledError, Exception) as exc:  # a worker lost (KilledWorker) or a task undeliverable
        return {"status": "failed", "seconds": 0.0,
                "error": f"{task.input}: the Dask task failed ({type(exc).__name__}: {exc})."}


def dask_client(cluster_or_address):
    """A Dask client of a local cluster or of the scheduler at an address; BadInputError if it cannot be reached."""
    from distributed import Client

    try:
        return Client(cluster_or_address, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise BadInputError(None, f"cannot reach the Dask scheduler at {cluster_or_address} ({exc})") from None


def require_scheduler(address: str) -> None:
    """BadInputError unless a Dask scheduler answers at `address`: nothing takes a connection there within
    REACH_SECONDS (refused, an unknown host), or what does (an HTTP server, a Dask worker) does not answer
    Dask's handshake and `identity` request as a scheduler within ANSWER_SECONDS."""
    import asyncio

    from distributed.comm import connect, parse_address
    from distributed.comm.registry import get_backend
    from distributed.core import send_recv
    from distributed.security import Security

    args = Security().get_connection_args("client")

    async def reach() -> None:
        scheme, where = parse_address(address)
        comm = await asyncio.wait_for(get_backend(scheme).get_connector().connect(where, **args), REACH_SECONDS)
        comm.abort()

    async def identity() -> object:
        comm = await connect(address, timeout=ANSWER_SECONDS, **args)
        try:
            return await send_recv(comm, op="identity")
        finally:
            comm.abort()

    try:
        asyncio.run(reach())
    except TimeoutError:
        raise BadInputError(None, f"cannot reach the Dask scheduler at {address} (no connection within "
                                  f"{REACH_SECONDS} s)") from None
    except Exception as exc:
        raise BadInputError(None, f"cannot reach the Dask scheduler at {address} ({_cause(exc)})") from None
    try:
        answer = asyncio.run(asyncio.wait_for(identity(), ANSWER_SECONDS))
    except TimeoutError:
        why = f"no answer within {ANSWER_SECONDS} s"
    except Exception:   # another protocol's bytes read as Dask's frames: MemoryError, ValueError, CommClosedError…
        why = "its answer is not in Dask's protocol"
    else:
        kind = answer.get("type") if isinstance(answer, dict) else None
        if kind == "Scheduler":
            return
        why = f"it answers as a Dask {kind}" if isinstance(kind, str) else "its answer is not a scheduler's"
    raise BadInputError(None, f"{address} does not answer as a Dask scheduler ({why})")


def _cause(exc: BaseException) -> str:
    """The first cause of a chain of exceptions, in words (`Connection refused`)."""
    while exc.__cause__ is not None or exc.__context__ is not None:
        exc = exc.__cause__ or exc.__context__
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


@contextlib.contextmanager
def _cluster(scheduler: str | None, jobs: int):
    """A quiet LocalCluster of `jobs` single-threaded worker processes (DASK_WORKER_CONFIG), unless a
    scheduler is given (None then). Its logs are silenced below CRITICAL: a worker whose heartbeat meets the
    scheduler closing at the batch's end logs a traceback at ERROR, and a batch reports its cases itself."""
    if scheduler is not None:
        yield None
        return
    import dask
    from distributed import LocalCluster

    one_thread_environment()                      # inherited by the worker processes
    with dask.config.set(DASK_WORKER_CONFIG), _deaf_to_ctrl_c():
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
    with cluster:
        yield cluster


@contextlib.contextmanager
def _deaf_to_ctrl_c():
    """Ctrl-C ignored while processes are started (they keep ignoring it: a terminal's Ctrl-C reaches every
    process of its group, and the batch, which stops them, says what became of the cases)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


_child: ProcessPoolExecutor | None = None
"""A Dask worker's own process for its cases (`plan_in_child`), started on its first case."""


def plan_in_child(task: Task) -> dict:
    """`plan_case` in a child process of this (Dask worker) process, kept for its next cases: there a case
    runs as in a local worker, away from the worker's event loop. A daemonic worker (a Nanny's, by default)
    may not start processes, and plans in its own thread instead."""
    global _child
    if multiprocessing.current_process().daemon:
        return plan_case(task)
    if _child is None:
        _child = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=_local_worker, initargs=(os.getpid(),))
    try:
        return _child.submit(plan_case, task).result()
    except BrokenProcessPool:
        _child = None
        return _died(task, 1)


def _died(task: Task, times: int = ATTEMPTS) -> dict:
    return {"status": "failed", "seconds": 0.0,
            "error": f"{task.input}: the worker process planning it died ({times}×; out of memory or killed)."}
