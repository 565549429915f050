"""A batch of recorded steps as numpy arrays: every readout of the scene's effects and the
arm's drawing, for all rows at once. No rerun here.

`Snapshot(sim)` is what a batch is read with: the simulator's layout when its rows were
taken (extra states, channels and their kinds, the effects that store energy, the joint
torque's code, E(0) split into its parts), so rows queued before a payload is grasped or
a reset still read as they were taken. `channel_values` names each readout by its entity
path (the names below; blueprint.py gives them series names, colours and places):

    energy/total, energy/balance_residual   E (kinetic and every stored energy) and residual, J
    books/stored/<part>      change since t = 0 of kinetic and each effect's stored energy
    books/<kind>/<channel>   every channel of the scene by name (kind: input, loss, transfer)
    joints/angle, joints/velocity, joints/torque (with a drive), joints/current (windings)
    joints/commanded_torque  the command held at each step (command policies)
    joints/angle_measured, joints/velocity_measured   with sensors: as read (after the state)

A row is the simulator's state, then with sensors the readings, then under a control loop
the torque that acted over the step (physics/simulator.recorded_row), which the joint torque
is evaluated with, as a command policy's with its command.

With books/stored/* + inputs - losses the residual closes: Σ stored changes - Σ inputs +
Σ losses = energy/balance_residual (transfer channels, e.g. the motors' work on the joints
with windings, move energy inside the books and are not counted).
"""
from __future__ import annotations

from types import FunctionType

import numpy as np

from ..physics import model
from ..physics.effects import Effect
from ..physics.stepping.integrators import INTEGRATORS
from ..physics.trust.unestimated import NO_ESTIMATE

# Each effect's stored energy as a part of E: the part's name in the books.
STORED_PARTS = {"gravity": "gravity", "springs": "springs", "motors": "windings"}
KINDS = ("input", "loss", "transfer")
CURRENTS = ("i1", "i2")           # the windings' extra states (A)
COMMANDED = "joints/commanded_torque"
MEASURED = {"joints/angle": "joints/angle_measured",        # with sensors: the readings
            "joints/velocity": "joints/velocity_measured"}  # beside the truth
# How far each step is from the exact flow (physics/trust/accuracy.py), and what it cost.
LOCAL_ERROR = "accuracy/local_error"            # the step's estimate, max over q, q̇
ACCUMULATED_ERROR = "accuracy/accumulated_error"  # their sum since reset
SUBSTEPS = "accuracy/substeps"                  # sub-steps the step was taken as


def stores_energy(effect) -> bool:
    """Whether an effect keeps energy of its own in E: gravity, springs, the windings'
    inductance. Motors without windings store none apart from T (the rotors are in M)."""
    return (type(effect).stored_energy is not Effect.stored_energy
            and getattr(effect, "windings", True))


def held_by(scene) -> str:
    """What holds a scene's local error: its tolerance (a scaled error per simulated
    second), or for an embedded pair (dopri5) its rtol and atol; nothing where the scene's
    estimate is off."""
    if scene.estimate == "off":
        return f"estimate off: {NO_ESTIMATE}"
    if INTEGRATORS[scene.method].adaptive:
        return f"rtol {scene.rtol:g}, atol {scene.atol:g} ({scene.method})"
    return (f"tolerance {scene.tolerance:g} per s (scaled: max |e_q|, |e_qd|/(1+|qd|))"
            if scene.tolerance else "tolerance 0 (estimate only)")


def channel_path(name: str, kind: str) -> str:
    return f"books/{kind}/{name}"


def stored_path(part: str) -> str:
    return f"books/stored/{part}"


def extra_paths(extra) -> dict:
    """{entity path: names of the extra states it holds}: the winding currents together."""
    if tuple(extra) == CURRENTS:
        return {"joints/current": CURRENTS}
    return {f"state/{name}": (name,) for name in extra}


