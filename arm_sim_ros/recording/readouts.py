"""A batch of recorded steps as numpy arrays: the readouts of every channel and the arm's
drawing, for all rows at once with numpy. Pure functions: no rerun, no state.
"""
from __future__ import annotations

import numpy as np


def energies(arm, gravity: float, q1, q2, u1, u2):
    """Kinetic and potential energy of many states: model.kinetic_energy and
    model.potential_energy term for term, in numpy (the scalar calls cost more than
    the RK4 step itself; see benchmarks/bench_telemetry.py)."""
    a, b, d = arm.inertia_coefficients
    k1, k2 = arm.gravity_coefficients
    c2 = np.cos(q2)
    m11 = a + 2.0 * b * c2
    m12 = d + b * c2
    kinetic = 0.5 * (m11 * u1 * u1 + 2.0 * m12 * u1 * u2 + d * u2 * u2)
    potential = gravity * (k1 * np.sin(q1) + k2 * np.sin(q1 + q2))
    return kinetic, potential


def gravity_torques(arm, gravity: float, q1, q2):
    """model.gravity_torque for many configurations, as an (n, 2) array."""
    k1, k2 = arm.gravity_coefficients
    g2 = gravity * k2 * np.cos(q1 + q2)
    return np.column_stack((gravity * k1 * np.cos(q1) + g2, g2))


def drawing_points(arm, q1, q2):
    """Elbow and tip of many configurations, y negated: the viewer's 2D y axis points down."""
    l1, l2 = arm.link_lengths
    elbow = np.column_stack((l1 * np.cos(q1), -l1 * np.sin(q1)))
    tip = elbow + np.column_stack((l2 * np.cos(q1 + q2), -l2 * np.sin(q1 + q2)))
    return elbow, tip


def applied_torques(sim, q1, q2, commands):
    """The applied torque per row, as sim.dynamics.applied_torque gives it at that step
    (`commands`: the held command of each row, for the command policies)."""
    scene, n = sim.scene, len(q1)
    if commands is not None:
        tau = commands.reshape(n, 2)
    else:
        tau = np.tile(sim.dynamics.applied_torque((0.0, 0.0)), (n, 1)).astype(float)
    if scene.policy.endswith("gravity_compensation") and scene.gravity != 0.0:
        tau = (0.0 if scene.policy == "gravity_compensation" else tau) + gravity_torques(
            sim.arm, scene.gravity, q1, q2)
    return tau


def channel_values(sim, states, commands) -> dict:
    """{entity path: (n,) or (n, k) values} of the scalar channels for (n, width) states
    of `sim` (q1, q2, q̇1, q̇2, then sim.channels), as blueprint.energy_paths and
    joint_paths name them."""
    q1, q2, u1, u2 = states[:, 0], states[:, 1], states[:, 2], states[:, 3]
    kinetic, potential = energies(sim.arm, sim.scene.gravity, q1, q2, u1, u2)
    total = kinetic + potential
    books = {name: states[:, 4 + i] for i, name in enumerate(sim.channels)}
    work = books.get("work", 0.0)
    dissipated = books.get("dissipated", 0.0)
    values = {"energy/kinetic": kinetic, "energy/potential": potential, "energy/total": total,
              "energy/balance_residual": total - sim.initial_energy - work + dissipated,
              "joints/angle": states[:, 0:2], "joints/velocity": states[:, 2:4]}
    if "dissipated" in books:
        values["energy/dissipated"] = dissipated
    if "work" in books:
        values["work/actuator"] = work
        values["joints/torque"] = applied_torques(sim, q1, q2, commands)
    return values


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
