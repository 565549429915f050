"""An independent reference for scenes that switch modes: the arm's equations written here
from the explainer's definitions (point masses and link inertias, no code shared with
arm_sim_ros.physics), friction and joint limits as modes, every switch located by scipy's
solve_ivp on DOP853 with terminal events, restarted in the new mode (an impulse at an
impact). What the accuracy study and the estimate's tests judge our event handling by.

Covered: gravity, damping (one value or per joint), springs, a tip payload, the zero,
constant and gravity-compensation policies, Coulomb/Stribeck friction with stiction, hard
limits with restitution and compliant limits. Scenes with anything else are not covered
(`covers` says why) and the study falls back to our own stepper at a fine step.
"""
from __future__ import annotations

from math import cos, exp, inf, sin

import numpy as np

TOLERANCE = 1e-12
REST_SPEED = 1e-4          # a bounce slower than this ends at rest (the documented rule)
SAME_INSTANT = 64          # switches at one instant past which this reference cannot decide
MAX_STEP = 5e-4            # s: solve_ivp finds an event by a sign change over its step, so a
                           # velocity through zero and back within one step would be missed


class Undecided(Exception):
    """The reference switches without end at one instant (a joint that slips at Stribeck's
    peak and stops at once, again and again): it cannot say what the motion is."""
COVERED_POLICIES = ("zero", "constant", "gravity_compensation")


def covers(scene) -> str | None:
    """Why this reference cannot run `scene`, or None when it can."""
    for key in ("motors", "effort_limits", "controller_model", "servo"):
        if getattr(scene, key, None):
            return f"{key} is not written here"
    if scene.policy not in COVERED_POLICIES:
        return f"policy {scene.policy} is not written here"
    return None


def arriving(gap: float, velocity: float) -> float:
    """A boundary's switching function: the gap, except on the boundary moving away from it
    (a restart just after a switch there), where it does not switch again."""
    return 1e-12 if abs(gap) < 1e-9 and velocity >= 0.0 else gap


class Arm:
    """M(q) q̈ + b(q, q̇) + g(q) = τ: from the kinematics of the links' centres and the tip."""

    def __init__(self, scene):
        self.l1, self.l2 = scene.link_lengths
        self.inertias = scene.com_inertias
        payload = scene.payload["mass"] if scene.payload else 0.0
        (m1, m2), (r1, r2) = scene.link_masses, scene.com_distances
        # (mass, on link, distance along it): the two centres and the payload at the tip
        self.points = [(m1, 1, r1), (m2, 2, r2)] + ([(payload, 2, self.l2)] if payload else [])
        self.gravity = scene.gravity

    def kinematics(self, q, u, link, s):
        """(y, Jacobian rows dx/dq and dy/dq, J̇ q̇) of a point s along `link`."""
        a1, a12 = q[0], q[0] + q[1]
        if link == 1:
            jx, jy = (-s * sin(a1), 0.0), (s * cos(a1), 0.0)
            bias = (-s * u[0] ** 2 * cos(a1), -s * u[0] ** 2 * sin(a1))
            return s * sin(a1), jx, jy, bias
        w = u[0] + u[1]
        jx = (-self.l1 * sin(a1) - s * sin(a12), -s * sin(a12))
        jy = (self.l1 * cos(a1) + s * cos(a12), s * cos(a12))
        bias = (-self.l1 * u[0] ** 2 * cos(a1) - s * w * w * cos(a12),
                -self.l1 * u[0] ** 2 * sin(a1) - s * w * w * sin(a12))
        return self.l1 * sin(a1) + s * sin(a12), jx, jy, bias

    def terms(self, q, u):
        """(M as (m11, m12, m22), b + g as a pair) at (q, q̇), in plain floats."""
        i1, i2 = self.inertias
        m11, m12, m22, r1, r2 = i1 + i2, i2, i2, 0.0, 0.0
        for mass, link, s in self.points:
            _, (x1, x2), (y1, y2), (bx, by) = self.kinematics(q, u, link, s)
            m11 += mass * (x1 * x1 + y1 * y1)
            m12 += mass * (x1 * x2 + y1 * y2)
            m22 += mass * (x2 * x2 + y2 * y2)
            r1 += mass * (x1 * bx + y1 * by + self.gravity * y1)
            r2 += mass * (x2 * bx + y2 * by + self.gravity * y2)
        return (m11, m12, m22), (r1, r2)


