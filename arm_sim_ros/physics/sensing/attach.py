"""What the simulator calls: the readings sampled after each step, the control loop before it.

A scene that names no `sensors` and no command_delay gets none of it (`attach` gives None):
no call, no sample, no cost per step (benchmarks/bench_sensors.py). `sensors` that model
nothing (every key absent, or only a seed) publish the state itself as the readings, at the
cost of a call per step. Once a simulator has had sensors, a live change keeps its sample
index going even through spans without them, so no stream is ever repeated.
"""
from __future__ import annotations

from ..effects.servo import sample_grid
from ..model import ParameterError
from .loop import Loop
from .readings import Readings
from .sensors import SensorModel, delay_steps

# Drives whose law reads the state; under sensors that model something they read readings.
READING_POLICIES = ("gravity_compensation", "command_gravity_compensation")
COMMANDED_POLICIES = ("command", "command_gravity_compensation")


def measures(scene) -> bool:
    """Whether the scene's sensors model something (their readings are not the state)."""
    return scene.sensors is not None and not SensorModel(scene.sensors, scene.step_size).exact


def drives(scene) -> bool:
    """Whether the scene's drive runs in a control loop (loop.py): it reads the state under
    sensors that model something, or it is commanded under a command_delay."""
    servo = scene.servo
    reads = scene.policy in READING_POLICIES or (servo is not None and (
        any(kind != "effort" for kind in servo.get("interface", ("position",) * 2))))
    commanded = servo is not None or scene.policy in COMMANDED_POLICIES + READING_POLICIES
    return (commanded and scene.command_delay > 0) or (reads and measures(scene))


def check(scene) -> None:
    """One line (ParameterError) for sensors, a command_delay, or a servo rate under a
    control loop, that are not whole numbers of the scene's steps."""
    SensorModel(scene.sensors, scene.step_size)
    delay_steps("command_delay", scene.command_delay, scene.step_size)
    rate = (scene.servo or {}).get("rate")
    if rate and drives(scene) and sample_grid(rate, scene.step_size)[0] is None:
        raise ParameterError(
            f"servo.rate = {rate:g} Hz samples every {1 / rate / scene.step_size:.6g} steps "
            f"of {scene.step_size:g} s; under sensors or a command_delay the controller "
            "samples at whole steps")


class Sensing:
    """One simulator's readings (None where they are the state) and control loop (None
    without one); `index`: the next sample's, kept through spans without readings."""

    def __init__(self, sim, scene, carried: Sensing | None = None):
        dynamics, model = sim.dynamics, SensorModel(scene.sensors, scene.step_size)
        old = carried.readings if carried is not None else None
        self.index = carried.index if carried is not None else 0
        self.readings = None
        if not model.exact:
            self.readings = Readings(model, old)
            if old is None and hasattr(sim, "state"):    # live: readings from now on
                self.readings.start(sim.steps, sim.state, self.index)
        self.loop = (Loop(dynamics, scene, carried.loop if carried is not None else None)
                     if dynamics.command is not dynamics.given else None)

    @property
    def active(self) -> bool:
        """Whether it acts between steps (readings to sample, a loop): a compiled run of many
        steps in one call (Simulator.run) would miss that."""
        return self.readings is not None or self.loop is not None

    def reading(self, sim) -> tuple:
        """(q1, q2, q̇1, q̇2) as read now (a sample due now taken first)."""
        if self.readings is None:
            return tuple(sim.state[:4])
        self.readings.catch_up(sim.steps, sim.state)
        self.index = self.readings.index
        return self.readings.current

    def reset(self, sim) -> None:
        self.index = 0
        if self.readings is not None:
            self.readings.reset(sim.state)
        if self.loop is not None:
            self.loop.reset(sim.state, self.reading(sim))

    def before(self, sim) -> None:
        """At the start of a step: the sample due at its start (taken lazily: the state is
        the one the last step reached), then the control loop."""
        reading = self.reading(sim)
        if self.loop is not None:
            self.loop.before(sim, reading)


def attach(sim, scene) -> Sensing | None:
    """sim's sensing for `scene` (None without sensors, a loop, or sensors before); a live
    change takes the sample due now under the sensors that were in force until now."""
    carried = getattr(sim, "sensing", None)
    if carried is not None:
        carried.reading(sim)
    if scene.sensors is None and sim.dynamics.command is sim.dynamics.given and carried is None:
        return None
    return Sensing(sim, scene, carried)
