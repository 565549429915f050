"""The effects, as the issue states them, each checked against an independent formulation.

`FirstPrinciples` below is written from scratch, from the issue's words, sharing no code
with arm_sim_ros.physics: the links and the payload are bodies whose kinetic energy comes
from their own Jacobians (d'Alembert: M = Σ m JᵀJ + rotational inertias + armature,
velocity-product torques Σ m Jᵀ(J̇q̇)), the payload is a separate point mass at the tip (not
folded into link 2), springs, damping and effort clamps are written out, and the windings
are two more ODEs. It is integrated by scipy's DOP853 at rtol = atol = 1e-12, with every
clamp's switch located as an event (integration restarts there, so the reference keeps
its accuracy across the kinks).

Tolerances: the simulator's RK4 at h = 5e-4 s over 1 s has a global error ~C h⁴; on these
scenes it is below 3e-10 (measured), so 1e-8 leaves a margin of 10 and still catches any
wrong term (a wrong term shows up at 1e-4 or more). That holds across a clamp's switch
too: a clamp of a state-dependent request is a mode whose switch the simulator locates
inside the step (physics/switching/clamps.py), measured 2.5e-11 to 2.1e-10 on the clamped cases
(with MIN/MAX inside the RK stages the kink cost RK4 its order: up to 2e-7, then allowed
1e-6). A clamp of a request constant within the step is constant there: no kink.
"""
import itertools
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from arm_sim_ros.physics.effects import Motors
from arm_sim_ros.physics.model import ParameterError
from arm_sim_ros.physics.scene import Scene, SceneError, load_scene, preset_names
from arm_sim_ros.physics.simulator import Simulator
from arm_sim_ros.physics.stepping.stability import half_disk_limit
from arm_sim_ros.physics.stepping.integrators import RK4

H = 5e-4                     # the simulator's step in the comparisons
T = 1.0                      # compared at t = 1 s
SMOOTH_TOL = 1e-8            # rad, rad/s, A: RK4's error, clamp switches located (above)
BOOKS = ("work", "dissipated", "electrical_input", "copper_loss")


# --- The independent formulation -------------------------------------------------------

def _pair(value):
    return tuple(value) if isinstance(value, tuple) else (value, value)


def point_kinematics(l1, link, s, q, u):
    """Position, Jacobian rows (x, y) and J̇q̇ of a point at distance s along link 1 or 2."""
    c1, s1 = math.cos(q[0]), math.sin(q[0])
    c12, s12 = math.cos(q[0] + q[1]), math.sin(q[0] + q[1])
    w1, w12 = u[0], u[0] + u[1]
    if link == 1:
        return ((s * c1, s * s1), ((-s * s1, 0.0), (s * c1, 0.0)),
                (-s * w1 * w1 * c1, -s * w1 * w1 * s1))
    return ((l1 * c1 + s * c12, l1 * s1 + s * s12),
            ((-l1 * s1 - s * s12, -s * s12), (l1 * c1 + s * c12, s * c12)),
            (-l1 * w1 * w1 * c1 - s * w12 * w12 * c12, -l1 * w1 * w1 * s1 - s * w12 * w12 * s12))


def bodies(lengths, masses, coms, payload):
    """(mass, link, distance from its joint) of every point mass: the two COMs, the payload."""
    points = [(masses[0], 1, coms[0]), (masses[1], 2, coms[1])]
    return points + [(payload, 2, lengths[1])] if payload else points


def gravity_torque(lengths, masses, coms, payload, gravity, q):
    """τ that holds the bodies against gravity −y: −Σ m Jᵀ(0, −γ) = γ Σ m (J_y)ᵀ."""
    t1 = t2 = 0.0
    for m, link, s in bodies(lengths, masses, coms, payload):
        _, (_, jy), _ = point_kinematics(lengths[0], link, s, q, (0.0, 0.0))
        t1, t2 = t1 + m * gravity * jy[0], t2 + m * gravity * jy[1]
    return t1, t2