class Snapshot:
    """How the rows of one simulator read (see the module's docstring). `initial`: E(0)'s
    parts {kinetic, part: J} to keep (a payload grasped mid-run keeps the run's E(0));
    default: those of the scene's initial state."""

    def __init__(self, sim, initial: dict | None = None):
        dynamics = sim.dynamics
        self.scene, self.arm, self.step_size = sim.scene, sim.arm, sim.step_size
        self.extra, self.channels = tuple(sim.extra), tuple(sim.channels)
        self.kinds = dict(zip(self.channels, dynamics.channel_kinds))
        self.first = 4 + len(self.extra)
        self.effects = dynamics.active
        self.stores = tuple((STORED_PARTS.get(e.name, e.name), e, self._extra_of(e))
                            for e in dynamics.active if stores_energy(e))
        self.drives = any(e.drives for e in dynamics.active)
        self.commanded = sim.scene.policy.startswith("command")
        self.measured = sim.scene.sensors is not None   # rows hold the readings (sensing/)
        self.looped = dynamics.command is not dynamics.given   # ... and the acting torque
        self.arm3d = None         # the recorder's 3D arm (arm3d.Arm3D), when the URDF is this arm
        self.initial_energy = sim.initial_energy
        # (inputs, losses) booked by channels a live change removed (damping set to 0 ...)
        self.retired = tuple(sim.retired)
        self.estimates = sim.error_estimate == sim.error_estimate   # NaN: not estimated
        # What the whole recording holds (carry_on: a live switch of `estimate`): the modes
        # in the order they ran, and whether any of its rows carry estimates.
        self.modes, self.estimated = (sim.scene.estimate,), self.estimates
        self.held_by = held_by(sim.scene)
        # An embedded pair (dopri5) adapts its own step: it has no sub-steps to count.
        self.adaptive = INTEGRATORS[sim.scene.method].adaptive
        self._torque = vectorised(dynamics.torque_function) if self.drives else None
        if initial is None:
            scene = sim.scene
            row = np.array([[*scene.initial_positions, *scene.initial_velocities]
                            + [0.0] * (len(self.extra) + len(self.channels))])
            with np.errstate(all="ignore"):     # an absurd start's E is inf, as in the core
                kinetic, stored = energies(self, row)
            initial = {"kinetic": float(kinetic[0])} | {p: float(v[0]) for p, v in stored.items()}
        self.initial = {part: initial.get(part, 0.0) for part in self.parts}

    def _extra_of(self, effect) -> slice:
        """The state columns of the effect's extra states (none: an empty slice)."""
        start = 4 + (self.extra.index(effect.state[0]) if effect.state else 0)
        return slice(start, start + len(effect.state))

    @property
    def parts(self) -> tuple[str, ...]:
        """The parts of E: kinetic, then each effect's stored energy in assembly order."""
        return ("kinetic",) + tuple(part for part, _, _ in self.stores)

    @property
    def key(self) -> tuple:
        """What the blueprint and the series' styles depend on."""
        return (self.arm, self.parts, tuple(self.kinds.items()), self.extra, self.drives,
                self.commanded, self.estimates, self.held_by, self.initial_energy, self.measured,
                self.looped, self.modes, self.estimated)

    def carry_on(self, before: Snapshot | None) -> Snapshot:
        """This setup's snapshot in a recording whose earlier rows `before` read: the error
        estimate's modes and rows it held so far are the recording's still (a node switched
        from global to off holds the estimates made until then)."""
        if before is not None:
            mode = self.modes[-1]
            self.modes = before.modes + ((mode,) if before.modes[-1] != mode else ())
            self.estimated = before.estimated or self.estimates
        if len(self.modes) > 1:           # what held the error: each mode in its turn
            self.held_by = f"estimate {', then '.join(self.modes)}: the events say when"
        return self

    def joint_torque(self, states, commands):
        """(n, 2) torque the joints receive, as sim.dynamics.joint_torque gives it row by
        row (`commands`: the command held at each row, for the command policies)."""
        if commands is not None:
            self._torque.__globals__["command"] = (commands[:, 0], commands[:, 1])
        t1, t2 = self._torque(*states[:, :self.first].T)
        return np.column_stack(np.broadcast_arrays(t1, t2, states[:, 0])[:2])


def reads_alike(old: Snapshot, new: Snapshot) -> bool:
    """Whether rows read the same under `new` as under `old` (a live change of damping or
    friction values: the energies, books and joint torque a row shows do not depend on
    them), so that rows before and after the change can go in one batch."""
    if old.key != new.key or old.retired != new.retired or old.drives != new.drives:
        return False
    if not old.drives:
        return True
    a, b = old._torque, new._torque          # the drive chain's code and its constants
    if a.__code__.co_code != b.__code__.co_code or a.__code__.co_consts != b.__code__.co_consts:
        return False
    try:
        return all(bool(np.all(a.__globals__.get(n) == b.__globals__.get(n)))
                   for n in a.__code__.co_names if n != "command")
    except (TypeError, ValueError):
        return False


