"""The sensors and the control loop inside the compiled run (run_books of a sensed scene's
module), as source text, and their state between Python's objects and the kernel's arrays.

Each step begins as Sensing.before begins it (sensing/attach.py): the sample due now
(Readings.catch_up: readings.py), the reading in force `delay` back, then the control
loop's sample (loop.Loop.before): the drive's law at the reading (the policy's torque, or
the servo's discrete law with its integrals stepped: effects/servo.py), queued to act
command_delay later, and the torque acting over the step. The same operations in the same
order as Python's, with numpy's draws (draws.py). Nothing is kept until the step is taken
(commit): a step handed back to Python finds the readings, the queue and the state as they
were, and Python takes it from there. A position whose count is not a finite number (Python's
round raises) is handed back too, as is a queue that outgrows its ring.

    RS  readings: a ring of samples (the step taken at, p1, p2, v1, v2)
    RI  its head, count, next index, latest sample's step, every, delay, has a previous,
        the ring's size, quantised, differenced, the seed, readings on
    RF  the previous sample's positions, period, step size, offsets, noise, resolution,
        velocity noise
    LS  the loop's queue: (the step it acts from, torque, from new inputs, shadow's torque)
    LI  its head, count, every, delay, the ring's size, a loop on, a servo's law
    DC  the drive: uses the command, compensates, believed gravity x (k1, k2), the inputs
        now (command, servo set-points) and as last sampled, their count, the servo's
        interfaces (0 position, 1 velocity, 2 effort), kp, ki, kd, tracking, integral and
        effort limits (inf: none), period, effort set-points (policy setpoint)
    DG  the draws' stream states (draws.normal), a row per (stream, joint)
"""
from __future__ import annotations

from collections import deque
from math import inf, isfinite

from ..effects.servo import Servo
from ..trust.unestimated import Off

INPUTS, STORED = 4, 12          # DC: the inputs now, and as the loop last sampled them
SERVO = 21                      # DC: where the servo's constants begin
INTERFACE = {"position": 0.0, "velocity": 1.0, "effort": 2.0}