class FirstPrinciples:
    """The arm of `scene` with every effect, from the issue's equations."""

    def __init__(self, scene, command=(0.0, 0.0), payload=None):
        s = scene
        self.lengths, self.masses = s.link_lengths, s.link_masses
        self.coms, self.inertias, self.gravity = s.com_distances, s.com_inertias, s.gravity
        self.payload = (s.payload["mass"] if s.payload else 0.0) if payload is None else payload
        self.damping = _pair(s.damping)
        springs = s.springs or {}
        self.stiffness = springs.get("stiffness", (0.0, 0.0))
        self.rest = springs.get("rest_positions", (0.0, 0.0))
        motors = s.motors or {}
        self.gear = motors.get("gear_ratio", (1.0, 1.0))
        rotor = motors.get("rotor_inertia", (0.0, 0.0))
        self.armature = tuple(n * n * j for n, j in zip(self.gear, rotor))   # N² J
        self.windings = motors.get("resistance") is not None
        self.resistance, self.inductance = motors.get("resistance"), motors.get("inductance")
        self.torque_constant, self.voltage_limit = (motors.get("torque_constant"),
                                                    motors.get("voltage_limit"))
        self.effort = s.effort_limits
        believed = s.controller_model or {}
        pick = lambda key, true: true if believed.get(key) is None else believed[key]
        self.believed = (pick("link_lengths", s.link_lengths), pick("link_masses", s.link_masses),
                         pick("com_distances", s.com_distances),
                         pick("payload_mass", self.payload), pick("gravity", s.gravity))
        self.policy, self.constant, self.command = s.policy, s.constant_torque, command
        self.q0 = s.initial_positions
        self.servo = s.servo
        if s.servo:        # set-points [q*, q̇*, τ*]: the scene's (policy setpoint) or hold q0
            self.targets = [list(s.initial_positions), [0.0, 0.0], [0.0, 0.0]]
            for j, kind in enumerate(s.servo["interface"] if s.policy == "setpoint" else ()):
                self.targets[("position", "velocity", "effort").index(kind)][j] = s.setpoint[j]
        self.y0 = ([*s.initial_positions, *s.initial_velocities]
                   + [0.0] * (2 if self.servo else 0)
                   + [0.0] * (2 if self.windings else 0) + [0.0] * len(BOOKS))
        self.clamps = ([("effort", j) for j in (0, 1)] if self.effort else []) + (
            [("volts", j) for j in (0, 1)] if self.voltage_limit else [])
        self.switches = 0

    # mechanics
    def mass_matrix_and_bias(self, q, u):
        """M(q) and the velocity-product torques Σ m Jᵀ J̇q̇."""
        i1, i2 = self.inertias             # ω1 = q̇1, ω2 = q̇1 + q̇2
        m11, m12, m22 = i1 + i2 + self.armature[0], i2, i2 + self.armature[1]
        b1 = b2 = 0.0
        for m, link, s in bodies(self.lengths, self.masses, self.coms, self.payload):
            _, (jx, jy), (ax, ay) = point_kinematics(self.lengths[0], link, s, q, u)
            m11 += m * (jx[0] * jx[0] + jy[0] * jy[0])
            m12 += m * (jx[0] * jx[1] + jy[0] * jy[1])
            m22 += m * (jx[1] * jx[1] + jy[1] * jy[1])
            b1 += m * (jx[0] * ax + jy[0] * ay)
            b2 += m * (jx[1] * ax + jy[1] * ay)
        return (m11, m12, m22), (b1, b2)

    def momentum(self, q, u):
        (m11, m12, m22), _ = self.mass_matrix_and_bias(q, u)
        return m11 * u[0] + m12 * u[1], m12 * u[0] + m22 * u[1]

    def energy(self, y):
        """Kinetic (links, payload, rotors) + gravity + springs + windings' ½Li²."""
        q, u = y[0:2], y[2:4]
        (m11, m12, m22), _ = self.mass_matrix_and_bias(q, u)
        e = 0.5 * (m11 * u[0] ** 2 + 2.0 * m12 * u[0] * u[1] + m22 * u[1] ** 2)
        for m, link, s in bodies(self.lengths, self.masses, self.coms, self.payload):
            e += m * self.gravity * point_kinematics(self.lengths[0], link, s, q, u)[0][1]
        e += sum(0.5 * k * (qi - r) ** 2 for k, qi, r in zip(self.stiffness, q, self.rest))
        if self.windings:
            e += sum(0.5 * l * i * i for l, i in zip(self.inductance,
                                                     y[-len(BOOKS) - 2:-len(BOOKS)]))
        return e

    # the drive chain: policy → effort clamp → driver (→ voltage clamp) → winding
    def requested(self, y):
        q = y[0:2]
        compensation = lambda q: gravity_torque(*self.believed, q)
        if self.servo:
            return self.servo_request(y, compensation)
        return {"zero": lambda: (0.0, 0.0), "constant": lambda: self.constant,
                "frozen_gravity": lambda: compensation(self.q0),
                "gravity_compensation": lambda: compensation(q),
                "command": lambda: self.command,
                "command_gravity_compensation": lambda: tuple(
                    c + g for c, g in zip(self.command, compensation(q)))}[self.policy]()

    def servo_request(self, y, compensation):
        """The PID of each joint toward its set-point (effects/servo.py's equations)."""
        s, (q, u, w) = self.servo, (y[0:2], y[2:4], y[4:6])
        g = (compensation(q) if self.policy == "command_gravity_compensation"
             else (0.0, 0.0))
        limit = s.get("integral_limit") or (math.inf, math.inf)
        r = []
        for j, kind in enumerate(s["interface"]):
            wc = min(max(w[j], -limit[j]), limit[j])
            r.append(g[j] + (
                s["kp"][j] * (self.targets[0][j] - q[j])
                + s["kd"][j] * (self.targets[1][j] - u[j]) + wc if kind == "position" else
                s["kp"][j] * (self.targets[1][j] - u[j]) + wc if kind == "velocity" else
                self.targets[2][j] if self.policy == "setpoint" else self.command[j]))
        return r

    def servo_rates(self, y, tau_request, tau):
        s, (q, u, w) = self.servo, (y[0:2], y[2:4], y[4:6])
        limit = s.get("integral_limit") or (math.inf, math.inf)
        rates = []
        for j, kind in enumerate(s["interface"]):
            ki, kp = s["ki"][j], s["kp"][j]
            b = (s.get("tracking") or (None, None))[j] or (ki / kp if ki > 0 and kp > 0 else 1.0)
            e = (self.targets[0][j] - q[j] if kind == "position" else
                 self.targets[1][j] - u[j] if kind == "velocity" else None)
            wc = min(max(w[j], -limit[j]), limit[j])
            rates.append(0.0 if e is None or ki == 0.0 else
                         ki * e + b * (tau[j] - tau_request[j]) + b * (wc - w[j]))
        return rates

    def drive(self, q, modes, arguments=None):
        """(joint torque from the actuator without windings, winding voltages or None).
        Each clamp is one smooth piece per `modes` entry: 0 passes, ±1 holds ±limit."""
        def clamp(key, x, limit):
            if arguments is not None:
                arguments[key] = (x, limit)
            return x if modes.get(key, 0) == 0 else modes[key] * limit
        t = list(self.requested(q))
        self.request = list(t)
        if self.effort:
            t = [clamp(("effort", j), t[j], self.effort[j]) for j in (0, 1)]
        self.clamped = list(t)
        if not self.windings:
            return t, None
        v = [self.resistance[j] * t[j] / (self.gear[j] * self.torque_constant[j]) for j in (0, 1)]
        if self.voltage_limit:
            v = [clamp(("volts", j), v[j], self.voltage_limit[j]) for j in (0, 1)]
        return None, v

    def rhs(self, y, modes):
        q, u = y[0:2], y[2:4]
        (m11, m12, m22), (b1, b2) = self.mass_matrix_and_bias(q, u)
        tau, volts = self.drive(y, modes)
        rates, electrical, copper = [], 0.0, 0.0
        if self.servo:
            rates = self.servo_rates(y, self.request, self.clamped)
        if self.windings:
            i = y[-len(BOOKS) - 2:-len(BOOKS)]
            kn = [self.torque_constant[j] * self.gear[j] for j in (0, 1)]
            rates += [(volts[j] - self.resistance[j] * i[j] - kn[j] * u[j]) / self.inductance[j]
                     for j in (0, 1)]
            tau = [kn[j] * i[j] for j in (0, 1)]
            electrical = volts[0] * i[0] + volts[1] * i[1]
            copper = self.resistance[0] * i[0] ** 2 + self.resistance[1] * i[1] ** 2
        g = gravity_torque(self.lengths, self.masses, self.coms, self.payload, self.gravity, q)
        f = [tau[j] - g[j] - self.damping[j] * u[j] - self.stiffness[j] * (q[j] - self.rest[j])
             for j in (0, 1)]
        f1, f2 = f[0] - b1, f[1] - b2
        det = m11 * m22 - m12 * m12
        a1, a2 = (m22 * f1 - m12 * f2) / det, (m11 * f2 - m12 * f1) / det
        return [u[0], u[1], a1, a2, *rates, tau[0] * u[0] + tau[1] * u[1],
                self.damping[0] * u[0] ** 2 + self.damping[1] * u[1] ** 2, electrical, copper]

    def _arguments(self, y, modes):
        arguments = {}
        self.drive(y, modes, arguments)
        return arguments

    def _events(self, modes):
        """Each clamp's switching functions in the current modes, with the mode after."""
        events = []
        for key in self.clamps:
            mode = modes[key]
            for sign in ((1, -1) if mode == 0 else (mode,)):
                def g(t, y, key=key, sign=sign):
                    x, limit = self._arguments(y, modes)[key]
                    return x - sign * limit
                g.terminal, g.direction = True, sign if mode == 0 else -mode
                events.append((g, key, sign if mode == 0 else 0))
        return events

    def solve(self, t_end):
        """The state (q, q̇, i, then the BOOKS) at t_end."""
        t, y, modes = 0.0, np.array(self.y0), {}
        for _ in range(2):      # effort modes first, then the voltages they feed
            modes = {key: (1 if x > lim else -1 if x < -lim else 0)
                     for key, (x, lim) in self._arguments(y, modes).items()}
        while True:
            events = self._events(modes)
            sol = solve_ivp(lambda t, y: self.rhs(y, modes), (t, t_end), y, method="DOP853",
                            rtol=1e-12, atol=1e-12, events=[g for g, _, _ in events] or None)
            assert sol.status >= 0, sol.message
            if sol.status == 0:
                return sol.y[:, -1]
            k = min((te[0], n) for n, te in enumerate(sol.t_events) if len(te))[1]
            t, y = sol.t_events[k][0], sol.y_events[k][0]
            modes = modes | {events[k][1]: events[k][2]}
            self.switches += 1
            self.switched(t, events[k][1], events[k][2])

    def switched(self, t, clamp_and_joint, mode):
        """Called at each located switch (for tests that time them)."""