def vectorised(function):
    """A generated function of physics/dynamics.py run on arrays: the same code with
    numpy's cos, sin, minimum and maximum, as physics/batch.py runs the right-hand side."""
    names = dict(function.__globals__, cos=np.cos, sin=np.sin, MIN=np.minimum, MAX=np.maximum)
    return FunctionType(function.__code__, names, function.__name__)


_potential_energy = vectorised(model.potential_energy)


def energies(snap: Snapshot, states):
    """Kinetic energy (links and rotors) and {part: stored energy} of each effect that
    stores some, for (n, width) states: Simulator.energies term for term in numpy (the
    scalar calls cost more than the RK4 step itself; see benchmarks/bench_telemetry.py)."""
    q2, u1, u2 = states[:, 1], states[:, 2], states[:, 3]
    a, b, d, m22 = snap.arm.mass_constants
    c2 = np.cos(q2)
    m11 = a + 2.0 * b * c2
    m12 = d + b * c2
    kinetic = 0.5 * (m11 * u1 * u1 + 2.0 * m12 * u1 * u2 + m22 * u2 * u2)
    return kinetic, {part: _stored(snap, effect, states, at) for part, effect, at in snap.stores}


def _stored(snap: Snapshot, effect, states, at):
    """An effect's stored energy for every row: its own stored_energy on arrays (springs,
    windings, joint limits are plain arithmetic); gravity's calls math.sin, so it runs as
    model.potential_energy on numpy's."""
    q = states[:, 0], states[:, 1]
    if effect.name == "gravity":
        value = _potential_energy(snap.arm, q, effect.gravity)
    else:
        value = effect.stored_energy(snap.arm, q, tuple(states[:, at].T))
    return np.broadcast_to(np.asarray(value, dtype=float), q[0].shape)


def channel_values(snap: Snapshot, states, commands) -> dict:
    """{entity path: (n,) or (n, k) values} of every readout of (n, width) states (q1, q2,
    q̇1, q̇2, the extra states, the channels), named as the module's docstring says."""
    kinetic, stored = energies(snap, states)
    potential = sum(stored.values()) if stored else np.zeros_like(kinetic)
    end = states.shape[1] - 2 * snap.looped        # under a control loop: its torque last
    if snap.looped:
        commands = states[:, end:]
    total = kinetic + potential
    books = {name: states[:, snap.first + i] for i, name in enumerate(snap.channels)}
    inputs, losses = snap.retired
    for name, kind in snap.kinds.items():
        if kind == "input":
            inputs = inputs + books[name]
        elif kind == "loss":
            losses = losses + books[name]
    values = {"energy/total": total,
              "energy/balance_residual": total - snap.initial_energy - inputs + losses,
              stored_path("kinetic"): kinetic - snap.initial["kinetic"]}
    for part, value in stored.items():
        values[stored_path(part)] = value - snap.initial[part]
    for name, kind in snap.kinds.items():
        values[channel_path(name, kind)] = books[name]
    values["joints/angle"], values["joints/velocity"] = states[:, 0:2], states[:, 2:4]
    if snap.measured:
        values[MEASURED["joints/angle"]] = states[:, end - 4:end - 2]
        values[MEASURED["joints/velocity"]] = states[:, end - 2:end]
    if snap.drives:
        values["joints/torque"] = snap.joint_torque(states, commands)
    if snap.commanded:
        values[COMMANDED] = (commands if commands is not None
                             else np.zeros((len(states), 2)))
    for path, names in extra_paths(snap.extra).items():
        at = [4 + snap.extra.index(name) for name in names]
        values[path] = states[:, at] if len(at) > 1 else states[:, at[0]]
    return values


FLOAT32_MAX = float(np.finfo(np.float32).max)    # the viewer draws in float32


def reach(arm) -> float:
    """Half the width of the arm's view: a little more than the arm at full stretch, at most
    what the viewer's float32 holds."""
    return min(1.1 * sum(arm.link_lengths), FLOAT32_MAX)


