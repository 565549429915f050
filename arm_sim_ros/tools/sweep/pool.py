"""Where a sweep's blocks run: here (one worker), on local processes (every core, no Dask),
or on a Dask cluster (--scheduler). Each yields the blocks as they finish, in whatever
order (and None every CHECK_SECONDS while none does: the progress goes on); a block's rows
do not depend on where or when it ran (rows.py), so neither does the table.

A stop (Ctrl-C, SIGTERM: tools/signals.py) ends the work: blocks not yet started are
cancelled, and the local processes abandon the blocks under way at their next chunk of
samples (a `halt` event they share), so the sweep keeps exactly the blocks finished. Local
processes ignore SIGINT: a Ctrl-C at the terminal reaches the whole process group, and the
sweep, not each worker, decides what is kept.
"""
from __future__ import annotations

import signal

from .rows import Task, run_task

CHECK_SECONDS = 0.2          # how often a wait looks at a stop request
SPAWN_WORTH = 10.0           # seconds of work left (one process) that pay for starting more
_halt = None                 # this worker process's halt event (set by the sweep's process)


class Halted(BaseException):
    """The sweep stopped: this block is abandoned (a BaseException, as KeyboardInterrupt
    is, so that no `except Exception` in the engine takes it for a sample's fault)."""


def _start_worker(halt) -> None:
    global _halt
    _halt = halt
    signal.signal(signal.SIGINT, signal.SIG_IGN)


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


def every_core(tasks, workers: int, stop, used: dict):
    """The first block here; the rest on `workers` local processes where they would take
    more than SPAWN_WORTH seconds here (each new process imports and loads its kernels
    first: a small sweep is done sooner without). `used["processes"]`: how many run it."""
    first = None
    for first in here(tasks[:1], stop):
        yield first
    if first is None or len(tasks) == 1:
        return
    left = (first.seconds - first.compiling) * (len(tasks) - 1)
    if left <= SPAWN_WORTH or len(tasks) == 2:
        yield from here(tasks[1:], stop)
        return
    used["processes"] = min(workers, len(tasks) - 1)
    yield from processes(tasks[1:], used["processes"], stop)


def processes(tasks, workers: int, stop):
    """The blocks on `workers` local processes (spawned: each imports and compiles afresh,
    once, whatever the parent holds)."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from multiprocessing import get_context

    context = get_context("spawn")
    halt = context.Event()
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_start_worker,
                             initargs=(halt,)) as pool:
        waiting = {pool.submit(run_in_worker, task) for task in tasks}
        try:
            while waiting and not stop.requested:
                finished, waiting = wait(waiting, CHECK_SECONDS, FIRST_COMPLETED)
                for future in finished:
                    yield future.result()
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