def compare(scene, command=(0.0, 0.0)):
    """Largest deviation of the state and of the books (relative to the energy scale)."""
    sim = Simulator(scene)
    sim.set_command(*command)
    sim.run(T)
    ref = FirstPrinciples(scene, command)
    y = ref.solve(T)
    n = 4 + len(sim.extra)
    state = float(np.max(np.abs(np.array(sim.state[:n]) - y[:n])))
    books = sim.channel_values(sim.state)
    scale = max(1.0, abs(ref.energy(y)), *(abs(v) for v in y[n:]))
    book = max([abs(books[name] - y[n + k]) for k, name in enumerate(BOOKS) if name in books]
               + [abs(sim.energy(sim.state) - ref.energy(y))]) / scale
    return sim, ref, state, book


# --- Scenes ------------------------------------------------------------------------------

MOVING = dict(initial_positions=(0.4, -0.3), initial_velocities=(1.0, -1.5), step_size=H)
WINDINGS = {"gear_ratio": [20.0, 10.0], "rotor_inertia": [1e-4, 2e-4],
            "resistance": [1.0, 1.5], "inductance": [0.01, 0.015], "torque_constant": [0.05, 0.06]}
WRONG_MODEL = {"gravity": 9.5, "link_masses": [1.1, 0.8], "com_distances": [0.45, 0.55],
               "link_lengths": [1.05, 0.95], "payload_mass": 0.2}