def drawn(arm) -> bool:
    """Whether the viewer's float32 holds the arm's drawing (an arm of 1e154 m it does not:
    its drawing is left out, its numbers recorded all the same)."""
    return 1.1 * sum(arm.link_lengths) < FLOAT32_MAX


def drawing_points(arm, q1, q2):
    """Elbow and tip of many configurations, in the physics' coordinates (y up); the view
    flips them for the viewer's 2D y axis, which points down (blueprint.FLIP)."""
    l1, l2 = arm.link_lengths
    elbow = np.column_stack((l1 * np.cos(q1), l1 * np.sin(q1)))
    tip = elbow + np.column_stack((l2 * np.cos(q1 + q2), l2 * np.sin(q1 + q2)))
    return elbow, tip


def unpack(runs, states, n):
    """Runs of [first step, command, steps] (n steps in all) and their flattened states as
    arrays: step numbers (n,), states (n, width), commands (n, 2) or None."""
    states = np.frombuffer(states, float).reshape(n, -1)
    lengths = np.array([count for _, _, count in runs])
    firsts = np.array([first for first, _, _ in runs]) - (np.cumsum(lengths) - lengths)
    steps = np.arange(n) + np.repeat(firsts, lengths)
    commands = (np.repeat(np.array([c for _, c, _ in runs], float), lengths, axis=0)
                if runs[0][1] is not None else None)
    return steps, states, commands


def error_books(sim) -> tuple:
    """The error books after sim's latest step, as accuracy_values takes each row of them:
    (step, error_estimate, accumulated_error, substeps_taken)."""
    return sim.steps, sim.error_estimate, sim.accumulated_error, sim.substeps_taken


def accuracy_paths(snap: Snapshot) -> list[str]:
    """The error books' entities: the estimates where the simulator makes them, and the
    sub-steps unless the integrator adapts its own step (dopri5 takes no sub-steps)."""
    return (([LOCAL_ERROR, ACCUMULATED_ERROR] if snap.estimated else [])
            + ([] if snap.adaptive else [SUBSTEPS]))


def accuracy_values(snap: Snapshot, steps, books, before: tuple):
    """({entity path: (rows, values)}, sub-steps of every row (nan: a run's initial row),
    (step, substeps_taken) of the last row) from the error books sampled in a batch:
    `books` (m, 4) rows of (step, error_estimate, accumulated_error, substeps_taken), steps
    ascending, the batch's last step among them; `steps`: each row's step; `before`: (step,
    substeps_taken) of the last sample before the batch ((0, 0): none).

    The estimates are each sampled step's own. Sub-steps: the growth of substeps_taken per
    step since the sample before (no growth: plain steps, 1 each), given to each step in
    between; exact while the count holds, its mean where it changes (substeps_taken counts
    split steps only, so a span of plain and split steps reads at least 1). A count that
    fell or a step that went back restarted from 0 (a payload's rebuild, a reset)."""
    at, local, accumulated, taken = books.T
    rows = np.searchsorted(steps, at)
    previous_step = np.concatenate(([before[0]], at[:-1]))
    previous_taken = np.concatenate(([before[1]], taken[:-1]))
    back = at < previous_step                      # a reset: the run starts again at 0
    span = at - np.where(back, 0.0, previous_step)
    grown = taken - np.where(back | (taken < previous_taken), 0.0, previous_taken)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(grown == 0.0, 1.0, np.maximum(grown / span, 1.0))
    mean[span == 0] = np.nan                       # a run's initial row: no step
    starts = np.concatenate(([0], rows[:-1] + 1))
    per_row = np.repeat(mean, rows - starts + 1)   # each step gets its span's
    is_step = at > 0
    values = {}
    if snap.estimates:
        known = np.flatnonzero(is_step & np.isfinite(local) & np.isfinite(accumulated))
        values[LOCAL_ERROR] = rows[known], local[known]
        values[ACCUMULATED_ERROR] = rows[known], accumulated[known]
    if not snap.adaptive:
        known = np.flatnonzero(is_step & np.isfinite(mean))
        values[SUBSTEPS] = rows[known], mean[known]
    return values, per_row, (float(at[-1]), float(taken[-1]))
