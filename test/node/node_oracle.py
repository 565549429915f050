"""What the node should publish, from the core Simulator alone (shared by the transport tests)."""
from arm_sim_ros.physics.simulator import Simulator


def expected_states(scene, schedule, steps_per_tick):
    """[(q, qd, tau)] after each tick; schedule: per tick, the command received before it or None."""
    sim, out = Simulator(scene), []
    for command in schedule:
        if command is not None:
            sim.set_command(*command)
        for _ in range(steps_per_tick):
            sim.step()
        y = sim.state
        out.append(([y[0], y[1]], [y[2], y[3]], list(sim.dynamics.applied_torque(y[:2]))))
    return out


def assert_matches(received, expected):
    """JointState messages equal the oracle exactly: the node runs the same core."""
    assert len(received) == len(expected)
    for message, (q, qd, tau) in zip(received, expected):
        assert (list(message.position), list(message.velocity), list(message.effort)) == (q, qd, tau)