EVERYTHING = dict(MOVING, damping=(0.3, 0.1),
                  springs={"stiffness": [20.0, 5.0], "rest_positions": [0.5, -0.5]},
                  payload={"mass": 0.4}, motors=WINDINGS | {"voltage_limit": [15.0, 5.0]},
                  effort_limits=(12.0, 3.0), controller_model=WRONG_MODEL,
                  policy="command_gravity_compensation")

EFFECT_CASES = {
    "gravity": Scene(**MOVING),
    "damping_scalar": Scene(**MOVING, damping=0.4),
    "damping_per_joint": Scene(**MOVING, damping=(0.5, 0.05)),
    "springs": Scene(**MOVING, springs={"stiffness": [20.0, 5.0], "rest_positions": [0.5, -0.5]}),
    "payload": Scene(**MOVING, payload={"mass": 0.5}),
    "motors_armature": Scene(**MOVING, motors={"gear_ratio": [100.0, 50.0],
                                               "rotor_inertia": [1.81e-5, 1.81e-5]}),
    "motors_windings": Scene(**MOVING, motors=WINDINGS, policy="gravity_compensation"),
    "motors_windings_saturating": Scene(**MOVING, policy="gravity_compensation",
                                        motors=WINDINGS | {"voltage_limit": [15.0, 5.0]}),
    "effort_limits": Scene(**MOVING, effort_limits=(12.0, 3.0), policy="gravity_compensation"),
    "effort_limits_before_driver": Scene(**MOVING, effort_limits=(12.0, 3.0), motors=WINDINGS,
                                         policy="gravity_compensation"),
    "controller_model": Scene(**MOVING, payload={"mass": 0.5}, controller_model=WRONG_MODEL,
                              policy="gravity_compensation"),
    "controller_model_unnamed_keys_are_true": Scene(**MOVING, payload={"mass": 0.5},
                                                    controller_model={"gravity": 9.5},
                                                    policy="gravity_compensation"),
    "controller_model_frozen": Scene(**MOVING, payload={"mass": 0.5},
                                     controller_model=WRONG_MODEL, policy="frozen_gravity"),
    "constant_torque_no_gravity": Scene(**MOVING, gravity=0.0, policy="constant",
                                        constant_torque=(1.0, -0.5)),
    "everything": Scene(**EVERYTHING),
}


@pytest.mark.parametrize("case", EFFECT_CASES)
def test_each_effect_matches_the_first_principles_equations(case):
    scene = EFFECT_CASES[case]
    command = (1.5, -0.5) if scene.policy.startswith("command") else (0.0, 0.0)
    sim, ref, state, books = compare(scene, command)
    assert state <= SMOOTH_TOL, (case, state, ref.switches)
    assert books <= SMOOTH_TOL, (case, books)
    clamp_switches = sum(n for kind, n in sim.switch_events.items()
                         if kind.startswith(("effort_", "voltage_")))
    assert clamp_switches == ref.switches, (case, dict(sim.switch_events), ref.switches)
    assert abs(sim.initial_energy - ref.energy(ref.y0)) <= 1e-12 * max(1.0, abs(sim.initial_energy))


def test_the_clamped_cases_really_switch():
    """The clamp cases above really cross their limits (so SMOOTH_TOL holds across it)."""
    for case in ("effort_limits", "motors_windings_saturating", "everything"):
        ref = FirstPrinciples(EFFECT_CASES[case], (1.5, -0.5))
        ref.solve(T)
        assert ref.switches >= 1, case


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_matches_the_first_principles_equations(name):
    # The smooth effects of each preset; friction and joint limits (switched at located
    # events) have their own independent reference in test_friction_limits.py.
    scene = load_scene(name).replace(step_size=H, friction=None, joint_limits=None)
    sim, ref, state, books = compare(scene)
    assert state <= SMOOTH_TOL, (name, state, ref.switches)
    # The maxon windings (L/R = 0.53 ms) start with a current step that RK4 at h R/L ~ 1
    # integrates to ~1e-5 of the books (measured 1.5e-4 J of 16.9 J); the state forgets it.
    assert books <= (1e-4 if sim.extra else SMOOTH_TOL), (name, books)