SENSING = '''
@njit(cache=True, inline="always")
def wrap(k, size):
    """k mod size for 0 <= k < 2 size (a ring's head plus at most its count): no division."""
    return k - size if k >= size else k


@njit(cache=True, inline="always")
def gravity_believed(q1, q2, DC):
    """model.gravity_torque at (q1, q2), the believed gravity x coefficients in DC[2:4]."""
    g2 = DC[3] * cos(q1 + q2)
    return DC[2] * cos(q1) + g2, g2


@njit(cache=True, inline="always")
def policy_law(q1, q2, DC):
    """Actuator.law at the read (q1, q2): the command held, the believed gravity on top."""
    t1, t2 = (DC[4], DC[5]) if DC[0] != 0.0 else (0.0, 0.0)
    if DC[1] != 0.0:
        g1, g2 = gravity_believed(q1, q2, DC)
        t1, t2 = t1 + g1, t2 + g2
    return t1, t2


@njit(cache=True, inline="always")
def servo_joint(i, q, u, w, g, DC):
    """Servo.sample of joint i at the read q, q̇ with its integral w: (torque, new w)."""
    kind, limit = DC[21 + i], DC[31 + i]
    wc = w if limit == inf else smaller(bigger(w, -limit), limit)
    if kind == 0.0:
        e = DC[6 + i] - q
        r = DC[23 + i] * e + DC[27 + i] * (DC[8 + i] - u) + wc + g
    elif kind == 1.0:
        e = DC[8 + i] - u
        r = DC[23 + i] * e + wc + g
    else:
        e = 0.0
        r = (DC[10 + i] if DC[36] != 0.0 else DC[4 + i]) + g
    torque = smaller(bigger(r, -DC[33 + i]), DC[33 + i])
    if kind != 2.0 and DC[25 + i] > 0.0:
        back = DC[29 + i] * (torque - r + wc - w)
        w += DC[35] * (DC[25 + i] * e + back)
    return torque, w


@njit(cache=True, inline="always")
def position_read(q, j, index, RI, RF, DG):
    """SensorModel.positions of joint j: (False where round would raise, the position)."""
    x = q + RF[4 + j]
    if RF[6 + j] != 0.0:
        x += RF[6 + j] * normal(DG, j, RI[10], 0, j, index)
    if RI[8] == 1:
        v = x / RF[8 + j]
        if not isfinite(v):
            return False, x
        n = np.rint(v)
        x = (n if n != 0.0 else 0.0) * RF[8 + j]     # Python's round gives 0, never -0
    return True, x


@njit(cache=True, inline="always")
def take_sample(q1, q2, u1, u2, steps, RS, RI, RF, DG):
    """Readings._take at `steps` into the ring's slot after its samples: False where Python
    must take it."""
    if RI[1] >= RI[7]:
        return False
    index = RI[2]
    interval = RF[2] if steps - RI[3] == RI[4] else (steps - RI[3]) * RF[3]
    ok1, p1 = position_read(q1, 0, index, RI, RF, DG)
    ok2, p2 = position_read(q2, 1, index, RI, RF, DG)
    if not (ok1 and ok2):
        return False
    if RI[9] == 1:
        v1, v2 = 0.0, 0.0
        if RI[6] == 1:
            v1, v2 = (p1 - RF[0]) / interval, (p2 - RF[1]) / interval
    else:
        v1 = u1 + RF[10] * normal(DG, 2, RI[10], 1, 0, index) if RF[10] != 0.0 else u1
        v2 = u2 + RF[11] * normal(DG, 3, RI[10], 1, 1, index) if RF[11] != 0.0 else u2
    slot = wrap(RI[0] + RI[1], RI[7])
    RS[slot, 0], RS[slot, 1], RS[slot, 2], RS[slot, 3], RS[slot, 4] = steps, p1, p2, v1, v2
    return True


@njit(cache=True, inline="always")
def changed(DC):
    """The inputs (command, set-points) differ from those the loop last sampled."""
    for k in range(int(DC[20])):
        if DC[4 + k] != DC[12 + k]:
            return True
    return False


@njit(cache=True, inline="always")
def sense(q1, q2, u1, u2, w1, w2, steps, K, RS, RI, RF, LS, LI, DC, DG):
    """Sensing.before at `steps`, nothing kept: (False where Python must take the step; the
    torque acting over it; the servo's integrals; for commit: a sample taken, readings
    passed, a torque queued, queued torques passed)."""
    r1, r2, r3, r4 = q1, q2, u1, u2
    took, passed, queued, acted = 0, 0, 0, 0
    if RI[11] == 1:
        if steps - RI[3] >= RI[4]:
            if not take_sample(q1, q2, u1, u2, steps, RS, RI, RF, DG):
                return False, 0.0, 0.0, w1, w2, 0, 0, 0, 0
            took = 1
        head, count, size, due = RI[0], RI[1] + took, RI[7], steps - RI[5]
        while count - passed > 1 and RS[wrap(head + passed + 1, size), 0] <= due:
            passed += 1
        at = wrap(head + passed, size)
        r1, r2, r3, r4 = RS[at, 1], RS[at, 2], RS[at, 3], RS[at, 4]
    t1, t2 = K[0], K[1]
    if LI[5] == 1:
        head, count, size = LI[0], LI[1], LI[4]
        if steps % LI[2] == 0:
            if count >= size:
                return False, 0.0, 0.0, w1, w2, 0, 0, 0, 0
            if LI[6] == 1:
                g1, g2 = gravity_believed(r1, r2, DC) if DC[1] != 0.0 else (0.0, 0.0)
                s1, w1 = servo_joint(0, r1, r3, w1, g1, DC)
                s2, w2 = servo_joint(1, r2, r4, w2, g2, DC)
            else:
                s1, s2 = policy_law(r1, r2, DC)
            act, last = float(steps + LI[3]), LS[wrap(head + count - 1, size), 0]
            slot = wrap(head + count, size)
            LS[slot, 0] = last if last > act else act
            LS[slot, 1], LS[slot, 2], LS[slot, 4], LS[slot, 5] = s1, s2, s1, s2
            LS[slot, 3] = 1.0 if changed(DC) else 0.0
            queued, count = 1, count + 1
        while count - acted > 1 and LS[wrap(head + acted + 1, size), 0] <= steps:
            acted += 1
            if LS[wrap(head + acted, size), 3] != 0.0:
                break
        at = wrap(head + acted, size)
        t1, t2 = LS[at, 1], LS[at, 2]
    return True, t1, t2, w1, w2, took, passed, queued, acted


@njit(cache=True, inline="always")
def sample_kept(at_step, RS, RI, RF):
    """The sample take_sample wrote after the ring's samples, kept (taken at `at_step`)."""
    slot = wrap(RI[0] + RI[1], RI[7])
    RF[0], RF[1] = RS[slot, 1], RS[slot, 2]
    RI[1], RI[2], RI[3], RI[6] = RI[1] + 1, RI[2] + 1, at_step, 1


@njit(cache=True, inline="always")
def commit(at_step, took, passed, queued, acted, RS, RI, RF, LS, LI, DC):
    """What sense found, kept: the step it began has been taken."""
    if took == 1:
        sample_kept(at_step, RS, RI, RF)
    if RI[11] == 1:
        RI[0], RI[1] = wrap(RI[0] + passed, RI[7]), RI[1] - passed
    if queued == 1:
        LI[1] += 1
        for k in range(8):
            DC[12 + k] = DC[4 + k]
    if LI[5] == 1:
        LI[0], LI[1] = wrap(LI[0] + acted, LI[4]), LI[1] - acted


@njit(cache=True)
def read_now(q1, q2, u1, u2, steps, RS, RI, RF, DG, out):
    """Readings.catch_up at `steps` in the arrays (the sample due taken and kept, the
    readings passed dropped), the reading now into `out`: False (nothing kept) where Python
    must take the sample."""
    if steps - RI[3] >= RI[4]:
        if not take_sample(q1, q2, u1, u2, steps, RS, RI, RF, DG):
            return False
        sample_kept(steps, RS, RI, RF)
    head, count, size, due = RI[0], RI[1], RI[7], steps - RI[5]
    passed = 0
    while count - passed > 1 and RS[wrap(head + passed + 1, size), 0] <= due:
        passed += 1
    at = wrap(head + passed, size)
    RI[0], RI[1] = at, count - passed
    out[0], out[1], out[2], out[3] = RS[at, 1], RS[at, 2], RS[at, 3], RS[at, 4]
    return True
'''