class Independent:
    """The scene's motion, switch by switch. Modes per joint: +1/-1 sliding, 0 stuck
    (friction), "lower"/"upper" resting on a hard limit, None free; zones per joint: +1/-1
    beyond a compliant limit, 0 within."""

    def __init__(self, scene):
        self.arm, self.scene = Arm(scene), scene
        d = scene.damping
        self.damping = np.array(d if isinstance(d, tuple) else (d, d), dtype=float)
        springs = scene.springs or {}
        self.stiffness = np.array(springs.get("stiffness", (0.0, 0.0)))
        self.rest = np.array(springs.get("rest_positions", (0.0, 0.0)))
        fr = scene.friction
        self.fc = np.array(fr["coulomb"]) if fr else None
        self.fs = np.array(fr.get("static") or fr["coulomb"]) if fr else None
        self.vs = (fr.get("stribeck_velocity") or 0.0) if fr else 0.0
        lim = scene.joint_limits or {}
        self.lower, self.upper = np.array(lim.get("lower", (-inf, -inf))), np.array(
            lim.get("upper", (inf, inf)))
        self.k, self.c = lim.get("stiffness"), lim.get("damping") or 0.0
        self.e = lim.get("restitution") or 0.0
        self.hard = bool(lim) and self.k is None
        self.q0 = np.array(scene.initial_positions)

    def drive(self, q):
        policy = self.scene.policy
        if policy == "constant":
            return tuple(self.scene.constant_torque)
        if policy == "gravity_compensation":
            return self.arm.terms(q, (0.0, 0.0))[1]
        return (0.0, 0.0)

    def slide(self, u, i):
        if self.vs == 0.0:
            return self.fc[i]
        return self.fc[i] + (self.fs[i] - self.fc[i]) * exp(-(u[i] / self.vs) ** 2)

    def solve(self, x, mode, zone):
        """(q̈, holding torques of the fixed joints) in (mode, zone)."""
        q, u = x[:2], x[2:4]
        (m11, m12, m22), rest = self.arm.terms(q, u)
        drive = self.drive(q)
        f = [drive[i] - rest[i] - self.damping[i] * u[i] - self.stiffness[i] * (q[i] - self.rest[i])
             for i in (0, 1)]
        for i in (0, 1):
            if zone[i]:
                edge = self.upper[i] if zone[i] > 0 else self.lower[i]
                f[i] -= self.k * (q[i] - edge) + self.c * u[i]
            if mode[i] in (1, -1):
                f[i] -= mode[i] * self.slide(u, i)
        fixed = [mode[i] in (0, "lower", "upper") for i in (0, 1)]
        if not fixed[0] and not fixed[1]:
            det = m11 * m22 - m12 * m12
            acc = [(m22 * f[0] - m12 * f[1]) / det, (m11 * f[1] - m12 * f[0]) / det]
        elif fixed[0] and fixed[1]:
            acc = [0.0, 0.0]
        else:
            acc = [0.0, f[1] / m22] if fixed[0] else [f[0] / m11, 0.0]
        hold = [m11 * acc[0] + m12 * acc[1] - f[0], m12 * acc[0] + m22 * acc[1] - f[1]]
        return acc, [hold[i] if fixed[i] else 0.0 for i in (0, 1)]

    def events(self, mode, zone):
        out = []
        for i in (0, 1):
            if mode[i] in (1, -1):
                out.append((lambda t, x, i=i, s=mode[i]: s * x[2 + i], "stop", i))
            elif mode[i] == 0:
                out.append((lambda t, x, i=i: self.fs[i] - abs(self.solve(x, mode, zone)[1][i]),
                            "slip", i))
            elif mode[i] in ("lower", "upper"):
                sign = 1 if mode[i] == "lower" else -1
                out.append((lambda t, x, i=i, s=sign: s * self.solve(x, mode, zone)[1][i],
                            "release", i))
            if self.hard and mode[i] not in (0, "lower", "upper"):
                # arriving only: a restart on the stop moving away is no impact
                out.append((lambda t, x, i=i: arriving(self.upper[i] - x[i], -x[2 + i]),
                            "impact", i))
                out.append((lambda t, x, i=i: arriving(x[i] - self.lower[i], x[2 + i]),
                            "impact", i))
            if self.k is not None:
                if zone[i] == 0:
                    out.append((lambda t, x, i=i: arriving(self.upper[i] - x[i], -x[2 + i]),
                                "enter", i))
                    out.append((lambda t, x, i=i: arriving(x[i] - self.lower[i], x[2 + i]),
                                "enter", i))
                else:
                    edge = self.upper[i] if zone[i] > 0 else self.lower[i]
                    out.append((lambda t, x, i=i, s=zone[i], e=edge:
                                arriving(s * (x[i] - e), s * x[2 + i]), "leave", i))
        for g, _, _ in out:
            g.terminal, g.direction = True, -1
        return out

    def settle(self, x, mode, zone):
        """Stuck joints whose holding torque passes stiction slip toward it (worst first);
        joints resting on a limit that would have to pull come free."""
        for _ in range(4):
            hold = self.solve(x, mode, zone)[1]
            bad = [(abs(hold[i]) - self.fs[i], i) for i in (0, 1)
                   if mode[i] == 0 and abs(hold[i]) > self.fs[i]]
            bad += [(1.0, i) for i in (0, 1) if (mode[i] == "lower" and hold[i] < 0.0)
                    or (mode[i] == "upper" and hold[i] > 0.0)]
            if not bad:
                return mode
            _, i = max(bad)
            mode[i] = (-int(np.sign(hold[i])) if mode[i] == 0 else
                       0 if self.fc is not None else None)
        return mode

    def switch(self, kind, i, x, mode, zone):
        if kind == "stop":
            x[2 + i], mode[i] = 0.0, 0
        elif kind == "slip":
            mode[i] = -int(np.sign(self.solve(x, mode, zone)[1][i]))
        elif kind == "release":
            mode[i] = 0 if self.fc is not None else None
        elif kind == "enter":           # at the nearer limit (the event leaves it on it)
            zone[i] = 1 if abs(x[i] - self.upper[i]) < abs(x[i] - self.lower[i]) else -1
        elif kind == "leave":
            zone[i] = 0
        elif kind == "impact":
            (m11, m12, m22), _ = self.arm.terms(x[:2], x[2:4])
            minv = np.linalg.inv(np.array([[m11, m12], [m12, m22]]))
            v = x[2 + i]
            e, j = (self.e if self.e * abs(v) >= REST_SPEED else 0.0), 1 - i
            change = minv[:, i] * (-(1.0 + e) * v / minv[i, i])
            if (mode[j] == "upper" and change[j] > 0) or (mode[j] == "lower" and change[j] < 0):
                change = np.zeros(2)          # the other joint's stop takes its share
                change[i] = -(1.0 + e) * v
            x[2:4] += change
            mode[i] = (None if self.fc is None else -int(np.sign(v))) if e else (
                "upper" if v > 0 else "lower")
            if change[j]:             # the other joint moves, off its stop if it rested
                mode[j] = (int(np.sign(x[2 + j])) if x[2 + j] else 0) if self.fc is not None \
                    else None
        return self.settle(x, mode, zone)

    def initial(self, x):
        mode = [(int(np.sign(x[2 + i])) if x[2 + i] else 0) if self.fc is not None else None
                for i in (0, 1)]
        zone = [0, 0]
        for i in (0, 1):
            if self.hard and x[2 + i] == 0.0 and x[i] >= self.upper[i]:
                mode[i] = "upper"
            elif self.hard and x[2 + i] == 0.0 and x[i] <= self.lower[i]:
                mode[i] = "lower"
            elif self.k is not None:
                zone[i] = 1 if x[i] > self.upper[i] else -1 if x[i] < self.lower[i] else 0
        return self.settle(x, mode, zone), zone

    def states(self, times) -> list[tuple]:
        """(q1, q2, q̇1, q̇2) at `times` (ascending, from 0)."""
        from scipy.integrate import solve_ivp   # here: arm-sim starts without scipy (0.6 s)

        x = np.array([*self.scene.initial_positions, *self.scene.initial_velocities], float)
        mode, zone = self.initial(x)
        t, out, k = 0.0, [], 0
        self.switch_times = []        # when each switch happened
        end = times[-1]
        while k < len(times):
            events = self.events(mode, zone)
            wanted = [s for s in times[k:] if s >= t]

            def rates(_, y):
                return [y[2], y[3], *self.solve(y, mode, zone)[0]]

            sol = solve_ivp(rates, (t, end), x, method="DOP853", rtol=TOLERANCE,
                            atol=TOLERANCE, events=[g for g, _, _ in events], dense_output=True,
                            max_step=MAX_STEP)
            stop = end if sol.status != 1 else min(
                ts[0] for ts in sol.t_events if len(ts))
            while k < len(times) and times[k] <= stop and (times[k] < stop or sol.status != 1):
                out.append(tuple(sol.sol(times[k])))
                k += 1
            if sol.status != 1 or not wanted:
                break
            which = next(n for n, ts in enumerate(sol.t_events) if len(ts) and ts[0] == stop)
            t, x = stop, sol.y_events[which][0].copy()
            self.switch_times.append(t)
            if self.switch_times[-SAME_INSTANT:] == [t] * SAME_INSTANT:
                raise Undecided(f"{SAME_INSTANT} switches at t = {t!r} s ({events[which][1]} "
                                f"of joint {events[which][2] + 1}): no reference motion")
            mode, zone = list(mode), list(zone)
            mode = self.switch(events[which][1], events[which][2], x, mode, zone)
        return out