# --- Presets ---------------------------------------------------------------------------

PRESET_EFFECTS = {
    "damped_release": "damping", "per_joint_damping": "damping",
    "springs_oscillation": "springs", "payload_release": "payload",
    "geared_release": "motors", "motor_windings_hold": "motors",
    "effort_limited_hold": "effort_limits", "wrong_payload_model": "controller_model",
    "geared_arm": "motors", "servo_hold": "servo", "servo_reach": "servo",
}


@pytest.mark.parametrize("name", sorted(PRESET_EFFECTS))
def test_each_effect_preset_loads_runs_and_calls_its_effect(name):
    assert (Path(__file__).parents[2] / "config" / "scenes" / f"{name}.yaml").is_file()
    scene = load_scene(name)
    sim = Simulator(scene)
    assert PRESET_EFFECTS[name] in sim.dynamics.effects
    largest = sim.run(min(scene.duration, 0.5))
    assert all(math.isfinite(v) for v in sim.state) and sim.fault is None
    scale = max(1.0, abs(sim.initial_energy), *(abs(v) for v in sim.channel_values(sim.state).values()))
    assert largest <= 1e-4 * scale


def test_geared_arm_windings_hold_the_pose_within_a_milliradian():
    sim = Simulator(load_scene("geared_arm"))
    sim.run(1.0)
    assert max(abs(v) for v in sim.state[:2]) < 1e-3
    assert sim.channel_values(sim.state)["copper_loss"] > 0.0
    assert sim.saturated_steps == 0


# --- Energy balance for every combination ---------------------------------------------

COMBINED = {
    "damping": {"damping": (0.3, 0.1)},
    "springs": {"springs": {"stiffness": [20.0, 5.0], "rest_positions": [0.5, -0.5]}},
    "payload": {"payload": {"mass": 0.4}},
    "armature": {"motors": {"gear_ratio": [20.0, 10.0], "rotor_inertia": [1e-4, 2e-4]}},
    "windings": {"motors": {k: v for k, v in WINDINGS.items() if k != "rotor_inertia"}
                 | {"voltage_limit": [15.0, 5.0]}},
    "effort_limits": {"effort_limits": (12.0, 3.0)},
    "controller_model": {"controller_model": {"payload_mass": 0.1, "link_masses": [1.1, 0.9]}},
    "servo": {"servo": {"interface": ["position", "velocity"], "kp": [60.0, 8.0],
                        "ki": [40.0, 10.0], "kd": [6.0, 0.0], "integral_limit": [5.0, 2.0]}},
}
SUBSETS = [names for r in range(len(COMBINED) + 1) for names in itertools.combinations(COMBINED, r)]


def combined_scene(names, **extra):
    values = {}
    for name in names:
        for key, value in COMBINED[name].items():
            values[key] = values.get(key, {}) | value if key == "motors" else value
    return Scene(name="+".join(names), **(MOVING | {"step_size": 2e-3} | values | extra),
                 policy="command_gravity_compensation")


@pytest.mark.parametrize("names", SUBSETS, ids=lambda names: "+".join(names) or "gravity_only")
def test_energy_balance_closes_for_every_combination_of_effects(names):
    sim = Simulator(combined_scene(names))
    sim.set_command(2.0, -1.0)                 # a drive on top of the compensation
    largest, scale = 0.0, abs(sim.initial_energy)
    for _ in range(250):                       # 0.5 s, residual checked at every step
        sim.step()
        inputs, losses = sim.books(sim.state)
        scale = max(scale, abs(sim.energy(sim.state)), abs(inputs), abs(losses))
        largest = max(largest, abs(sim.residual()))
    assert largest <= 1e-6 * max(scale, 1.0), (names, largest, scale)
    assert sim.fault is None


def test_energy_books_carry_the_channels_each_effect_names():
    sim = Simulator(combined_scene(tuple(COMBINED)))
    assert set(sim.channels) == {"work", "electrical_input", "copper_loss", "dissipated",
                                 "payload_exchange"}
    assert sim.extra == ("integral1", "integral2", "i1", "i2")
    kinds = dict(zip(sim.channels, sim.dynamics.channel_kinds))
    assert kinds == {"work": "transfer", "electrical_input": "input", "copper_loss": "loss",
                     "dissipated": "loss", "payload_exchange": "input"}


# --- Generated source: an absent effect runs no code -----------------------------------

MARKERS = {   # names only that effect's code uses
    "springs": ("SPRING1", "REST1"),
    "damping": ("DAMPING",),           # DAMPING or DAMPING1, DAMPING2
    "windings": ("INV_IND1", "DRIVE1", "KN1", "i1", "RES1"),
    "voltage_limit": ("VLIM1",),
    "effort_limits": ("EFFORT1",),
    "controller_model": ("GC1", "gc1"),
    "gravity": ("G1", "G2", "cos(q1"),
    "actuator": ("t1", "command", "TORQUE1"),
}
EVERY_MARKER = [m for markers in MARKERS.values() for m in markers]