MORE = ", RS, RI, RF, LS, LI, DC, DG"


def parts(extra, width: int) -> dict:
    """run_books' SENSE, COMMIT and RESTORE (kernels.run_loop) for a state of `width` whose
    extra states are `extra` (a servo's integrals among them: stepped by its law)."""
    integrals = "integral1" in extra
    w = ("state[4], state[5]" if integrals else "0.0, 0.0")
    sense = f'''        unsensed, a0, a1 = state, K[0], K[1]
        took, passed, queued, acted = 0, 0, 0, 0
        if LI[5] == 1 or (RI[11] == 1 and (steps - RI[3] >= RI[4] or (
                RI[1] > 1 and RS[wrap(RI[0] + 1, RI[7]), 0] <= steps - RI[5]))):
            ok, t1, t2, w1, w2, took, passed, queued, acted = sense(
                state[0], state[1], state[2], state[3], {w}, steps, K, RS, RI, RF, LS, LI, DC,
                DG)
            if not ok:
                code = 1
                break
            K[0], K[1] = t1, t2'''
    if integrals:     # (a servo's law only under a loop, which senses every step)
        sense += "\n            state = (state[0], state[1], state[2], state[3], w1, w2" + "".join(
            f", state[{k}]" for k in range(6, width)) + ")"
    return dict(MORE=MORE, SENSE=sense, COMMIT='''        commit(steps - 1, took, passed, queued, acted, RS, RI, RF, LS, LI, DC)''',
                RESTORE='''    if code == 1:                             # as it was: Python takes the step
        state = unsensed
        K[0], K[1] = a0, a1''')


