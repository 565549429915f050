"""The simulator's state and error books in the compiled loops' arrays, and back (runs.Kernel
holds them there between its calls; Settled writes them back before a simulator's books are
read).

    y   the state            z   the shadow's state     L   the shadow's local error
    O   motion - shadow      S   the state before one whose check is Python's
    I   steps, due, since, booked_taken, substeps, every, the controller's floor and cap,
        the cap, the most said, capped, states, order, known (a local error measured),
        followed (z is the shadow's), lost, the loss said, the books' fault said
    F   h, E(0), the retired inputs and losses, the largest |residual|, the shadow's
        largest distance, the energy in play, the error estimate, the controller's previous
        ratio, tolerance, SAFETY x target, target, Richardson's factor, the lowest energy,
        the order, the count below which steps are measured at the shadow (stiff_below)
"""
from __future__ import annotations

from ..trust.controller import SAFETY
from ..trust.unestimated import Off

NEVER = 2 ** 62           # the step index of a check that never comes (estimate off)


def pack(kernel, sim, books) -> None:
    """The simulator's state and `books` into the kernel's arrays (F[4], the largest
    |residual|, is the caller's)."""
    I, F, h = kernel.I, kernel.F, sim.step_size
    kernel.y[:] = sim.state
    if isinstance(books, Off):        # the steps alone: no check is ever due, no shadow
        n = books.substeps
        I[:] = (sim.steps, NEVER, sim.steps, 0, n, 1, n, n, n, n, 1, 4, 4, 0, 0, 0, 1,
                sim.books_fault is not None)
        F[:] = (h, sim.initial_energy, *sim.retired, 0.0, 0.0, sim.energy_in_play,
                books.error_estimate, 1.0, 0.0, 1.0, 1.0, 1.0, sim.lowest_energy, 4.0, 0.0)
        return
    shadow, n = books.shadow, books.states
    known = shadow.local is not None
    followed = known and not shadow.lost and sim.state is shadow.last
    if known:
        kernel.L[:n] = shadow.local
    if followed:
        kernel.z[:] = shadow.shadow
    kernel.O[:n] = shadow.offset or [0.0] * n
    I[:] = (sim.steps, books.due, books.since, books.booked_taken, books.substeps,
            books.every, books.free.floor, books.free.cap, books.cap, books.most,
            books.capped, n, books.order, known, followed, shadow.lost,
            books.said_lost or books.emit is None, sim.books_fault is not None)
    F[:] = (h, sim.initial_energy, *sim.retired, 0.0, shadow.largest, sim.energy_in_play,
            books.error_estimate, books.free.previous, books.tolerance,
            SAFETY * books.target(h), books.target(h), books.factor, sim.lowest_energy,
            float(books.order), books.stiff_below)


def unpack(kernel, sim, books, sound: int) -> None:
    """The arrays back into `books` and the simulator (whose state and step count the
    kernel keeps current); `sound`: the step of the latest state found sound."""
    I, F = kernel.I, kernel.F
    sim.energy_in_play = float(F[6])
    sim._sound = kernel.last if sound == sim.steps else tuple(kernel.S.tolist())
    if isinstance(books, Off):
        return
    shadow, n = books.shadow, books.states
    books.due, books.since, books.booked_taken = (int(v) for v in I[1:4])
    if int(I[4]) != books.substeps:
        books.use(int(I[4]))
    books.every = int(I[5])
    books.error_estimate, books.free.previous = float(F[7]), float(F[8])
    if I[13]:
        shadow.local = kernel.L[:n].tolist()
    if I[14]:
        shadow.shadow, shadow.offset = tuple(kernel.z.tolist()), kernel.O[:n].tolist()
        shadow.last = kernel.last
    shadow.largest, shadow.lost = float(F[5]), bool(I[15])


class Settled:
    """A simulator attribute the compiled kernel may hold ahead of Python's objects (between
    its calls the books stay in its arrays: compiled/runs.py): settled before it is read."""

    def __set_name__(self, owner, name):
        self.key = f"_settled{name}"

    def __get__(self, sim, owner=None):
        if sim is None:
            return self
        kernel = sim.__dict__.get("kernel")
        if kernel is not None and kernel.held is not None:
            kernel.settle(sim)
        try:
            return sim.__dict__[self.key]
        except KeyError:
            raise AttributeError(self.key) from None

    def __set__(self, sim, value):
        sim.__dict__[self.key] = value


def settle(sim, keep: bool = True) -> None:
    """What a compiled kernel holds back into the simulator's objects; `keep` False: forgotten
    (they were put back, or are reset)."""
    kernel = getattr(sim, "kernel", None)
    if kernel is not None:
        kernel.settle(sim) if keep else kernel.drop()


def acting(sim) -> None:
    """A control loop's torque acting (dynamics.command) made current where a compiled run
    holds it (K[0], K[1]); the rest stays in the arrays (nothing to pack again)."""
    kernel = getattr(sim, "kernel", None)
    if kernel is not None and kernel.held is not None:
        K = kernel.held[1]
        sim.dynamics.command[:] = [float(K[0]), float(K[1])]