def _names(source):
    """The markers (see MARKERS) some name in `source` starts with."""
    tokens = set(re.findall(r"[A-Za-z_][A-Za-z_0-9]*", source))
    return {m for m in EVERY_MARKER if m == "cos(q1" and m in source
            or any(token.startswith(m) for token in tokens)}


def test_gravity_only_source_has_no_code_of_any_other_effect():
    sim = Simulator(load_scene("release"))
    names = _names(sim.dynamics.source)
    assert names & set(EVERY_MARKER) == set(MARKERS["gravity"])
    assert sim.channels == () and sim.extra == ()


@pytest.mark.parametrize("effect", [e for e in MARKERS if e not in ("gravity", "actuator")])
def test_an_absent_effect_leaves_no_trace_in_the_generated_source(effect):
    everything = Scene(**EVERYTHING)
    without = {"springs": dict(springs=None), "damping": dict(damping=0.0),
               "windings": dict(motors={"gear_ratio": [20.0, 10.0]}),
               "voltage_limit": dict(motors=WINDINGS), "effort_limits": dict(effort_limits=None),
               "controller_model": dict(controller_model=None)}[effect]
    present = _names(Simulator(everything).dynamics.source)
    absent = _names(Simulator(everything.replace(**without)).dynamics.source)
    assert set(MARKERS[effect]) <= present          # the check can see the effect...
    assert not set(MARKERS[effect]) & absent        # ...and it is gone without it


def test_armature_and_payload_cost_no_code():
    """Reflected rotor inertia and the payload only change constants; the payload adds its
    exchange channel (rate 0), nothing else."""
    plain = Simulator(load_scene("release")).dynamics
    geared = Simulator(load_scene("geared_release")).dynamics
    held = Simulator(load_scene("payload_release")).dynamics
    assert geared.source == plain.source and geared.function.__globals__["A"] > plain.function.__globals__["A"]
    assert held.source == plain.source.replace("return a1, a2", "return a1, a2, 0.0")
    assert held.channels == ("payload_exchange",) and plain.channels == ()


def test_no_damping_no_dissipated_channel_no_windings_no_currents():
    sim = Simulator(Scene(**MOVING, policy="constant", constant_torque=(1.0, 0.0)))
    assert sim.channels == ("work",) and sim.extra == ()
    assert len(sim.state) == 5


# --- Bad parameters --------------------------------------------------------------------

BAD = [
    ({"payload": {"mass": -0.1}}, "payload.mass"),
    ({"payload": {"mass": 1.0, "volume": 2.0}}, "payload.volume"),
    ({"payload": {}}, "payload.mass"),
    ({"motors": WINDINGS | {"inductance": [0.0, 0.01]}}, "motors.inductance"),
    ({"motors": WINDINGS | {"inductance": [0.01, -1.0]}}, "motors.inductance"),
    ({"motors": WINDINGS | {"resistance": [0.0, 1.0]}}, "motors.resistance"),
    ({"motors": WINDINGS | {"resistance": [-1.0, 1.0]}}, "motors.resistance"),
    ({"motors": WINDINGS | {"torque_constant": [0.0, 1.0]}}, "motors.torque_constant"),
    ({"motors": WINDINGS | {"voltage_limit": [24.0, 0.0]}}, "motors.voltage_limit"),
    ({"motors": {"gear_ratio": [10.0, 10.0, 10.0]}}, "motors.gear_ratio"),
    ({"motors": {"gear_ratio": [10.0, 10.0], "rotor_inertia": [-1e-5, 0.0]}}, "motors.rotor_inertia"),
    ({"motors": {"gear_ratio": [10.0, 10.0], "resistance": [1.0, 1.0],
                 "inductance": [0.01, 0.01]}}, "torque_constant"),
    ({"motors": {"gear_ratio": [10.0, 10.0], "torque_constant": [0.1, 0.1]}}, "resistance"),
    ({"motors": {"gear_ratio": [10.0, 10.0], "voltage_limit": [24.0, 24.0]}}, "voltage_limit"),
    ({"motors": WINDINGS | {"backlash": 0.1}}, "motors.backlash"),
    ({"motors": {"rotor_inertia": [1e-5, 1e-5]}}, "motors.gear_ratio"),
    ({"springs": {"stiffness": [10.0]}}, "springs.stiffness"),
    ({"springs": {"stiffness": [-10.0, 1.0]}}, "springs.stiffness"),
    ({"springs": {"stiffness": [10.0, 1.0], "rest_positions": [0.0, 0.0, 0.0]}}, "springs.rest_positions"),
    ({"springs": {"stiffness": [10.0, 1.0], "damping": 1.0}}, "springs.damping"),
    ({"springs": {"stiffness": [float("nan"), 1.0]}}, "springs.stiffness"),
    ({"damping": [0.1, 0.2, 0.3]}, "damping"),
    ({"damping": [0.1, -0.2]}, "damping"),
    ({"effort_limits": [10.0, -1.0]}, "effort_limits"),
    ({"effort_limits": [10.0]}, "effort_limits"),
    ({"controller_model": {"link_masses": [-1.0, 1.0]}}, "controller_model.link_masses"),
    ({"controller_model": {"payload_mass": -0.5}}, "controller_model.payload_mass"),
    ({"controller_model": {"gravity": -9.81}}, "controller_model.gravity"),
    ({"controller_model": {"inertia": [1.0, 1.0]}}, "controller_model.inertia"),
    ({"springz": {"stiffness": [1.0, 1.0]}}, "springz"),
]


