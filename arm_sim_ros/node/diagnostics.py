"""What the node publishes, transport-neutral: JointState and diagnostics as plain data.

The diagnostic keys are one list, used by the node and by `arm-sim run --bag`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from ..physics.trust.unestimated import NO_ESTIMATE


class JointStateData(NamedTuple):   # one a tick: a tuple is built in a third of the time
    stamp_ns: int
    frame_id: str
    name: list
    position: list
    velocity: list
    effort: list
    truth: JointStateData | None = None   # with sensors: the state itself (~/true_joint_states)


@dataclass(frozen=True)
class DiagnosticData:
    stamp_ns: int
    level: int
    name: str
    message: str
    hardware_id: str
    values: list           # [(key, value text)]


COUNTERS = ("received_commands", "refused_commands", "stale_commands", "late_ticks",
            "command_timeouts")


def diagnostic_values(sim, real_time_factor: str, max_abs_residual: float, held: bool,
                      command, steps_per_tick: int, counters=None,
                      last_refusal: str = "none") -> list:
    """The (key, text) pairs of the simulation's DiagnosticStatus: the node's, and those an
    offline `arm-sim run --bag` writes (its counters stay 0). `last_refusal`: why the latest
    refused command was refused, so that its sender can say so (arm-sim send-torque)."""
    counters = counters or {}
    return [
        ("scene", sim.scene.name), ("policy", sim.scene.policy),
        ("sim_time", f"{sim.time:.6f}"), ("real_time_factor", real_time_factor),
        ("energy_residual", "held" if held else f"{sim.residual():.3e}"),
        ("max_abs_energy_residual", f"{max_abs_residual:.3e}"),
        *((name, str(counters.get(name, 0))) for name in COUNTERS),
        ("last_refusal", last_refusal),
        ("command", f"{command[0]:g} {command[1]:g}"),
        ("steps_per_tick", str(steps_per_tick)),
        # What the stability guard did: sub-steps per step (1 = plain steps) and refusals.
        ("substeps_per_step", str(sim.substeps)),
        ("substeps_taken", str(sim.substeps_taken)),
        # physics/compiled/build.py: which code takes runs of plain steps (extra `fast`)
        ("compute_path", sim.path),
        ("refused_steps", str(sim.refused_steps)),
        # physics/trust/accuracy.py: the latest local error estimate and their sum since reset;
        # none where the scene's estimate is off (physics/trust/unestimated.py)
        ("estimate", f"off: {NO_ESTIMATE}" if sim.scene.estimate == "off" else "global"),
        ("error_estimate", f"{sim.error_estimate:.3e}"),
        ("accumulated_error", f"{sim.accumulated_error:.3e}"),
        # Friction, limits and clamps switched inside steps, by kind (none without them).
        ("switch_events", " ".join(f"{k}={n}" for k, n in sorted(sim.switch_events.items()))
         or "0"),
    ]
