"""Where a sweep's blocks run: here (one worker), on local processes (every core, no Dask),
or on a Dask cluster (--scheduler). Each yields the blocks as they finish, in whatever
order (and None every CHECK_SECONDS while none does: the progress goes on); a block's rows
do not depend on where or when it ran (rows.py), so neither does the table.

A stop (Ctrl-C, SIGTERM: tools/signals.py) ends the work: blocks not yet started are
cancelled, and the local processes abandon the blocks under way at their next chunk of
samples (a `halt` event they share), so the sweep keeps exactly the blocks finished. Local
processes ignore the stop signals from their first instruction on (started while the sweep
ignores them: an ignored signal stays ignored through exec, and Python then installs no
KeyboardInterrupt): a Ctrl-C at the terminal, or `timeout`, signals the whole process
group, and the sweep, not each worker, decides what is kept.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

from ..signals import SIGNALS
from .rows import Task, run_task

CHECK_SECONDS = 0.2          # how often a wait looks at a stop request
SPAWN_WORTH = 10.0           # seconds of work left (one process) that pay for starting more
_halt = None                 # this worker process's halt event (set by the sweep's process)


class Halted(BaseException):
    """The sweep stopped: this block is abandoned (a BaseException, as KeyboardInterrupt
    is, so that no `except Exception` in the engine takes it for a sample's fault)."""


class WorkersLost(RuntimeError):
    """A local worker process died (killed, out of memory): the blocks it held are lost."""


def _start_worker(halt) -> None:
    global _halt
    _halt = halt


@contextmanager
def stops_ignored():
    """The stop signals ignored meanwhile (in the main thread: elsewhere there are no
    handlers to change), so that the processes started now inherit them ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {number: signal.signal(number, signal.SIG_IGN) for number in SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _halted() -> None:
    if _halt is not None and _halt.is_set():
        raise Halted


def run_in_worker(task: Task):
    return run_task(task, _halted)


def here(tasks, stop):
    """The blocks one after another in this process; a stop abandons the block under way
    (signals.py: the handler raises inside it)."""
    from ..signals import StepInterrupted

    for task in tasks:
        if stop.requested:
            return
        stop.within_step = True
        try:
            done = run_task(task)
        except StepInterrupted:
            return
        finally:
            stop.within_step = False
        yield done


def local(tasks, workers: int | None, stop, used: dict):
    """The blocks on `workers` local processes (None: as many as the machine has CPUs,
    where the work is worth it: the first block here, the rest on processes only where
    they would take longer here than a new process takes to start, SPAWN_WORTH seconds,
    and to compile what the first block compiled); 1: here. `used["processes"]`: how
    many run it."""
    import os

    if workers is not None:
        if workers > 1 and len(tasks) > 1:
            used["processes"] = min(workers, len(tasks))
            yield from processes(tasks, used["processes"], stop)
        else:
            yield from here(tasks, stop)
        return
    first = None
    for first in here(tasks[:1], stop):
        yield first
    cores = min(os.cpu_count() or 1, len(tasks) - 1)
    if first is None or cores < 2 or (first.seconds - first.compiling) * (
            len(tasks) - 1) <= SPAWN_WORTH + first.compiling:
        yield from here(tasks[1:], stop)
        return
    used["processes"] = cores
    yield from processes(tasks[1:], cores, stop)


def processes(tasks, workers: int, stop):
    """The blocks on `workers` local processes (spawned: each imports and compiles afresh,
    once, whatever the parent holds)."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from multiprocessing import get_context

    from concurrent.futures.process import BrokenProcessPool

    context = get_context("spawn")
    halt = context.Event()
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                             initargs=(halt,)) as pool:
        with stops_ignored():              # the submits start the processes
            waiting = {pool.submit(run_in_worker, task) for task in tasks}
        try:
            while waiting and not stop.requested:
                finished, waiting = wait(waiting, CHECK_SECONDS, FIRST_COMPLETED)
                for future in finished:
                    try:
                        yield future.result()
                    except BrokenProcessPool:
                        raise WorkersLost("a worker process died (killed, or out of "
                                          "memory?)") from None
                if not finished:
                    yield None
        finally:
            halt.set()
            for future in waiting:
                future.cancel()


def connect(scheduler: str):
    """A Dask client of the cluster at `scheduler`, or one line (UsageError) when Dask is
    not installed, nobody answers or it is no Dask scheduler: the fit's connection."""
    from ..fit.command import connected

    return connected(scheduler)


def cluster(tasks, client, stop):
    """The blocks on the Dask cluster of `client` (connect), which it closes."""
    from distributed import wait

    with client:
        waiting = set(client.map(run_task, tasks, pure=False))
        try:
            while waiting and not stop.requested:
                try:
                    finished, pending = wait(list(waiting), CHECK_SECONDS, "FIRST_COMPLETED")
                except TimeoutError:        # none finished yet: look at the stop again
                    yield None
                    continue
                waiting = set(pending)
                for future in finished:
                    yield future.result()
        finally:
            client.cancel(list(waiting))