@pytest.mark.parametrize("overrides, key", BAD, ids=[key for _, key in BAD])
def test_bad_parameters_are_refused_with_one_line_naming_the_key(overrides, key):
    with pytest.raises(SceneError) as refused:
        Scene().replace(**overrides)
    message = str(refused.value)
    assert "\n" not in message and key in message, message


def test_a_bad_scene_file_is_refused_with_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("motors:\n  gear_ratio: [10.0, 10.0]\n  resistance: [1.0, 1.0]\n"
                    "  inductance: [0.0, 0.01]\n  torque_constant: [0.1, 0.1]\n")
    with pytest.raises(SceneError) as refused:
        load_scene(str(path))
    assert "\n" not in str(refused.value) and "motors.inductance" in str(refused.value)


def test_partial_windings_are_refused_by_the_effect_itself():
    with pytest.raises(ParameterError, match="the windings need"):
        Motors(gear_ratio=(10.0, 10.0), resistance=(1.0, 1.0))


def test_a_believed_com_on_the_elbow_axis_is_a_controller_belief_not_a_singular_arm():
    """Only the believed gravity is used; its (unused) mass matrix must not refuse the scene."""
    scene = Scene(**MOVING, com_inertias=(0.1, 0.0), policy="gravity_compensation",
                  controller_model={"com_distances": [0.5, 0.0]})
    sim, ref, state, _ = compare(scene)
    assert state <= SMOOTH_TOL


# --- Voltage limit: allowed, and its saturation reported --------------------------------

def test_a_voltage_limit_too_low_to_hold_is_allowed_and_its_saturation_reported():
    scene = load_scene("geared_arm").replace(**{"motors.voltage_limit": (2.0, 2.0)})
    sim = Simulator(scene)
    heard = []
    sim.event_listeners.append(heard.append)
    sim.run(0.2)
    saturation = [e for e in heard if e.kind == "saturation"]
    assert len(saturation) == 1 and "\n" not in saturation[0].message
    assert saturation[0].t == pytest.approx(sim.step_size)
    assert "joint 1" in saturation[0].message and "2 V limit" in saturation[0].message
    assert sim.saturated_steps == 200
    assert sim.state[0] < -0.01                      # it cannot hold the arm: it sags
    sim.reset()
    assert sim.saturated_steps == 0


def test_a_sufficient_voltage_limit_reports_no_saturation():
    sim = Simulator(load_scene("geared_arm"))
    sim.run(0.2)
    assert sim.saturated_steps == 0 and not [e for e in sim.events if e.kind == "saturation"]


def test_saturation_is_counted_where_the_reference_clamps():
    """The count matches the steps whose end state the first-principles driver clamps."""
    scene = EFFECT_CASES["motors_windings_saturating"].replace(step_size=1e-3)
    sim = Simulator(scene)
    ref = FirstPrinciples(scene)
    expected = 0
    for _ in range(500):
        sim.step()
        arguments = ref._arguments(sim.state, {})
        expected += any(abs(x) > lim for key, (x, lim) in arguments.items() if key[0] == "volts")
    assert sim.saturated_steps == expected > 0


# --- Payload grasp and release at run time --------------------------------------------

@pytest.mark.parametrize("base", ["damped", "geared_arm"])
def test_grasp_keeps_momentum_release_keeps_velocity_and_the_books_close(base):
    scene = (Scene(**MOVING, damping=0.1) if base == "damped" else
             load_scene("geared_arm").replace(initial_velocities=(0.5, -1.0)))
    sim = Simulator(scene)
    held = scene.payload["mass"] if scene.payload else 0.0
    largest = sim.run(0.2)

    before = sim.state
    q, qd = before[0:2], before[2:4]
    momentum = FirstPrinciples(scene, payload=held).momentum(q, qd)
    energy_before = FirstPrinciples(scene, payload=held).energy(before)
    sim.set_payload(held + 0.7)                                     # grasp
    after = sim.state
    grasped = FirstPrinciples(scene, payload=held + 0.7)
    assert after[0:2] == q
    assert np.allclose(grasped.momentum(q, after[2:4]), momentum, rtol=1e-13, atol=1e-13)
    assert after[4:4 + len(sim.extra)] == before[4:4 + len(sim.extra)]   # currents carried
    exchange = sim.channel_values(after)["payload_exchange"]
    assert exchange == pytest.approx(grasped.energy(after) - energy_before, abs=1e-12)
    kinetic_loss = (0.5 * sum(p * v for p, v in zip(momentum, qd))
                    - 0.5 * sum(p * v for p, v in zip(momentum, after[2:4])))
    assert kinetic_loss > 0.0                                        # an inelastic grasp
    largest = max(largest, sim.run(0.2))

    qd = sim.state[2:4]
    sim.set_payload(0.0)                                             # release
    assert sim.state[2:4] == qd
    largest = max(largest, sim.run(0.2))
    scale = max(1.0, abs(sim.initial_energy), *map(abs, sim.channel_values(sim.state).values()))
    assert largest <= 1e-5 * scale, largest


