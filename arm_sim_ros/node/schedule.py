"""When the next tick is due: publish_rate x real_time_factor ticks per wall second.

Both transports pace their ticks with it. A late tick is counted by the core; the ticks
then follow back to back until the schedule is met again, unless it is more than CATCH_UP
behind, when the schedule restarts from now instead of bursting (a stalled machine must not
be followed by seconds of flat-out ticking)."""
from __future__ import annotations

CATCH_UP = 0.05   # wall seconds of lag made up by ticking back to back (scheduler jitter)


class TickSchedule:
    def __init__(self, now: float):
        self.next_tick = now

    def wait(self, now: float) -> float:
        """Wall seconds until the next tick is due (≤ 0: due now)."""
        return self.next_tick - now

    def run_due(self, core, tick) -> int:
        """A tick timer's callback (the rclpy transport's): `tick()` for every tick due, on
        the core's wall clock and current wall period, so a late callback still keeps
        real_time_factor; at most CATCH_UP s of ticks, so commands and services are served
        between. In lockstep the commands tick: it returns at once. Returns the ticks run."""
        if core.config.values["lockstep"]:
            return 0
        now = started = core.wall_clock()
        ran = 0
        while self.wait(now) <= 0 and now - started <= CATCH_UP:
            tick()
            self.ticked(now, core.config.wall_period)
            ran += 1
            now = core.wall_clock()
        return ran

    def ticked(self, now: float, period: float) -> None:
        """A tick ran at `now`; the next is one `period` (the current wall period) later."""
        self.next_tick += period
        if self.next_tick < now - max(period, CATCH_UP):
            self.next_tick = now


# Wall seconds from the JointState of a tick a command made (lockstep) to its /clock: a
# use_sim_time controller (controller_manager) wakes on /clock and reads the latest JointState
# its hardware has taken, in another thread; written together, it often had not yet taken
# this one and acted on the state a tick older.
STATE_BEFORE_CLOCK = 0.001
