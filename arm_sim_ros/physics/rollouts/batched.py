"""Samples of one scene structure stepped together: their simulators' kernel arrays stacked
row by row and advanced by one compiled call (compiled/batched.py: run_many), rows on
numba's threads.

Each sample is its own Simulator, built as Simulator.run's would be, its books packed into
its kernel's arrays as Kernel.run packs them (Kernel.hold); a row is then stepped by the
same compiled run_books its Kernel.run calls. A row the compiled run hands back (a fault,
a divergence, anything Python must say) leaves the stack: its arrays go back to its kernel,
which finishes the step as Kernel.run does (Kernel.after), and the sample runs on alone.
So every number is its own Simulator.run's, whatever the thread count.
"""
from __future__ import annotations

import numpy as np

from ..compiled import build
from .alone import ROW, Built, advance, hand_out

KERNEL_ARRAYS = ("y", "z", "L", "O", "G", "S", "I", "F")


def batchable(run: Built) -> bool:
    """Whether the sample's next steps are its kernel's run_books (a smooth scene's compiled
    run; not a switching one's, whose modes are the sample's own)."""
    kernel = run.sim.kernel
    return (kernel is not None and kernel.hold(run.sim)
            and kernel.held[0] is kernel.module.run_books)


def structure(run: Built) -> tuple:
    """What samples stepped together share: the compiled module, the steps, the step size."""
    return id(run.sim.kernel.module), run.steps, run.sim.step_size


class Stack:
    """The kernel arrays of some samples, a row each, for run_many."""

    def __init__(self, runs: list[Built]):
        self.runs = runs
        kernels = [run.sim.kernel for run in runs]
        for run, kernel in zip(runs, kernels):
            kernel.given(run.sim, kernel.held[1])
        self.arrays = [np.stack([getattr(k, name) for k in kernels]) for name in KERNEL_ARRAYS]
        self.K = np.stack([k.held[1] for k in kernels])
        self.C = np.stack([k.C for k in kernels])
        self.more = [padded(arrays) for arrays in zip(*(k.held[2] for k in kernels))]
        self.R = np.zeros((len(runs), 3), dtype=np.int64)
        self.F = self.arrays[KERNEL_ARRAYS.index("F")]
        for run, largest in zip(runs, self.F):
            largest[4] = run.largest

    def step(self, left: int, rows) -> None:
        """Every row `left` steps (rows: (n, left, ROW) or (n, 0, ROW))."""
        module = self.runs[0].sim.kernel.module
        module.run_many(*self.arrays, self.K, self.C, left, rows, self.R, *self.more)

    def back(self, a: int) -> None:
        """Row a's arrays back into its kernel."""
        kernel = self.runs[a].sim.kernel
        for name, stacked in zip(KERNEL_ARRAYS, self.arrays):
            getattr(kernel, name)[:] = stacked[a]
        kernel.held[1][:] = self.K[a]
        for own, stacked in zip(kernel.held[2], self.more):
            own[:] = stacked[a][:len(own)]
        kernel.sound = int(self.R[a, 2])
        self.runs[a].largest = float(self.F[a, 4])

    def handed_back(self, left: int, rows) -> list[int]:
        """The rows a call of `left` steps handed back, each finished as its Kernel.run
        would go on (Kernel.after, its trajectory's rows into `rows`): their arrays are then
        their kernels' own, and they run on alone."""
        back = [k for k in range(len(self.runs))
                if (self.R[k, 1], self.R[k, 0]) != (0, left)]
        for k in back:
            run = self.runs[k]
            self.back(k)
            run.sim.kernel.T = rows[k]
            try:
                run.done, run.largest = run.sim.kernel.after(
                    run.sim, left, int(self.R[k, 0]), int(self.R[k, 1]), float(self.F[k, 4]))
            except Exception as raised:     # noqa: BLE001 (a sample's fault is its outcome)
                run.error, run.done = raised, left
            finally:
                run.sim.kernel.T = rows[k, :0]
        return back

    def settled(self) -> None:
        """Every row's arrays back into its kernel and its simulator's state and books
        current, as after its Kernel.run."""
        for k, run in enumerate(self.runs):
            self.back(k)
            _, run.largest = run.sim.kernel.after(run.sim, 1, 1, 0, float(self.F[k, 4]))


def padded(arrays) -> np.ndarray:
    """Arrays stacked, the shorter (a smaller ring of samples) padded with zeros."""
    rows = max(len(a) for a in arrays)
    out = np.zeros((len(arrays), rows, *arrays[0].shape[1:]), dtype=arrays[0].dtype)
    for i, a in enumerate(arrays):
        out[i, :len(a)] = a
    return out


def run_together(runs: list[Built], observe, chunk: int, threads: int) -> None:
    """Samples of one structure (structure()) for their steps, in compiled calls of up to
    `chunk` steps, each chunk's rows handed to `observe`; each sample's outcome is then its
    simulator's (Built.outcome)."""
    numba = build.numba
    cores = numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(cores if threads <= 0 else min(threads, cores))
    steps, step_size, indices = runs[0].steps, runs[0].sim.step_size, [r.index for r in runs]
    stack, alone, done = Stack(runs), [], 0
    start = None if observe is None else np.array([run.start for run in runs])[:, None]
    for left in chunks(steps, chunk):
        rows = np.zeros((len(runs), left if observe is not None else 0, ROW))
        before = list(alone)
        if stack is not None:
            at = [runs.index(run) for run in stack.runs]
            mine = rows if len(at) == len(runs) else np.zeros((len(at), *rows.shape[1:]))
            stack.step(left, mine)
            back = stack.handed_back(left, mine)
            rows[at] = mine
            for k in back:
                go_on(stack.runs[k], left, rows[at[k]], stack.runs[k].done, done)
            alone += [stack.runs[k] for k in back]
            stack = restacked(stack, back)
        for run in before:
            go_on(run, left, rows[runs.index(run)], 0, done)
        done += left
        if observe is not None:
            hand_out(observe, indices, done, step_size,
                     rows if start is None else np.concatenate([start, rows], axis=1))
            start = None
    if start is not None:                 # no steps: the row at t = 0 alone
        hand_out(observe, indices, 0, step_size, start)
    if stack is not None and steps:
        stack.settled()


def chunks(steps: int, chunk: int) -> list[int]:
    return [min(chunk, steps - done) for done in range(0, steps, chunk)]


def go_on(run: Built, left: int, rows, taken: int, done: int) -> None:
    """A sample handed back takes the call's `left` steps alone from `taken` (rows: its
    trajectory's rows of the call; NaN from a step that raised on, as after it)."""
    if run.error is None:
        try:
            run.largest = advance(run.sim, left - taken, run.largest,
                                  rows[taken:] if len(rows) else None)
        except Exception as raised:     # noqa: BLE001 (a sample's fault is its outcome)
            run.error = raised
    if run.error is not None and len(rows):
        rows[max(0, run.sim.steps - done):] = np.nan


def restacked(stack: Stack, back: list[int]):
    """The stack without the rows handed back (their kernels keep their own arrays)."""
    if not back:
        return stack
    kept = [k for k in range(len(stack.runs)) if k not in back]
    for k in kept:
        stack.back(k)
    return Stack([stack.runs[k] for k in kept]) if kept else None
