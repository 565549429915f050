"""A recording made by a different simulator than ours, for `arm-sim fit` to be judged on.

The arm's equations are written out here again, separately from physics/ (the payload as
a point mass in the kinetic energy rather than folded into link 2, the rotor inertia as
N²J on the diagonal, Coriolis torques from the Christoffel symbols), and integrated with
scipy's DOP853 at tight tolerances, restarted at every sample (the torque is held over a
sample interval, as the node holds a command) and at every friction event: a sliding
joint's velocity reaching zero (it sticks if the torque holding it still is within the
breakaway friction, else slides on in the direction of the net torque) and a stuck joint's
holding torque reaching the breakaway friction. The parameters are hidden from the fit:
the tests hand it a base scene with other values.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import cos, sin

import numpy as np
from scipy.integrate import solve_ivp

from arm_sim_ros.physics.scene import load_scene
from arm_sim_ros.tools.fit.data import checked
from arm_sim_ros.tools.fit.excitation import multisine

NOISE = (1e-4, 1e-3)          # rad, rad/s
RATE = 500.0                  # Hz
PEAKS = (8.0, 3.0)            # N m


@dataclass(frozen=True)
class HiddenArm:
    """The explainer's rods with a tip payload, geared rotors, damping and friction."""

    damping: tuple = (0.4, 0.25)
    coulomb: tuple = (0.6, 0.3)
    static: tuple = (0.6, 0.3)
    payload: float = 0.5
    gear: tuple = (50.0, 30.0)
    rotor: tuple = (2e-5, 1.5e-5)
    gravity: float = 9.81

    def mass_matrix(self, q2):
        l1 = l2 = 1.0
        m1 = m2 = 1.0
        r1 = r2 = 0.5
        i1 = i2 = 1.0 / 12.0
        mp, c = self.payload, cos(q2)
        m11 = (i1 + m1 * r1 ** 2 + i2 + m2 * (l1 ** 2 + r2 ** 2 + 2 * l1 * r2 * c)
               + mp * (l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * c) + self.gear[0] ** 2 * self.rotor[0])
        m12 = i2 + m2 * (r2 ** 2 + l1 * r2 * c) + mp * (l2 ** 2 + l1 * l2 * c)
        m22 = i2 + m2 * r2 ** 2 + mp * l2 ** 2 + self.gear[1] ** 2 * self.rotor[1]
        return np.array([[m11, m12], [m12, m22]])

    def passive(self, q, qd, modes):
        """Every generalized force but the actuator's: −c(q, q̇) − g(q) − D q̇ − friction."""
        mp, g = self.payload, self.gravity
        h = (0.5 + mp) * sin(q[1])                       # (m2 r2 + mp l2) l1 sin q2
        coriolis = np.array([-h * (2 * qd[0] * qd[1] + qd[1] ** 2), h * qd[0] ** 2])
        k2 = (0.5 + mp) * g * cos(q[0] + q[1])
        weight = np.array([(0.5 + 1.0 + mp) * g * cos(q[0]) + k2, k2])
        friction = np.array([m * f if m else 0.0 for m, f in zip(modes, self.coulomb)])
        return -coriolis - weight - np.array(self.damping) * qd - friction

    def accelerations(self, q, qd, tau, modes):
        """(q̈, holding torques λ): a stuck joint (mode 0) does not accelerate."""
        m, f = self.mass_matrix(q[1]), np.asarray(tau) + self.passive(q, qd, modes)
        free = [i for i in (0, 1) if modes[i]]
        a = np.zeros(2)
        if free:
            a[free] = np.linalg.solve(m[np.ix_(free, free)], f[free])
        return a, m @ a - f

    def settle(self, q, qd, tau, modes):
        """Modes consistent with the holding torques: a stuck joint beyond its breakaway
        slides in the direction of the net torque on it."""
        modes = list(modes)
        for _ in range(3):
            _, lam = self.accelerations(q, qd, tau, modes)
            slipping = [i for i in (0, 1) if modes[i] == 0 and abs(lam[i]) > self.static[i]]
            if not slipping:
                return modes
            worst = max(slipping, key=lambda i: abs(lam[i]) - self.static[i])
            modes[worst] = -1 if lam[worst] > 0 else 1
        return modes