class Sensed:
    """A simulator's readings and control loop (sim.sensing) in the arrays above while a
    compiled run holds them: packed when the run starts (Kernel.hold), unpacked into the
    Python objects when it settles (they are read from the simulator each time: a copy of
    its attributes, tools/run/whole_steps.py, may have replaced them)."""

    def __deepcopy__(self, memo):   # scratch: nothing a step leaves behind
        return self

    def __init__(self, sensing, module=None):
        import numpy as np
        self.np = np
        self.RS, self.LS = np.zeros((1, 5)), np.zeros((1, 6))
        self.RI, self.LI = np.zeros(12, dtype=np.int64), np.zeros(8, dtype=np.int64)
        self.RF, self.DC = np.zeros(12), np.zeros(37)
        self.DG = np.zeros((4, 10), dtype=np.uint64)
        self.DG[:, 0] = np.iinfo(np.uint64).max        # no block yet
        self.looped = sensing.loop is not None
        self.law = drive_constants(sensing.loop, self.DC) if self.looped else True
        self.module, self.out = module, np.zeros(4)
        if sensing.readings is not None and module is not None:   # Python's samples too
            model = sensing.readings.model
            model.draws = CompiledDraws(module.normal, model.draws.seed, self.DG)

    @property
    def more(self) -> tuple:
        return self.RS, self.RI, self.RF, self.LS, self.LI, self.DC, self.DG

    def refresh(self, sensing) -> None:
        """The loop's inputs now (the command given, the servo's set-points) into DC: a
        command given between compiled calls."""
        if sensing.loop is not None:
            given = inputs(sensing.loop)
            self.DC[INPUTS:INPUTS + len(given)] = given

    def ready(self, sensing, books) -> bool:
        """Whether a compiled run can take the next steps: the readings begun; a loop only
        without the error estimate (its shadow runs a controller of its own, in Python),
        started, its drive's law known here, its inputs finite."""
        readings, loop = sensing.readings, sensing.loop
        if readings is not None and not readings.samples:
            return False
        return loop is None or (isinstance(books, Off) and loop.line is not None and
                                self.law and all(isfinite(v) for v in inputs(loop)))

    def read(self, sim):
        """The reading now (Sensing.reading) while a run holds the readings here, taken in
        the arrays: nothing to unpack and pack again around a read between steps; None
        where Python must take it (after settling)."""
        if self.RI[11] == 0:
            return tuple(sim.state[:4])
        y, out = sim.state, self.out
        if not self.module.read_now(y[0], y[1], y[2], y[3], sim.steps, self.RS, self.RI,
                                    self.RF, self.DG, out):
            return None
        return tuple(out.tolist())

    def pack(self, sensing, K) -> None:
        """The readings, the loop's queue and what acts now into the arrays (and K)."""
        np, readings, loop = self.np, sensing.readings, sensing.loop
        self.RI[11], self.RI[7] = readings is not None, 1
        if readings is not None:
            model, samples = readings.model, list(readings.samples)
            size = max(len(samples) + 2, model.delay // model.every + 3)
            if self.RS.shape[0] != size:
                self.RS = np.zeros((size, 5))
            for k, (step, values) in enumerate(samples):
                self.RS[k] = (step, *values)
            self.RI[:] = (0, len(samples), readings.index, readings.last, model.every,
                          model.delay, readings.previous is not None, size,
                          model.resolution is not None, model.velocity == "differences",
                          model.draws.seed, 1)
            self.RF[:] = (*(readings.previous or (0.0, 0.0)), model.period, model.step_size,
                          *model.offset, *model.noise, *(model.resolution or (1.0, 1.0)),
                          *model.velocity_noise)
        self.LI[5], self.LI[4] = loop is not None, 1
        if loop is not None:
            line = list(loop.line)
            size = max(len(line) + 2, loop.delay // loop.every + 3)
            if self.LS.shape[0] != size:
                self.LS = np.zeros((size, 6))
            for k, (act, torque, new, shadow) in enumerate(line):
                self.LS[k] = (act, *torque, new, *shadow)
            self.LI[:] = (0, len(line), loop.every, loop.delay, size, 1,
                          loop.servo is not None, 0)
            self.DC[STORED:STORED + len(loop.inputs)] = loop.inputs
            self.refresh(sensing)
            K[0], K[1] = loop.acting

    def unpack(self, sensing, K) -> None:
        """The arrays back into the readings and the loop."""
        readings, loop, RI, LI = sensing.readings, sensing.loop, self.RI, self.LI
        if readings is not None:
            RS, size = self.RS.tolist(), int(RI[7])
            readings.samples = deque((int(RS[k % size][0]), tuple(RS[k % size][1:]))
                                     for k in range(int(RI[0]), int(RI[0] + RI[1])))
            readings.index, readings.last = int(RI[2]), int(RI[3])
            readings.previous = self.RF[0:2].tolist() if RI[6] else None
            sensing.index = readings.index
        if loop is not None:
            LS, size = self.LS.tolist(), int(LI[4])
            loop.line = deque((int(LS[k % size][0]), tuple(LS[k % size][1:3]),
                               bool(LS[k % size][3]), tuple(LS[k % size][4:6]))
                              for k in range(int(LI[0]), int(LI[0] + LI[1])))
            loop.inputs = tuple(self.DC[STORED:STORED + len(inputs(loop))].tolist())
            loop.acting[:] = [float(K[0]), float(K[1])]
            loop.shadow_acting[:] = loop.line[0][3]


def inputs(loop) -> list:
    """A loop's inputs now: the command given, the servo's set-points (loop.Loop._inputs)."""
    return [*loop.given, *(loop.servo.setpoint if loop.servo is not None else ())]


class CompiledDraws:
    """noise.Draws on the compiled path: the same draws (draws.py) from the compiled normal,
    the streams' states shared with the compiled run (DG), so that a sample Python takes
    (sample 0 at reset, a step handed back) costs no block of numpy's."""

    def __init__(self, normal, seed: int, DG):
        self.compiled, self.seed, self.DG = normal, seed, DG

    def __deepcopy__(self, memo):   # a copy draws the same numbers (its states: a cache)
        return CompiledDraws(self.compiled, self.seed, self.DG.copy())

    def normal(self, stream: int, joint: int, index: int) -> float:
        return float(self.compiled(self.DG, 2 * stream + joint, self.seed, stream, joint,
                                   index))


def drive_constants(loop, DC) -> bool:
    """The loop's drive into DC; False where its law is not one the compiled run knows (a
    fixed torque: no loop drives one)."""
    drive = loop.drive
    compensation = getattr(drive, "compensation", None)
    if drive.compensates:        # model.gravity_torque of the believed arm (a partial)
        arm, gravity = compensation.args[0], compensation.keywords["gravity"]
        k1, k2 = arm.gravity_coefficients
        DC[1:4] = (1.0, gravity * k1, gravity * k2)
    DC[20] = 8 if loop.servo is not None else 2
    if not isinstance(drive, Servo):
        DC[0] = drive.policy.startswith("command")
        return drive.fixed is None
    limits = (drive.integral_limit or (inf, inf), drive.effort_limits or (inf, inf))
    DC[SERVO:] = (*(INTERFACE[kind] for kind in drive.interface), *drive.kp, *drive.ki,
                  *drive.kd, *drive.tracking, *limits[0], *limits[1], drive.period,
                  drive.policy == "setpoint")
    return True
