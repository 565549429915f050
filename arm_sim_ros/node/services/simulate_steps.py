"""The SimulateSteps action (simulation_interfaces/action/SimulateSteps) over the node's
SimulationControl: its goals with their status as action_msgs/GoalStatus has it, cancels as
action_msgs/srv/CancelGoal has them, and the ticks, one per `advance()`, so that a transport
answers requests (a cancel) between two ticks.

As the .action says and Gazebo does, every goal is accepted; one that cannot run (the
simulation playing, another goal running, more steps than one call may take) is aborted at
once with RESULT_OPERATION_FAILED and why. An executing goal ticks exactly `steps` times
(each tick published, as StepSimulation's), with feedback after each; a cancel stops it
between two ticks (CANCELED, its result saying how many it took); a play or stop request
meanwhile aborts it at the next tick. A goal's first tick waits, up to FEEDBACK_WAIT, for a
reader of the feedback: a client that has just found the server (`ros2 action send_goal --feedback`)
may not yet be matched with it, and would miss the first ticks' feedback.
"""
from __future__ import annotations

from dataclasses import dataclass

from .simulation import MAX_STEPS, RESULT_OK, RESULT_OPERATION_FAILED, STATE_PLAYING, interrupted

# action_msgs/msg/GoalStatus
STATUS_UNKNOWN, STATUS_ACCEPTED, STATUS_EXECUTING, STATUS_CANCELING = 0, 1, 2, 3
STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED = 4, 5, 6
TERMINAL = (STATUS_SUCCEEDED, STATUS_CANCELED, STATUS_ABORTED)
# action_msgs/srv/CancelGoal_Response
ERROR_NONE, ERROR_REJECTED, ERROR_UNKNOWN_GOAL_ID, ERROR_GOAL_TERMINATED = 0, 1, 2, 3
KEPT = 64            # finished goals whose results are kept (the oldest go first)
NO_GOAL = bytes(16)  # a zero goal id: every goal (CancelGoal)
FEEDBACK_WAIT = 0.5  # s (wall): the longest a goal's first tick waits for a feedback reader


@dataclass
class Goal:
    goal_id: bytes
    steps: int
    stamp_ns: int                 # when it was accepted (wall clock, as rcl_action stamps)
    status: int = STATUS_ACCEPTED
    completed: int = 0
    epoch: int = 0                # the control's when accepted (play or stop ends the goal)
    result: tuple = (RESULT_OK, "")

    @property
    def remaining(self) -> int:
        return self.steps - self.completed


def refusal(control, steps: int, busy: bool) -> tuple | None:
    """(code, message) why a goal of `steps` cannot run now, or None."""
    if control.state == STATE_PLAYING:
        return RESULT_OPERATION_FAILED, "simulate_steps needs the simulation paused"
    if busy:
        return RESULT_OPERATION_FAILED, "another simulate_steps goal is running"
    if control.calls:
        return RESULT_OPERATION_FAILED, "a step_simulation call is running"
    if steps > MAX_STEPS:
        return RESULT_OPERATION_FAILED, f"{steps} steps is beyond {MAX_STEPS} in one goal"
    return None


def waiting(stamp_ns: int, now_ns: int, listening: bool) -> bool:
    """The goal accepted at `stamp_ns` holds its first tick: nobody reads its feedback yet."""
    return not listening and now_ns - stamp_ns < FEEDBACK_WAIT * 1e9


def canceled(done: int, steps: int) -> str:
    return f"canceled after {done} of {steps} steps"


class StepsGoals:
    """The goals of one action server; `changed` says the status list changed (publish it)."""

    def __init__(self, control, clock_ns):
        self.control, self.clock_ns = control, clock_ns
        self.goals: dict[bytes, Goal] = {}     # by goal id, in order of acceptance
        self.changed = False

    def send_goal(self, goal_id: bytes, steps: int) -> Goal | None:
        """The goal accepted (executing, or aborted at once), None for an id already known."""
        goal_id = bytes(goal_id)
        if goal_id in self.goals:
            return None
        goal = Goal(goal_id, steps, self.clock_ns(), epoch=self.control.epoch)
        why = refusal(self.control, steps, self.active() is not None)
        self.goals[goal_id] = goal
        if why is None:
            goal.status = STATUS_EXECUTING
        else:
            self._finish(goal, STATUS_ABORTED, *why)
        self.changed = True
        return goal

    def active(self) -> Goal | None:
        """The goal executing (or being canceled), None if none."""
        return next((g for g in self.goals.values()
                     if g.status in (STATUS_EXECUTING, STATUS_CANCELING)), None)

    def advance(self, listening: bool = True) -> Goal | None:
        """One tick of the executing goal; the goal if it ticked (its feedback is due).
        `listening`: the feedback has a reader."""
        goal = self.active()
        if goal is None:
            return None
        if goal.status == STATUS_EXECUTING and not goal.completed and waiting(
                goal.stamp_ns, self.clock_ns(), listening):
            return None
        if goal.status == STATUS_CANCELING:
            self._finish(goal, STATUS_CANCELED, RESULT_OK, canceled(goal.completed, goal.steps))
            return None
        if goal.epoch != self.control.epoch:      # played or stopped meanwhile
            self._finish(goal, STATUS_ABORTED, RESULT_OPERATION_FAILED,
                         interrupted(goal.completed, goal.steps, self.control.why))
            return None
        if goal.remaining:
            if not self.control.ready():      # lockstep: the tick waits for its answer
                return None
            code, message = self.control.step(1)
            if code != RESULT_OK:             # set playing meanwhile
                self._finish(goal, STATUS_ABORTED, code,
                             interrupted(goal.completed, goal.steps, message))
                return None
            goal.completed += 1
        if not goal.remaining:
            self._finish(goal, STATUS_SUCCEEDED, RESULT_OK, "")
        return goal

    def cancel(self, goal_id: bytes, stamp_ns: int) -> tuple[int, list]:
        """(return code, the goals now canceling) of a CancelGoal request: a zero id and
        stamp cancel every goal, a stamp every goal accepted at or before it, an id that goal."""
        goal_id = bytes(goal_id)
        chosen = [g for g in self.goals.values() if (goal_id == NO_GOAL and not stamp_ns)
                  or g.goal_id == goal_id or (stamp_ns and g.stamp_ns <= stamp_ns)]
        if goal_id != NO_GOAL:
            if goal_id not in self.goals:
                return ERROR_UNKNOWN_GOAL_ID, []
            if self.goals[goal_id].status in TERMINAL and not stamp_ns:
                return ERROR_GOAL_TERMINATED, []
        canceling = [g for g in chosen if g.status not in TERMINAL]
        for goal in canceling:
            goal.status = STATUS_CANCELING
        self.changed = self.changed or bool(canceling)
        return ERROR_NONE, canceling

    def result(self, goal_id: bytes) -> tuple | None:
        """(status, code, message) of a finished or unknown goal; None while it runs."""
        goal = self.goals.get(bytes(goal_id))
        if goal is None:
            return STATUS_UNKNOWN, RESULT_OPERATION_FAILED, "no such goal (or long finished)"
        return (goal.status, *goal.result) if goal.status in TERMINAL else None

    def status_list(self) -> list[Goal]:
        self.changed = False
        return list(self.goals.values())

    def _finish(self, goal: Goal, status: int, code: int, message: str) -> None:
        goal.status, goal.result, self.changed = status, (code, message), True
        finished = [k for k, g in self.goals.items() if g.status in TERMINAL]
        for key in finished[:max(0, len(finished) - KEPT)]:
            del self.goals[key]