def integrate(arm: HiddenArm, start, tau, dt):
    """States at the sample times, tau[k] held over [t_k, t_k+1)."""
    y = np.array(start, dtype=float)
    modes = arm.settle(y[:2], y[2:], tau[0], [int(np.sign(v)) for v in y[2:]])
    out = [y.copy()]
    for k in range(len(tau) - 1):
        t, end, torque = k * dt, (k + 1) * dt, tau[k]
        modes = arm.settle(y[:2], y[2:], torque, modes)
        for _ in range(50):                               # events within the interval
            def rhs(_, s, modes=tuple(modes)):
                a, _ = arm.accelerations(s[:2], s[2:], torque, modes)
                return [s[2], s[3], a[0], a[1]]
            events = []
            for i in (0, 1):
                if modes[i]:                               # sliding: the velocity reaches 0
                    event = (lambda _, s, i=i: s[2 + i])
                    event.direction = -modes[i]
                else:                                      # stuck: |λ| reaches breakaway
                    event = (lambda _, s, i=i, modes=tuple(modes): arm.static[i] - abs(
                        arm.accelerations(s[:2], s[2:], torque, modes)[1][i]))
                    event.direction = -1
                event.terminal = True
                events.append(event)
            sol = solve_ivp(rhs, (t, end), y, method="DOP853", rtol=1e-12, atol=1e-13,
                            events=events)
            y = sol.y[:, -1].copy()
            hit = [i for i in (0, 1) if len(sol.t_events[i])]
            if sol.status != 1 or not hit:
                break
            t = sol.t[-1]
            i = hit[0]
            if modes[i]:                                   # stops: stick, or slide on
                y[2 + i] = 0.0
                modes[i] = 0
            modes = arm.settle(y[:2], y[2:], torque, modes)
        out.append(y.copy())
    return np.array(out)


@lru_cache(maxsize=4)
def recording(duration: float = 4.0, seed: int = 7, arm: HiddenArm = HiddenArm(),
              bias: tuple = (0.0, 0.0)):
    """(Recording with noise, the noiseless states) of a multi-sine (+ a constant `bias`)
    from hanging at rest."""
    _, tau = multisine(duration, RATE, PEAKS)
    tau = tau + np.array(bias)
    exact = integrate(arm, (-np.pi / 2, 0.0, 0.0, 0.0), tau, 1.0 / RATE)
    rng = np.random.default_rng(seed)
    t = np.arange(len(tau)) / RATE
    q = exact[:, :2] + rng.normal(0.0, NOISE[0], (len(t), 2))
    qd = exact[:, 2:] + rng.normal(0.0, NOISE[1], (len(t), 2))
    return checked(f"DOP853 {duration:g} s", t, q, qd, tau), exact


COUNTS = 4096                 # the encoder of sensed_recording: 2π/4096 rad per count
FINE = 2                      # the truth is kept every 1/(FINE x RATE) s: delays in whole steps


@lru_cache(maxsize=4)
def sensed_recording(duration: float = 4.0, seed: int = 7, sensor_delay: float = 0.003,
                     command_delay: float = 0.0, offset: tuple = (0.02, -0.015)):
    """(Recording of what a drive reads, the noiseless states every 1/(FINE x RATE) s) of the
    multi-sine from hanging at rest, made here and not by physics/sensing/: the commands act
    `command_delay` late (before the first, the first), and each reading is the truth
    `sensor_delay` earlier (before t = 0, the rest it started from) + `offset` + Gaussian
    noise NOISE[0], rounded to whole counts of a COUNTS-count encoder; the velocity is the
    difference of the last two readings x RATE (0 at the first). The recorded torque is the
    command, as it was given."""
    _, tau = multisine(duration, RATE, PEAKS)
    step = 1.0 / (FINE * RATE)
    acting = np.repeat(tau, FINE, axis=0)
    late = round(command_delay / step)
    acting = np.vstack([np.repeat(acting[:1], late, axis=0), acting[:len(acting) - late]])
    exact = integrate(HiddenArm(), (-np.pi / 2, 0.0, 0.0, 0.0), acting, step)
    at = np.clip(np.arange(len(tau)) * FINE - round(sensor_delay / step), 0, None)
    rng = np.random.default_rng(seed)
    count = 2 * np.pi / COUNTS
    q = np.round((exact[at, :2] + np.array(offset)
                  + rng.normal(0.0, NOISE[0], (len(tau), 2))) / count) * count
    qd = np.vstack([np.zeros((1, 2)), np.diff(q, axis=0) * RATE])
    t = np.arange(len(tau)) / RATE
    return checked(f"DOP853 {duration:g} s, read", t, q, qd, tau), exact


def truth_scene(arm: HiddenArm = HiddenArm()):
    """Our scene of the hidden arm (what the fit must find; never handed to it whole)."""
    return load_scene("downward_equilibrium").replace(
        step_size=1.0 / RATE, damping=arm.damping, payload={"mass": arm.payload},
        friction={"coulomb": list(arm.coulomb), "static": list(arm.static)},
        motors={"gear_ratio": list(arm.gear), "rotor_inertia": list(arm.rotor)})


def test_the_reference_and_our_simulator_agree_on_the_hidden_arm():
    """Two integrations of the same equations: they agree far below the noise, so what the
    fit finds is the arm's, not an integrator's."""
    from arm_sim_ros.tools.fit.problem import replay_scene, restarted, rollout

    rec, exact = recording(1.0)
    scene, substeps = replay_scene(truth_scene(), "effort", rec)
    ours = rollout(restarted(None, scene, exact[0]), substeps, rec.tau)
    assert np.max(np.abs(ours[:, :2] - exact[:, :2])) < 1e-3 * NOISE[0]
    assert np.max(np.abs(ours[:, 2:] - exact[:, 2:])) < 1e-3 * NOISE[1]
    assert (exact[:, 2:] == 0.0).any(), "some joint sticks: the friction events are exercised"
