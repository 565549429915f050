"""A parameter change as a transaction: the new physics is built and checked aside, and only
then takes the simulator's place; whatever fails is refused in the physics' words, and the
simulator is left as it was."""
from __future__ import annotations

from math import isfinite

from ...physics.stepping import stability
from ...physics.effects import servo
from ...physics.model import ParameterError
from ...physics.scene import SceneError
from ...physics.simulator import Simulator
from .parameters import NodeConfig, blamed
from .values import ParameterRefused


def build_simulator(config: NodeConfig, changed) -> Simulator:
    """The simulator of `config`'s scene, or ParameterRefused naming the physics that cannot
    be built (an arm whose mass matrix overflows, a plan that leaves double precision)."""
    try:
        sim = Simulator(config.scene)
    except (ValueError, ArithmeticError) as error:
        raise refusal(error, changed) from None
    needed, cap = planned_substeps(sim), int(config.scene.max_substeps)
    # a tick of 1e5 sub-steps would stall the node's rate and its services (past the
    # planner's own bound every step is refused at once: held, as offline)
    if cap < needed <= stability.MAX_SUBSTEPS:
        reason = (f"the physics with these values needs {needed} sub-steps per step to stay "
                  f"stable{' while a compliant limit is engaged' if needed > sim.substeps else ''}"
                  f", more than max_substeps = {cap}: the node would fall behind its rate and "
                  "stop answering; lower step_size, soften the effect, or raise max_substeps")
        # the value just set, not the step_size and max_substeps the advice names
        raise ParameterRefused(blamed("", list(changed)), reason)
    return sim


def planned_substeps(sim: Simulator) -> int:
    """The sub-steps the stability plan asks of one step, engaged in a compliant limit
    the most of that and the contact's count."""
    stepper = sim.switching
    engaged = stepper.contact_floor(sim.step_size) if stepper and stepper.engaged_rate else 0
    return max(sim.substeps, engaged)


def change_live(sim: Simulator, config: NodeConfig, names: list) -> None:
    """Live effects `names` changed to `config`'s: the simulator carries on from its state
    under them (a payload grasped or released first). A change the carried-over state cannot
    take (a grasp whose momentum overflows) is refused with `sim` as it was."""
    kept = dict(sim.__dict__)
    try:
        if "payload.mass" in names:     # grasp (momentum kept) or release (velocity kept)
            sim.set_payload(config.values["payload.mass"] or 0.0)
        if names != ["payload.mass"]:   # a servo's set-points carried, bumplessly
            servo.change_scene(sim, config.scene.replace(payload=sim.scene.payload))
        if not all(isfinite(v) for v in sim.state):
            raise OverflowError("the carried-over state is not finite")
    except Exception as error:     # whatever failed midway, the simulator is left as it was
        sim.__dict__.clear()
        sim.__dict__.update(kept)
        raise refusal(error, names) from None


def refusal(error: Exception, changed) -> ParameterRefused:
    """The refusal of `changed` for a physics error, in the physics' words."""
    if isinstance(error, (ParameterError, SceneError)):
        reason = str(error)
    elif isinstance(error, (ValueError, ArithmeticError)):
        # Python's words (math range error) would not tell anyone which quantity
        reason = ("the physics with these values leaves double precision (it overflows while "
                  "the dynamics and its step plan are built); use values at a robot's scale")
    else:   # a fault of the rebuild itself: refused all the same, nothing changed
        reason = ("the running physics could not be carried over to these values; nothing "
                  "changed (reset, or set them from a state the node can integrate)")
    return ParameterRefused(blamed(reason, list(changed)), reason)