def test_set_payload_refuses_a_negative_mass_and_changes_nothing():
    sim = Simulator(load_scene("payload_release"))
    sim.run(0.1)
    state, scene = sim.state, sim.scene
    with pytest.raises(SceneError, match="payload.mass"):
        sim.set_payload(-1.0)
    assert sim.state == state and sim.scene is scene


# --- Stability of stiff springs and fast windings --------------------------------------

def stiff_scene(kind, value, h):
    """The stability plan alone (tolerance 0): the default tolerance resolves the fast
    oscillation these scenes leave unresolved (test_error_estimate.py)."""
    base = dict(initial_positions=(0.3, -0.2), initial_velocities=(1.0, -1.0), step_size=h,
                tolerance=0.0)
    if kind == "springs":
        return Scene(**base, springs={"stiffness": [value, value], "rest_positions": [0.29, -0.21]})
    r = 0.573
    return Scene(**base, policy="gravity_compensation",
                 motors={"gear_ratio": [100.0, 50.0], "rotor_inertia": [1.81e-5, 1.81e-5],
                         "resistance": [r, r], "inductance": [r * value, r * value],
                         "torque_constant": [0.0404, 0.0404]})


STIFF = [("springs", 1e3), ("springs", 1e6), ("windings", 1e-3), ("windings", 1e-5)]
STEPS = [1e-4, 1e-3, 1e-2, 0.05]


@pytest.mark.parametrize("h", STEPS)
@pytest.mark.parametrize("kind, value", STIFF, ids=["k1e3", "k1e6", "LR1e-3", "LR1e-5"])
def test_stiff_effects_stay_finite_and_passive_at_every_step_size(kind, value, h):
    sim = Simulator(stiff_scene(kind, value, h))
    steps = {1e-4: 40, 1e-3: 10, 1e-2: 3, 0.05: 2}[h]
    scale = max(1.0, abs(sim.initial_energy))
    for _ in range(steps):
        sim.step()
        inputs, _ = sim.books(sim.state)
        assert all(math.isfinite(v) for v in sim.state)
        # passive: never more energy than it started with plus what was put in
        assert sim.energy(sim.state) - sim.initial_energy - inputs <= 1e-9 * scale
    assert sim.fault is None
    planned = [e for e in sim.events if e.kind == "substepping"]
    if sim.substeps > 1:
        assert len(planned) == 1 and ("springs" if kind == "springs" else "motors") in planned[0].message
        assert f"{sim.substeps} sub-steps" in planned[0].message
        assert sim.substeps_taken == steps * sim.substeps
    else:
        assert not planned and sim.substeps_taken == 0


def rk4_amplification(z):
    return abs(1 + z + z * z / 2 + z ** 3 / 6 + z ** 4 / 24)


def jacobian(sim, y):
    """d(q, q̇, i)/dt by central differences of the simulator's own right-hand side."""
    n = len(y)
    f = lambda z: np.array([z[2], z[3], *sim.dynamics.function(*z)[:n - 2]])
    out = np.zeros((n, n))
    for k in range(n):
        step = np.zeros(n)
        step[k] = 1e-7 * max(1.0, abs(y[k]))
        out[:, k] = (f(np.add(y, step)) - f(np.subtract(y, step))) / (2 * step[k])
    return out


@pytest.mark.parametrize("h", STEPS)
@pytest.mark.parametrize("kind, value", STIFF, ids=["k1e3", "k1e6", "LR1e-3", "LR1e-5"])
def test_planned_sub_steps_keep_every_eigenvalue_in_rk4s_region_at_every_elbow_angle(kind, value, h):
    """Independent of the planner's bound: linearise the scene's own f about equilibria at
    elbow angles 0..π (gravity off, springs relaxed there) and check |R(h_sub λ)| <= 1.
    rk4 named: a windings scene that names none runs exponential_rk4 where they are stiff."""
    worst = stiffest = 0.0
    for q2 in np.linspace(0.0, math.pi, 7):
        scene = stiff_scene(kind, value, h).replace(gravity=0.0, policy="zero", integrator="rk4")
        if kind == "springs":
            scene = scene.replace(springs=scene.springs | {"rest_positions": (0.3, q2)})
        sim = Simulator(scene)
        eigenvalues = np.linalg.eigvals(jacobian(sim, [0.3, q2, 0.0, 0.0] + [0.0] * len(sim.extra)))
        h_sub = h / sim.substeps
        worst = max(worst, max(rk4_amplification(h_sub * lam) for lam in eigenvalues))
        stiffest = max(stiffest, h_sub * max(abs(eigenvalues)))
    assert worst <= 1.0 + 1e-6, worst
    assert stiffest <= half_disk_limit(RK4)
    if sim.substeps > 1:      # and not wastefully many sub-steps
        assert stiffest >= 0.05 * half_disk_limit(RK4), stiffest
